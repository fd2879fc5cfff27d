//! `primary`: (being written)
