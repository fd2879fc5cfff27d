//! `blend`: (being written)
