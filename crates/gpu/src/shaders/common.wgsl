// common.wgsl — prepended to every shader of the GPU backend (see `shaders.rs`).
// Group 0 is the scene (`scene.rs`, `SceneGpu`); the functions here are the WGSL twins of
// hybrid-core's shading (`shading.rs`) and hybrid-cpu's surface evaluation (`prepare.rs`), so the
// raster, lighting and trace passes all see and light surfaces exactly as the CPU backend does.

struct FrameUniforms {
    view_proj: mat4x4<f32>,
    inv_view_proj: mat4x4<f32>,
    camera_position: vec4<f32>, // w = 1: orthographic
    camera_forward: vec4<f32>,
    camera_right: vec4<f32>,    // × half width (at distance 1, or world units when orthographic)
    camera_up: vec4<f32>,       // × half height
    size: vec4<f32>,            // width, height, 1/width, 1/height
    near_far: vec4<f32>,        // near, far, pixel size at distance 1 (or world, orthographic), -
    env_ambient: vec4<f32>,     // rgb, w = environment IOR
    sky_zenith: vec4<f32>,
    sky_horizon: vec4<f32>,
    sky_ground: vec4<f32>,
    sky_faces0: vec4<i32>,
    sky_faces1: vec4<i32>,      // faces +Z, -Z, sky kind, -
    counts: vec4<u32>,          // lights, objects, triangles, -
    raygen_rot: array<vec4<f32>, 3>, // the CPU capsule's RayGen: view → world rotation columns
    raygen_eye: vec4<f32>,      // camera position exactly
    raygen_proj: vec4<f32>,     // P00, P11, near, far
}

struct Vertex {
    position: vec4<f32>,
    normal: vec4<f32>,
    uv: vec4<f32>,
    tangent: vec4<f32>,
    color: vec4<f32>,
}

struct Triangle {
    v0: u32,
    v1: u32,
    v2: u32,
    mesh: u32,
}

struct MeshInfo {
    object: u32,
    material: u32,
    flags: u32,
    first_triangle: u32,
}

struct Material {
    emission: vec4<f32>,
    ambient: vec4<f32>,
    diffuse: vec4<f32>,      // rgb, a = opacity
    specular: vec4<f32>,     // rgb, a = shininess
    optical: vec4<f32>,      // reflectivity, IOR, casts_shadows, textured
    uv_transform: vec4<f32>, // tiling.xy, offset.xy
    maps0: vec4<i32>,        // emission, ambient, diffuse, specular
    maps1: vec4<i32>,        // normal, optical, -, -
}

struct Light {
    kind: vec4<u32>,        // kind, casts_shadows, -, -
    position: vec4<f32>,
    direction: vec4<f32>,   // directional: towards the light; spot: where it points
    power: vec4<f32>,       // colour × intensity
    attenuation: vec4<f32>, // constant, linear, quadratic
    cone: vec4<f32>,        // cos inner, cos outer
}

@group(0) @binding(0) var<uniform> frame: FrameUniforms;
@group(0) @binding(1) var<storage, read> vertices: array<Vertex>;
@group(0) @binding(2) var<storage, read> triangles: array<Triangle>;
@group(0) @binding(3) var<storage, read> meshes: array<MeshInfo>;
@group(0) @binding(4) var<storage, read> materials: array<Material>;
// Texture directory: entry t (< texture count) = (first level entry, level count, sRGB, -);
// level entries = (texel offset, width, height, page).
@group(0) @binding(5) var<storage, read> tex_dir: array<vec4<u32>>;
@group(0) @binding(6) var<storage, read> texels0: array<u32>;
@group(0) @binding(7) var<storage, read> texels1: array<u32>;
@group(0) @binding(8) var<storage, read> lights: array<Light>;

