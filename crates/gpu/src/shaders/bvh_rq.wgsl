// bvh_rq.wgsl — the triangle traversal in hardware: wgpu ray queries over the acceleration
// structure of rq.wgsl, the twin of bvh.wgsl (same `Hit`, `closest_hit` and
// `shadow_attenuation`, so the passes that call them compile unchanged against either). Needs
// common/*.wgsl and rq.wgsl before it. A hit's triangle index is its mesh's first triangle (group
// 0's `meshes`; the instance's custom data is the mesh index) plus the primitive index.

const NO_HIT: u32 = 0xffffffffu;

/// A ray–triangle hit: distance, triangle index (NO_HIT on a miss), weights of its corners.
struct Hit {
    t: f32,
    tri: u32,
    bary: vec3<f32>,
}

/// Corner weights from the hardware's barycentrics (the weights of corners 1 and 2).
fn rq_bary(b: vec2<f32>) -> vec3<f32> {
    return vec3<f32>(1.0 - b.x - b.y, b.x, b.y);
}

/// The closest triangle hit with tmin < t < tmax along o + t·d (tri = NO_HIT when none): every
/// triangle opaque for this query, so the hardware commits the nearest itself.
fn closest_hit(o: vec3<f32>, d: vec3<f32>, tmin: f32, tmax: f32) -> Hit {
    var best = Hit(tmax, NO_HIT, vec3<f32>(0.0));
    if !rq_ray_ok(o, d, tmin, tmax) {
        return best;
    }
    var rq: ray_query;
    rayQueryInitialize(&rq, rt_scene, RayDesc(RAY_FLAG_FORCE_OPAQUE, RT_MASK_TRIANGLES, tmin, tmax, o, d));
    while rayQueryProceed(&rq) {
    }
    let h = rayQueryGetCommittedIntersection(&rq);
    if h.kind == RAY_QUERY_INTERSECTION_TRIANGLE {
        best = Hit(h.t, meshes[h.instance_custom_data].first_triangle + h.primitive_index, rq_bary(h.barycentrics));
    }
    return best;
}

/// Listing 8b: the fraction of light passing along o + t·d, 0 < t < tmax. The query sees only
/// meshes that cast shadows (RT_MASK_SHADOW_CASTERS), every triangle as a candidate (any-hit):
/// each multiplies the light by its transparency (1 − opacity; textured opacity evaluated at the
/// hit) and none is committed, so every triangle along the ray counts once; stops at 0.
fn shadow_attenuation(o: vec3<f32>, d: vec3<f32>, tmax: f32) -> f32 {
    if !rq_ray_ok(o, d, 0.0, tmax) {
        return 1.0;
    }
    var att = 1.0;
    var rq: ray_query;
    rayQueryInitialize(&rq, rt_scene, RayDesc(RAY_FLAG_FORCE_NO_OPAQUE, RT_MASK_SHADOW_CASTERS, 0.0, tmax, o, d));
    while rayQueryProceed(&rq) {
        let c = rayQueryGetCandidateIntersection(&rq);
        if c.kind != RAY_QUERY_INTERSECTION_TRIANGLE {
            continue;
        }
        var transparency = rt_mesh_shadow[c.instance_custom_data];
        if transparency == SHADOW_EVALUATE {
            let tri = meshes[c.instance_custom_data].first_triangle + c.primitive_index;
            let s = triangle_surface_at(tri, rq_bary(c.barycentrics), 0.0);
            transparency = 1.0 - s.opacity;
        }
        att *= transparency;
        if att <= 0.0 {
            rayQueryTerminate(&rq);
            return 0.0;
        }
    }
    return max(att, 0.0);
}
