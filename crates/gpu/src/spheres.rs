//! `spheres`: (being written)
