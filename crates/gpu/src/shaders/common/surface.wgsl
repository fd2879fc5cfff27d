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

