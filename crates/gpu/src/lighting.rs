//! `lighting`: (being written)
