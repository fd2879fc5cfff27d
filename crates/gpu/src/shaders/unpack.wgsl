// unpack.wgsl — paper 2's block U as a full-screen pass, after common/*.wgsl: each fragment reads
// its packed RGBA16UI texel, discards alpha ≤ 0.1, decodes the colour (sRGB → linear) and the
// depth, and writes the RT surface to the G-buffer (hybrid_cpu::raster::rt_surface: emission =
// colour, opaque, IOR 1, position unprojected, normal towards the camera, object RT_SCENE_OBJECT)
// with the depth as `frag_depth` (compare Greater against the cleared reversed-Z depth).

@group(1) @binding(0) var packed_in: texture_2d<u32>;

@vertex
fn unpack_vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    return fullscreen_vertex(i);
}

@fragment
fn unpack_fs(@builtin(position) frag: vec4<f32>) -> GBufferDepthOut {
    let px = vec2<u32>(frag.xy);
    let t = textureLoad(packed_in, px, 0);
    let a = (t.x & 0xffffu) | ((t.y & 0xffffu) << 16u);
    let b = (t.z & 0xffffu) | ((t.w & 0xffffu) << 16u);
    let alpha = f32(a >> 24u) / 255.0;
    if !(alpha > 0.1) {
        discard;
    }
    let byte = vec3<f32>(f32(a & 0xffu), f32((a >> 8u) & 0xffu), f32((a >> 16u) & 0xffu)) / 255.0;
    let color = vec3<f32>(srgb_to_linear(byte.x), srgb_to_linear(byte.y), srgb_to_linear(byte.z));
    let depth = bitcast<f32>(b);

    // The pixel centre at `depth`, unprojected with the inverse view-projection.
    let ndc = vec4<f32>((f32(px.x) + 0.5) * frame.size.z * 2.0 - 1.0, 1.0 - (f32(px.y) + 0.5) * frame.size.w * 2.0, depth, 1.0);
    let h = frame.inv_view_proj * ndc;
    let p = h.xyz / h.w;
    let back = -frame.camera_forward.xyz;
    var normal = back;
    if frame.camera_position.w != 1.0 {
        normal = normalize_or(frame.raygen_eye.xyz - p, back);
    }

    // The RT surface: emission = its colour, no other reflectance, opaque, IOR 1.
    var s: Surface;
    s.position = p;
    s.normal = normal;
    s.emission = color;
    s.opacity = 1.0;
    s.ior = 1.0;
    return gbuffer_depth_out(s, RT_SCENE_OBJECT, depth);
}
