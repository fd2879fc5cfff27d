//! `heuristic`: (being written)
