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

