// shadow_depth.wgsl — stage 3b's shadow maps (hybrid_cpu::fallback: `raster::rasterize_depth`
// and `splat_spheres`): the caster meshes' depth from one light view, reversed-Z (Depth32Float,
// cleared to 0, compare Greater), then the point clouds' spheres as discs. common/*.wgsl and
// shadow_view.wgsl are prepended.

// The view (one slot per view, bound with a dynamic offset).
@group(1) @binding(0) var<uniform> shadow_view: ShadowViewGpu;
// Per mesh: 1 where it casts into the maps (`hybrid_core::fallback::caster_meshes`).
@group(1) @binding(1) var<storage, read> casters: array<u32>;
// The point clouds' spheres (`spheres::GpuSphere`).
struct Sphere {
    center: vec3<f32>,
    radius: f32,
    albedo: vec3<f32>,
    cloud: u32,
}
@group(1) @binding(2) var<storage, read> splat_spheres: array<Sphere>;

// Outside the depth range (z < 0): a primitive with all corners here is clipped away.
const CULLED: vec4<f32> = vec4<f32>(0.0, 0.0, -1.0, 1.0);

// Vertex pulling as raster.wgsl: vertex vi is corner vi % 3 of triangle vi / 3.
@vertex
fn vs_shadow(@builtin(vertex_index) vi: u32) -> @builtin(position) vec4<f32> {
    let t = triangles[vi / 3u];
    if casters[t.mesh] == 0u {
        return CULLED;
    }
    let corner = vi % 3u;
    var index = t.v0;
    if corner == 1u {
        index = t.v1;
    } else if corner == 2u {
        index = t.v2;
    }
    return shadow_view.view_proj * vec4<f32>(vertices[index].position.xyz, 1.0);
}

struct DiscOut {
    @builtin(position) clip: vec4<f32>,
    // Centre x, y and radius, in texels.
    @location(0) @interpolate(flat) disc: vec3<f32>,
}

// One sphere (instance) as a square of two triangles around its disc (hybrid_cpu::fallback's
// `disc`): centre and radius in texels, at the depth of the sphere's point nearest the light.
@vertex
fn vs_disc(@builtin(vertex_index) vi: u32, @builtin(instance_index) si: u32) -> DiscOut {
    var out: DiscOut;
    out.clip = CULLED;
    out.disc = vec3<f32>(0.0);
    let sp = splat_spheres[si];
    let v = shadow_view;
    let pr = project_point(v.view_proj, sp.center);
    if !pr.valid {
        return out;
    }
    let d = linear_depth(v, pr.z);
    var texel = v.texel_world;
    if v.orthographic == 0u {
        texel = v.texel_world * d;
    }
    let n = f32(v.size);
    let r = sp.radius / max(texel, 1e-12);
    let x = pr.uv.x * n;
    let y = pr.uv.y * n;
    if x + r < 0.0 || y + r < 0.0 || x - r > n || y - r > n || !(pr.z >= 0.0 && pr.z <= 1.0) {
        return out;
    }
    let front = min(depth_of(v, max(d - sp.radius, v.near)), 1.0);
    // Corners (-1, -1), (1, -1), (1, 1), (-1, -1), (1, 1), (-1, 1), a texel beyond the disc.
    let corner = vec2<f32>(
        select(-1.0, 1.0, vi == 1u || vi == 2u || vi == 4u),
        select(-1.0, 1.0, vi == 2u || vi == 4u || vi == 5u),
    );
    let p = vec2<f32>(x, y) + corner * (r + 1.0);
    out.clip = vec4<f32>(p.x / n * 2.0 - 1.0, 1.0 - p.y / n * 2.0, front, 1.0);
    out.disc = vec3<f32>(x, y, r);
    return out;
}

// The texels whose centres the disc covers (Greater wins against what is there).
@fragment
fn fs_disc(in: DiscOut) {
    let d = in.clip.xy - in.disc.xy;
    if dot(d, d) > in.disc.z * in.disc.z {
        discard;
    }
}
