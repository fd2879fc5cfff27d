//! `hybrid inspect`: the paper's Table 4 row for a scene. STUB.

/// Counts for `hybrid inspect`.
#[derive(Debug, Clone, Default)]
pub struct SceneStats;
