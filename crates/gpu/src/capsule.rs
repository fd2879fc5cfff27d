//! `capsule`: (being written)
