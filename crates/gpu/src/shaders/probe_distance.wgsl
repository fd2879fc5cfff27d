// probe_distance.wgsl — stage 3b's probe faces (hybrid_cpu::fallback::render_probe): per texel
// of a face just rendered, the distance from the probe's centre to the surface seen, the far
// plane where nothing was drawn, into the probes' distance buffer. The generated constants
// header is prepended.

struct ProbeFace {
    centre: vec4<f32>, // w = the far plane
    base: vec4<u32>,   // x = the face's first texel in `distances`
}

@group(0) @binding(0) var g_position: texture_2d<f32>;
@group(0) @binding(1) var g_object_id: texture_2d<u32>;
@group(0) @binding(2) var<storage, read_write> distances: array<f32>;
@group(0) @binding(3) var<uniform> face: ProbeFace;

@compute @workgroup_size(8, 8, 1)
fn probe_distance(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(g_object_id);
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    var d = face.centre.w;
    if textureLoad(g_object_id, gid.xy, 0).x != NO_OBJECT {
        d = min(distance(textureLoad(g_position, gid.xy, 0).xyz, face.centre.xyz), face.centre.w);
    }
    distances[face.base.x + gid.y * size.x + gid.x] = d;
}
