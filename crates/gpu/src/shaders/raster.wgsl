// raster.wgsl — stage 1, the G-buffer fill (hybrid_cpu::raster). common/*.wgsl is prepended.
//
// Vertex pulling: no vertex buffers; `draw(0..3 * triangle_count)`, vertex `vi` is corner
// `vi % 3` of triangle `vi / 3` (group 0's `triangles` / `vertices`). The fragment shader
// evaluates the surface exactly as the CPU's `TriangleSurface::at` (`evaluate_surface`) and
// writes the eight G-buffer targets (`targets::GBUFFER_COLOR_FORMATS` order). The depth test
// (reversed-Z, Greater, write on) keeps the nearest surface, the earlier triangle on ties — as
// the CPU rasteriser's visibility pass.

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) tangent: vec3<f32>,
    @location(4) color: vec3<f32>,
    @location(5) @interpolate(flat) tri: u32,
    /// Unit geometric normal of the triangle (the same in all three corners).
    @location(6) @interpolate(flat) geometric_normal: vec3<f32>,
    /// Bitangent sign of corner 0 (as the CPU: `tg[0].w`).
    @location(7) @interpolate(flat) tangent_sign: f32,
}

@vertex
fn vs_main(@builtin(vertex_index) vi: u32) -> VsOut {
    let tri = vi / 3u;
    let corner = vi % 3u;
    let t = triangles[tri];
    var index = t.v0;
    if corner == 1u {
        index = t.v1;
    } else if corner == 2u {
        index = t.v2;
    }
    let v = vertices[index];
    let p0 = vertices[t.v0].position.xyz;
    let p1 = vertices[t.v1].position.xyz;
    let p2 = vertices[t.v2].position.xyz;
    var out: VsOut;
    out.clip = frame.view_proj * vec4<f32>(v.position.xyz, 1.0);
    out.world = v.position.xyz;
    out.normal = v.normal.xyz;
    out.uv = v.uv.xy;
    out.tangent = v.tangent.xyz;
    out.color = v.color.xyz;
    out.tri = tri;
    out.geometric_normal = normalize_or(cross(p1 - p0, p2 - p0), vec3<f32>(0.0, 1.0, 0.0));
    out.tangent_sign = vertices[t.v0].tangent.w;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> GBufferOut {
    // UV change per pixel (the CPU: the UV planes one pixel right and one down), in uniform
    // control flow, before any branch.
    let footprint_raw = max(length(dpdxFine(in.uv)), length(dpdyFine(in.uv)));
    var footprint = 0.0;
    if is_finite(footprint_raw) {
        footprint = footprint_raw;
    }
    return gbuffer_at(in, footprint);
}

// The G-buffer outputs of the surface under fragment `in`, textures sampled with `footprint`.
fn gbuffer_at(in: VsOut, footprint: f32) -> GBufferOut {
    let mesh = triangles[in.tri].mesh;
    var p: SurfacePoint;
    p.mesh = mesh;
    p.position = in.world;
    p.normal = in.normal;
    p.geometric_normal = in.geometric_normal;
    p.uv = in.uv;
    p.tangent = vec4<f32>(in.tangent, in.tangent_sign);
    p.color = in.color;
    p.uv_footprint = footprint;
    let s = evaluate_surface(p);
    return gbuffer_out(s, meshes[mesh].object);
}

// The fallbacks' raster layers (probe faces, the see-through layer): as fs_main with textures
// sampled at level 0 (footprint 0), as a secondary ray's hit samples them
// (hybrid_cpu::raster's `level0`).
@fragment
fn fs_level0(in: VsOut) -> GBufferOut {
    return gbuffer_at(in, 0.0);
}
