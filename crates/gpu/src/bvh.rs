//! `bvh`: (being written)
