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

