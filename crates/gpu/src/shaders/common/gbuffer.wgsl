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

// GBuffer::surface: the surface a G-buffer's targets hold at px (gbuffer_out's inverse; no
// emission or ambient).
fn surface_at(
    position: texture_2d<f32>,
    normal: texture_2d<f32>,
    diffuse: texture_2d<f32>,
    specular: texture_2d<f32>,
    optical: texture_2d<f32>,
    px: vec2<i32>,
) -> Surface {
    let d = textureLoad(diffuse, px, 0);
    let sp = textureLoad(specular, px, 0);
    let o = textureLoad(optical, px, 0);
    var s: Surface;
    s.position = textureLoad(position, px, 0).xyz;
    s.normal = textureLoad(normal, px, 0).xyz;
    s.diffuse = d.xyz;
    s.opacity = d.w;
    s.specular = sp.xyz;
    s.shininess = sp.w;
    s.reflectivity = o.x;
    s.ior = o.y;
    return s;
}
