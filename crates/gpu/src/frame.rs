//! `frame`: (being written)