/// What the G-buffer holds for one pixel (hybrid_core::Surface).
struct Surface {
    position: vec3<f32>,
    normal: vec3<f32>,
    emission: vec3<f32>,
    ambient: vec3<f32>,
    diffuse: vec3<f32>,
    opacity: f32,
    specular: vec3<f32>,
    shininess: f32,
    reflectivity: f32,
    ior: f32,
}

fn is_finite(x: f32) -> bool {
    return abs(x) <= 3.402823e38;
}

fn normalize_or(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let len2 = dot(v, v);
    if len2 > 0.0 && is_finite(len2) {
        return v * inverseSqrt(len2);
    }
    return fallback;
}

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        return c / 12.92;
    }
    return pow((c + 0.055) / 1.055, 2.4);
}

fn linear_to_srgb(x: f32) -> f32 {
    let c = clamp(x, 0.0, 1.0);
    if c <= 0.0031308 {
        return c * 12.92;
    }
    return 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

fn specular_exponent(shininess: f32) -> f32 {
    return 1.0 + clamp(shininess, 0.0, 1.0) * 254.0;
}

// ---- textures (hybrid_scene::Texture / hybrid_cpu::prepare::sample_texture) ----

fn texel(tex: u32, level: u32, x: u32, y: u32) -> vec4<f32> {
    let header = tex_dir[tex];
    let l = tex_dir[header.x + level];
    let i = l.x + y * l.y + x;
    var packed: u32;
    if l.w == 0u {
        packed = texels0[i];
    } else {
        packed = texels1[i];
    }
    let t = unpack4x8unorm(packed);
    if header.z == 1u {
        return vec4<f32>(srgb_to_linear(t.x), srgb_to_linear(t.y), srgb_to_linear(t.z), t.w);
    }
    return t;
}

/// Bilinear sample of one mip level, repeat addressing; uv (0,0) = top-left.
fn sample_bilinear(tex: u32, uv: vec2<f32>, level_in: u32) -> vec4<f32> {
    let header = tex_dir[tex];
    let level = min(level_in, header.y - 1u);
    let l = tex_dir[header.x + level];
    if !is_finite(uv.x) || !is_finite(uv.y) {
        return texel(tex, level, 0u, 0u);
    }
    let w = l.y;
    let h = l.z;
    let x = (uv.x - floor(uv.x)) * f32(w) - 0.5;
    let y = (uv.y - floor(uv.y)) * f32(h) - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let xi = i32(x0);
    let yi = i32(y0);
    var ix0 = min(u32(max(xi, 0)), w - 1u);
    if xi < 0 { ix0 = w - 1u; }
    var iy0 = min(u32(max(yi, 0)), h - 1u);
    if yi < 0 { iy0 = h - 1u; }
    var ix1 = u32(max(xi + 1, 0));
    if xi + 1 >= i32(w) { ix1 = 0u; }
    var iy1 = u32(max(yi + 1, 0));
    if yi + 1 >= i32(h) { iy1 = 0u; }
    let a = mix(texel(tex, level, ix0, iy0), texel(tex, level, ix1, iy0), fx);
    let b = mix(texel(tex, level, ix0, iy1), texel(tex, level, ix1, iy1), fx);
    return mix(a, b, fy);
}

/// Trilinear sample for a UV footprint (UV units per pixel), as the CPU's `sample_texture`.
fn sample_texture(tex: u32, uv: vec2<f32>, footprint: f32) -> vec4<f32> {
    let header = tex_dir[tex];
    let base = tex_dir[header.x];
    let texels = footprint * f32(max(base.y, base.z));
    var lod = 0.0;
    if texels > 1.0 {
        lod = log2(texels);
    }
    let max_lod = f32(header.y - 1u);
    if is_finite(lod) {
        lod = clamp(lod, 0.0, max_lod);
    } else {
        lod = 0.0;
    }
    let l0 = floor(lod);
    let f = lod - l0;
    let a = sample_bilinear(tex, uv, u32(l0));
    if f <= 1e-4 {
        return a;
    }
    return mix(a, sample_bilinear(tex, uv, u32(l0) + 1u), f);
}

fn sample_map(map: i32, uv: vec2<f32>, footprint: f32) -> vec4<f32> {
    if map < 0 {
        return vec4<f32>(1.0);
    }
    return sample_texture(u32(map), uv, footprint);
}

// ---- surfaces (hybrid_cpu::prepare::TriangleSurface::at) ----

/// Interpolated attributes of a point on a triangle of `mesh`.
struct SurfacePoint {
    mesh: u32,
    position: vec3<f32>,
    /// Interpolated vertex normal (ignored when the mesh has none).
    normal: vec3<f32>,
    geometric_normal: vec3<f32>,
    uv: vec2<f32>,
    /// Interpolated tangent (xyz) and the bitangent sign (w, ±1).
    tangent: vec4<f32>,
    color: vec3<f32>,
    /// UV change per pixel, for mip selection.
    uv_footprint: f32,
}

fn evaluate_surface(p: SurfacePoint) -> Surface {
    let info = meshes[p.mesh];
    let mat = materials[info.material];
    var s: Surface;
    s.position = p.position;
    var normal = p.geometric_normal;
    if (info.flags & MESH_HAS_NORMALS) != 0u {
        normal = normalize_or(p.normal, p.geometric_normal);
    }
    var color = vec3<f32>(1.0);
    if (info.flags & MESH_HAS_COLORS) != 0u {
        color = p.color;
    }
    if mat.optical.w == 0.0 {
        // No maps: every sample would be 1.
        s.normal = normal;
        s.emission = mat.emission.xyz;
        s.ambient = mat.ambient.xyz;
        s.diffuse = mat.diffuse.xyz * color;
        s.opacity = clamp(mat.diffuse.w, 0.0, 1.0);
        s.specular = mat.specular.xyz;
        s.shininess = clamp(mat.specular.w, 0.0, 1.0);
        s.reflectivity = clamp(mat.optical.x, 0.0, 1.0);
        s.ior = mat.optical.y;
        return s;
    }
    var uv = vec2<f32>(0.0);
    if (info.flags & MESH_HAS_UVS) != 0u {
        uv = p.uv;
    }
    let tiling = mat.uv_transform.xy;
    uv = mat.uv_transform.zw + uv * tiling;
    var footprint = 0.0;
    if (info.flags & MESH_HAS_UVS) != 0u {
        footprint = p.uv_footprint * max(abs(tiling.x), abs(tiling.y));
    }
    if mat.maps1.x >= 0 && (info.flags & MESH_HAS_TANGENTS) != 0u {
        let t = p.tangent.xyz;
        let tangent = normalize_or(t - normal * dot(normal, t), vec3<f32>(0.0));
        if any(tangent != vec3<f32>(0.0)) {
            var sign = 1.0;
            if p.tangent.w < 0.0 { sign = -1.0; }
            let bitangent = cross(normal, tangent) * sign;
            let n_ts = sample_texture(u32(mat.maps1.x), uv, footprint).xyz * 2.0 - vec3<f32>(1.0);
            normal = normalize_or(tangent * n_ts.x + bitangent * n_ts.y + normal * n_ts.z, normal);
        }
    }
    let d = sample_map(mat.maps0.z, uv, footprint);
    let sp = sample_map(mat.maps0.w, uv, footprint);
    let o = sample_map(mat.maps1.y, uv, footprint);
    s.normal = normal;
    s.emission = mat.emission.xyz * sample_map(mat.maps0.x, uv, footprint).xyz;
    // Loaders give ambient the diffuse map when no ambient map is named: one sample serves both.
    var a = d;
    if mat.maps0.y != mat.maps0.z {
        a = sample_map(mat.maps0.y, uv, footprint);
    }
    s.ambient = mat.ambient.xyz * a.xyz;
    s.diffuse = mat.diffuse.xyz * d.xyz * color;
    s.opacity = clamp(mat.diffuse.w * d.w * o.z, 0.0, 1.0);
    s.specular = mat.specular.xyz * sp.xyz;
    s.shininess = clamp(mat.specular.w * sp.w, 0.0, 1.0);
    s.reflectivity = clamp(mat.optical.x * o.x, 0.0, 1.0);
    s.ior = mat.optical.y * o.y;
    return s;
}

/// The unit geometric normal of triangle `tri` (Y when degenerate).
fn triangle_geometric_normal(tri: u32) -> vec3<f32> {
    let t = triangles[tri];
    let p0 = vertices[t.v0].position.xyz;
    let p1 = vertices[t.v1].position.xyz;
    let p2 = vertices[t.v2].position.xyz;
    return normalize_or(cross(p1 - p0, p2 - p0), vec3<f32>(0.0, 1.0, 0.0));
}

/// The surface at barycentric coordinates `bary` (weights of corners 0, 1, 2) of triangle
/// `tri`, as `PreparedScene::surface_at` (trace hits, rt-only primary hits).
fn triangle_surface_at(tri: u32, bary: vec3<f32>, uv_footprint: f32) -> Surface {
    let t = triangles[tri];
    let a = vertices[t.v0];
    let b = vertices[t.v1];
    let c = vertices[t.v2];
    var p: SurfacePoint;
    p.mesh = t.mesh;
    p.position = a.position.xyz * bary.x + b.position.xyz * bary.y + c.position.xyz * bary.z;
    p.normal = a.normal.xyz * bary.x + b.normal.xyz * bary.y + c.normal.xyz * bary.z;
    p.geometric_normal = normalize_or(cross(b.position.xyz - a.position.xyz, c.position.xyz - a.position.xyz), vec3<f32>(0.0, 1.0, 0.0));
    p.uv = a.uv.xy * bary.x + b.uv.xy * bary.y + c.uv.xy * bary.z;
    p.tangent = vec4<f32>(a.tangent.xyz * bary.x + b.tangent.xyz * bary.y + c.tangent.xyz * bary.z, a.tangent.w);
    p.color = a.color.xyz * bary.x + b.color.xyz * bary.y + c.color.xyz * bary.z;
    p.uv_footprint = uv_footprint;
    return evaluate_surface(p);
}

// ---- camera ----

struct Ray {
    origin: vec3<f32>,
    dir: vec3<f32>,
}

/// The primary ray through continuous image position (sx, sy) in pixels ((0,0) top-left,
/// pixel centres at +0.5), as hybrid-cpu's `ViewRays::ray_at`.
fn primary_ray(sx: f32, sy: f32) -> Ray {
    let nx = sx * frame.size.z * 2.0 - 1.0;
    let ny = 1.0 - sy * frame.size.w * 2.0;
    let offset = frame.camera_right.xyz * nx + frame.camera_up.xyz * ny;
    let fwd = frame.camera_forward.xyz;
    if frame.camera_position.w == 1.0 {
        return Ray(frame.camera_position.xyz + offset, fwd);
    }
    return Ray(frame.camera_position.xyz, normalize_or(fwd + offset, fwd));
}

/// Unit direction from a surface point towards the viewer (−forward for orthographic).
fn view_dir(p: vec3<f32>) -> vec3<f32> {
    let fwd = frame.camera_forward.xyz;
    if frame.camera_position.w == 1.0 {
        return -fwd;
    }
    return normalize_or(frame.camera_position.xyz - p, -fwd);
}

// ---- lights (hybrid_core::shading) ----

fn spot_cone(cos_angle: f32, cos_inner: f32, cos_outer: f32) -> f32 {
    if cos_inner <= cos_outer {
        return select(0.0, 1.0, cos_angle >= cos_outer);
    }
    let t = clamp((cos_angle - cos_outer) / (cos_inner - cos_outer), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

fn attenuation_factor(a: vec4<f32>, d: f32) -> f32 {
    return 1.0 / max(a.x + a.y * d + a.z * d * d, 1e-12);
}

/// Direction towards the light from `p`, distance (a huge value for directional lights) and
/// the radiance arriving at `p` (unshadowed).
struct Incident {
    dir: vec3<f32>,
    distance: f32,
    radiance: vec3<f32>,
}

const FAR_AWAY: f32 = 3.0e38;

fn light_incident(light: Light, p: vec3<f32>) -> Incident {
    if light.kind.x == LIGHT_DIRECTIONAL {
        return Incident(light.direction.xyz, FAR_AWAY, light.power.xyz);
    }
    let d = light.position.xyz - p;
    let len = length(d);
    var dir = vec3<f32>(0.0, 1.0, 0.0);
    if len > 0.0 {
        dir = d / len;
    }
    var radiance = light.power.xyz * attenuation_factor(light.attenuation, len);
    if light.kind.x == LIGHT_SPOT {
        radiance = radiance * spot_cone(dot(-dir, light.direction.xyz), light.cone.x, light.cone.y);
    }
    return Incident(dir, len, radiance);
}

/// The normal flipped, if needed, to the viewer's side.
fn facing(n: vec3<f32>, view: vec3<f32>) -> vec3<f32> {
    if dot(n, view) < 0.0 {
        return -n;
    }
    return n;
}

/// Blinn–Phong contribution of light `i` to `s` seen along `view` (unshadowed).
fn blinn_phong(i: u32, s: Surface, view: vec3<f32>) -> vec3<f32> {
    let inc = light_incident(lights[i], s.position);
    if all(inc.radiance == vec3<f32>(0.0)) {
        return vec3<f32>(0.0);
    }
    let n = facing(s.normal, view);
    let n_dot_l = dot(n, inc.dir);
    if n_dot_l <= 0.0 {
        return vec3<f32>(0.0);
    }
    var spec = vec3<f32>(0.0);
    if any(s.specular != vec3<f32>(0.0)) {
        let h = normalize_or(inc.dir + view, vec3<f32>(0.0));
        spec = s.specular * pow(max(dot(n, h), 0.0), specular_exponent(s.shininess));
    }
    return (s.diffuse * n_dot_l + spec) * inc.radiance;
}

/// Listing 5: emission + env_ambient · ambient + Σ lights Blinn–Phong, unshadowed.
fn local_lighting(s: Surface, view: vec3<f32>) -> vec3<f32> {
    var c = s.emission + frame.env_ambient.xyz * s.ambient;
    for (var i = 0u; i < frame.counts.x; i++) {
        c += blinn_phong(i, s, view);
    }
    return c;
}

// ---- directions (listings 8a/8c) ----

fn reflect_dir(i: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return i - 2.0 * dot(n, i) * n;
}

/// Refraction between the environment and the material (entering when `i` goes against `n`),
/// falling back to the reflection on total internal reflection. xyz direction, w = 1 on TIR.
fn refract_or_reflect(i: vec3<f32>, n_in: vec3<f32>, env_ior: f32, mat_ior: f32) -> vec4<f32> {
    var n = n_in;
    var eta = env_ior / mat_ior;
    if dot(i, n_in) >= 0.0 {
        n = -n_in;
        eta = mat_ior / env_ior;
    }
    let cos_i = -dot(n, i);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        return vec4<f32>(reflect_dir(i, n_in), 1.0);
    }
    return vec4<f32>(normalize(eta * i + (eta * cos_i - sqrt(k)) * n), 0.0);
}

// ---- skybox (listing 8d) ----

fn cube_face_uv(d: vec3<f32>) -> vec3<f32> {
    let a = abs(d);
    var face = 0.0;
    var sc = 0.0;
    var tc = 0.0;
    var ma = 0.0;
    if a.x >= a.y && a.x >= a.z {
        if d.x > 0.0 { face = 0.0; sc = -d.z; tc = -d.y; } else { face = 1.0; sc = d.z; tc = -d.y; }
        ma = a.x;
    } else if a.y >= a.z {
        if d.y > 0.0 { face = 2.0; sc = d.x; tc = d.z; } else { face = 3.0; sc = d.x; tc = -d.z; }
        ma = a.y;
    } else {
        if d.z > 0.0 { face = 4.0; sc = d.x; tc = -d.y; } else { face = 5.0; sc = -d.x; tc = -d.y; }
        ma = a.z;
    }
    if !(ma > 0.0) { ma = 1.0; }
    return vec3<f32>(face, 0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0));
}

/// Linear skybox radiance along `dir`.
fn sky(dir: vec3<f32>) -> vec3<f32> {
    let kind = frame.sky_faces1.z;
    if kind == SKY_GRADIENT {
        let y = clamp(normalize_or(dir, vec3<f32>(0.0)).y, -1.0, 1.0);
        if y >= 0.0 {
            return mix(frame.sky_horizon.xyz, frame.sky_zenith.xyz, y);
        }
        return mix(frame.sky_horizon.xyz, frame.sky_ground.xyz, -y);
    }
    if kind == SKY_CUBE {
        let f = cube_face_uv(dir);
        let face = u32(f.x);
        var tex = 0;
        switch face {
            case 0u: { tex = frame.sky_faces0.x; }
            case 1u: { tex = frame.sky_faces0.y; }
            case 2u: { tex = frame.sky_faces0.z; }
            case 3u: { tex = frame.sky_faces0.w; }
            case 4u: { tex = frame.sky_faces1.x; }
            default: { tex = frame.sky_faces1.y; }
        }
        return sample_bilinear(u32(tex), f.yz, 0u).xyz;
    }
    return frame.sky_zenith.xyz;
}

// ---- G-buffer outputs (targets::GBUFFER_COLOR_FORMATS order) ----

/// The 8 G-buffer colour outputs of the passes that draw into the G-buffer.
struct GBufferOut {
    @location(0) position: vec4<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) emission: vec4<f32>,
    @location(3) ambient: vec4<f32>,
    @location(4) diffuse: vec4<f32>,  // rgb, a = opacity
    @location(5) specular: vec4<f32>, // rgb, a = shininess
    @location(6) optical: vec4<f32>,  // reflectivity, IOR, opacity
    @location(7) object_id: u32,
}

