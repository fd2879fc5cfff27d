// primary.wgsl — the rt-only mode's G-buffer from primary rays (hybrid-cpu's `rt_only_gbuffer`):
// one full-screen triangle; each fragment traces its pixel centre's ray through the triangle BVH
// and writes the raster pass's 8 targets and the hit's reversed-Z depth, or discards on a miss.
// Needs common/*.wgsl and bvh.wgsl before it.

@vertex
fn primary_vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    return fullscreen_vertex(i);
}

fn project(m: mat4x4<f32>, p: vec3<f32>) -> vec3<f32> {
    let c = m * vec4<f32>(p, 1.0);
    return c.xyz / c.w;
}

/// UV change per pixel on triangle `tri` seen along `dir` with pixel size `world` at the hit
/// (hybrid-cpu's `uv_footprint`).
fn uv_footprint(tri: u32, dir: vec3<f32>, world: f32) -> f32 {
    let t = triangles[tri];
    if (meshes[t.mesh].flags & MESH_HAS_UVS) == 0u {
        return 0.0;
    }
    let a = vertices[t.v0];
    let b = vertices[t.v1];
    let c = vertices[t.v2];
    let cr = cross(b.position.xyz - a.position.xyz, c.position.xyz - a.position.xyz);
    let world_area = length(cr);
    let e1 = b.uv.xy - a.uv.xy;
    let e2 = c.uv.xy - a.uv.xy;
    let uv_area = abs(e1.x * e2.y - e1.y * e2.x);
    if !(world_area > 0.0) || !is_finite(world_area) {
        return 0.0;
    }
    let cos = max(abs(dot(cr / world_area, dir)), 0.25);
    let f = world / cos * sqrt(uv_area / world_area);
    if is_finite(f) {
        return f;
    }
    return 0.0;
}

@fragment
fn primary_fs(@builtin(position) frag: vec4<f32>) -> GBufferDepthOut {
    // The ray through the pixel centre from the near plane to the far plane (reversed-Z: NDC
    // z = 1 near, 0 far), from the inverse view-projection as the CPU's `PrimaryRays`.
    let nx = frag.x * frame.size.z * 2.0 - 1.0;
    let ny = 1.0 - frag.y * frame.size.w * 2.0;
    let near = project(frame.inv_view_proj, vec3<f32>(nx, ny, 1.0));
    let far = project(frame.inv_view_proj, vec3<f32>(nx, ny, 0.0));
    let span = far - near;
    let len = length(span);
    if !(len > 0.0) || !is_finite(len) {
        discard;
    }
    let dir = span / len;
    let hit = closest_hit(near, dir, 0.0, len);
    if hit.tri == NO_HIT {
        discard;
    }
    let point = near + dir * hit.t;
    var world = frame.near_far.z;
    if frame.camera_position.w != 1.0 {
        world = world * distance(point, frame.camera_position.xyz);
    }
    let s = triangle_surface_at(hit.tri, hit.bary, uv_footprint(hit.tri, dir, world));
    return gbuffer_depth_out(s, meshes[triangles[hit.tri].mesh].object, clamp(project(frame.view_proj, s.position).z, 0.0, 1.0));
}
