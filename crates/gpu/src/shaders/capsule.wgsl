// capsule.wgsl — paper 2's RT-scene capsule as one compute pass (8×8), after common/*.wgsl and
// spheres.wgsl: per pixel the CPU capsule's primary ray (hybrid_cpu::capsule::RayGen, from the
// frame's `raygen_*` uniforms, operation for operation), the closest sphere, its Blinn–Phong
// shading with the scene's lights and ambient, block D (reversed-Z depth from t) and block P
// (RGBA16UI texel: A = sRGB colour bytes, B = depth bits). A miss writes all zero.

@group(1) @binding(0) var packed_out: texture_storage_2d<rgba16uint, write>;
/// Per pixel the global id of the sphere hit (cloud offset + point index), 0xffffffff on a miss
/// (for tests and debugging: which sphere each texel shows).
@group(1) @binding(1) var<storage, read_write> hit_ids: array<u32>;
/// The polygons' reversed-Z depth (0 = nothing drawn), read when CLIP is set.
@group(1) @binding(2) var clip_depth: texture_depth_2d;

/// Beyond paper 2 (`--clip-capsule`): stop each ray at the polygon depth, as the CPU capsule's
/// `clip_depth` (`t = z_e / dir_view_z` with z_e from the depth, RayGen::t_at_depth).
override CLIP: bool = false;

/// RayGen's `view_inv.transform_vector3(v)`: ((x·vx + y·vy) + z·vz) in glam's order.
fn capsule_rotate(v: vec3<f32>) -> vec3<f32> {
    let r = (frame.raygen_rot[1].xyz * v.y + frame.raygen_rot[0].xyz * v.x);
    return r + frame.raygen_rot[2].xyz * v.z;
}

/// glam's `normalize`: v · (1/|v|).
fn capsule_normalize(v: vec3<f32>) -> vec3<f32> {
    return v * (1.0 / sqrt(dot(v, v)));
}

/// GLSL packUnorm4x8 as hybrid-core's `pack_unorm4x8`: floor(0.5 + 255·clamp(c, 0, 1)), r low.
fn capsule_pack_unorm4x8(c: vec4<f32>) -> u32 {
    let q = vec4<u32>(floor(vec4<f32>(0.5) + 255.0 * clamp(c, vec4<f32>(0.0), vec4<f32>(1.0))));
    return q.x | (q.y << 8u) | (q.z << 16u) | (q.w << 24u);
}

@compute @workgroup_size(8, 8)
fn capsule_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = u32(frame.size.x);
    let h = u32(frame.size.y);
    if gid.x >= w || gid.y >= h {
        return;
    }
    let pixel = gid.y * w + gid.x;
    // Ray generation (paper eq. 3–5), exactly as RayGen::ray.
    let x = 2.0 * (f32(gid.x) + 0.5) / frame.size.x - 1.0;
    let y = 1.0 - 2.0 * (f32(gid.y) + 0.5) / frame.size.y;
    let sx = frame.raygen_proj.x;
    let sy = frame.raygen_proj.y;
    let near = frame.raygen_proj.z;
    let far = frame.raygen_proj.w;
    let ortho = frame.camera_position.w == 1.0;
    var origin: vec3<f32>;
    var dir: vec3<f32>;
    var dir_view_z: f32;
    var t_min: f32;
    var t_max: f32;
    if ortho {
        origin = frame.raygen_eye.xyz + capsule_rotate(vec3<f32>(x / sx, y / sy, 0.0));
        dir = capsule_normalize(capsule_rotate(vec3<f32>(0.0, 0.0, -1.0)));
        dir_view_z = -1.0;
        t_min = near;
        t_max = far;
    } else {
        let dv = capsule_normalize(vec3<f32>(x / sx, y / sy, -1.0));
        dir = capsule_rotate(dv);
        origin = frame.raygen_eye.xyz;
        dir_view_z = dv.z;
        t_min = near / -dv.z;
        t_max = far / -dv.z;
    }

    if CLIP {
        let z = textureLoad(clip_depth, vec2<i32>(gid.xy), 0);
        if z > 0.0 {
            var z_e: f32;
            if ortho {
                z_e = z * (far - near) - far;
            } else {
                z_e = -near * far / ((far - near) * z + near);
            }
            t_max = min(t_max, z_e / dir_view_z);
        }
    }

    let hit = sphere_closest_hit(origin, dir, t_min, t_max);
    if !hit.hit {
        textureStore(packed_out, vec2<i32>(gid.xy), vec4<u32>(0u));
        hit_ids[pixel] = 0xffffffffu;
        return;
    }
    let s = sphere_surface(hit.index, origin + dir * hit.t, dir);
    let color = local_lighting(s, -dir);

    // Block D: reversed-Z window depth of the hit (hybrid-core's synthesize_depth[_orthographic]).
    let z_e = hit.t * dir_view_z;
    var depth: f32;
    if ortho {
        depth = (far + z_e) / (far - near);
    } else {
        depth = near * (far + z_e) / ((far - near) * -z_e);
    }

    // Block P: A = sRGB-encoded colour with alpha 1, B = the depth's bits.
    let a = capsule_pack_unorm4x8(vec4<f32>(linear_to_srgb(color.x), linear_to_srgb(color.y), linear_to_srgb(color.z), 1.0));
    let b = bitcast<u32>(depth);
    textureStore(packed_out, vec2<i32>(gid.xy), vec4<u32>(a & 0xffffu, a >> 16u, b & 0xffffu, b >> 16u));
    hit_ids[pixel] = sphere_ids[hit.index];
}
