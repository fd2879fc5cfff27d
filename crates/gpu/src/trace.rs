//! `trace`: (being written)
