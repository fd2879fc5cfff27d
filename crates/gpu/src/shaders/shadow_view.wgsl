// shadow_view.wgsl — one shadow map's view (hybrid_core::fallback::ShadowView) and its depth
// conventions, shared by the shadow-map pass (shadow_depth.wgsl) and the lookups (fallback.wgsl).

// One shadow map (hybrid_core::fallback::ShadowView) and where it lies.
struct ShadowViewGpu {
    view_proj: mat4x4<f32>,
    near: f32,
    far: f32,
    // Orthographic: a texel's world size; perspective: at unit distance.
    texel_world: f32,
    // Cascades: the camera view distance up to which it is used (∞ otherwise).
    split_far: f32,
    size: u32,
    orthographic: u32,
    // SHADOW_ARRAY_MAPS or SHADOW_ARRAY_CUBE, and the layer in that array.
    array_index: u32,
    layer: u32,
}

// hybrid_core::fallback::project: uv (row 0 at the top) and reversed-Z depth; w ≤ 0 (behind a
// perspective view) gives valid = 0.
struct Projected {
    uv: vec2<f32>,
    z: f32,
    valid: bool,
}

fn project_point(view_proj: mat4x4<f32>, p: vec3<f32>) -> Projected {
    let c = view_proj * vec4<f32>(p, 1.0);
    if c.w <= 0.0 {
        return Projected(vec2<f32>(0.0), 0.0, false);
    }
    let ndc = c.xyz / c.w;
    return Projected(vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5), ndc.z, true);
}

fn linear_depth(v: ShadowViewGpu, z: f32) -> f32 {
    let n = v.near;
    let f = v.far;
    if v.orthographic != 0u {
        return f - z * (f - n);
    }
    return n * f / ((f - n) * z + n);
}

fn depth_of(v: ShadowViewGpu, d: f32) -> f32 {
    let n = v.near;
    let f = v.far;
    if v.orthographic != 0u {
        return (f - d) / (f - n);
    }
    return n * f / ((f - n) * max(d, 1e-6)) - n / (f - n);
}
