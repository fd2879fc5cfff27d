// shadow_depth.wgsl — stage 3b's shadow maps (hybrid_cpu::fallback, `raster::rasterize_depth`):
// the caster meshes' depth from one light view, reversed-Z (Depth32Float, cleared to 0, compare
// Greater). common/*.wgsl is prepended. Vertex pulling as raster.wgsl; no fragment shader.

// The view's world → clip matrix (one 256-byte slot per view, bound with a dynamic offset).
@group(1) @binding(0) var<uniform> shadow_view_proj: mat4x4<f32>;
// Per mesh: 1 where it casts into the maps (`hybrid_core::fallback::caster_meshes`).
@group(1) @binding(1) var<storage, read> casters: array<u32>;

@vertex
fn vs_shadow(@builtin(vertex_index) vi: u32) -> @builtin(position) vec4<f32> {
    let t = triangles[vi / 3u];
    if casters[t.mesh] == 0u {
        // All three corners behind the near plane (z < 0): the triangle is clipped away.
        return vec4<f32>(0.0, 0.0, -1.0, 1.0);
    }
    let corner = vi % 3u;
    var index = t.v0;
    if corner == 1u {
        index = t.v1;
    } else if corner == 2u {
        index = t.v2;
    }
    return shadow_view_proj * vec4<f32>(vertices[index].position.xyz, 1.0);
}
