//! `raster`: (being written)