/// `GBufferOut` plus the fragment's depth, for full-screen passes that find their surface
/// themselves (primary rays, the capsule's unpack).
struct GBufferDepthOut {
    @location(0) position: vec4<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) emission: vec4<f32>,
    @location(3) ambient: vec4<f32>,
    @location(4) diffuse: vec4<f32>,
    @location(5) specular: vec4<f32>,
    @location(6) optical: vec4<f32>,
    @location(7) object_id: u32,
    @builtin(frag_depth) depth: f32,
}

fn gbuffer_out(s: Surface, object_id: u32) -> GBufferOut {
    return GBufferOut(
        vec4<f32>(s.position, 1.0),
        vec4<f32>(s.normal, 0.0),
        vec4<f32>(s.emission, 1.0),
        vec4<f32>(s.ambient, 1.0),
        vec4<f32>(s.diffuse, s.opacity),
        vec4<f32>(s.specular, s.shininess),
        vec4<f32>(s.reflectivity, s.ior, s.opacity, 1.0),
        object_id,
    );
}

fn gbuffer_depth_out(s: Surface, object_id: u32, depth: f32) -> GBufferDepthOut {
    let o = gbuffer_out(s, object_id);
    return GBufferDepthOut(o.position, o.normal, o.emission, o.ambient, o.diffuse, o.specular, o.optical, o.object_id, depth);
}

/// Vertex `i` (0, 1, 2) of one triangle covering the whole screen.
fn fullscreen_vertex(i: u32) -> vec4<f32> {
    return vec4<f32>(f32(i32(i & 1u) * 4 - 1), f32(i32(i >> 1u) * 4 - 1), 0.0, 1.0);
}
