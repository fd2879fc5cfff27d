// spheres_rq.wgsl — the spheres' traversal in hardware (paper 2's intersection shader in
// ray-query form), after spheres.wgsl and rq.wgsl: `sphere_trace` for sphere_closest_hit and
// sphere_any_hit. The spheres are one AABB geometry (primitive index = slot, boxes padded so the
// hardware never culls a tangent hit); each candidate box runs the software path's own
// perpendicular-distance test (`sphere_ray_t`) and the tie rule (lower global index), so hits are
// the software path's exactly. The query's committed t only prunes the traversal.

fn sphere_trace(origin: vec3<f32>, dir: vec3<f32>, tmin: f32, tmax: f32, any: bool) -> SphereHit {
    var result = SphereHit(false, 0.0, 0u);
    let ray = sphere_ray(dir, tmin, tmax);
    if sphere_info.nodes == 0u || !ray.ok {
        return result;
    }
    let d = ray.d;
    let len = ray.len;
    let t_min = ray.t_min;
    var best_t = ray.t_max;
    var best_id = 0xffffffffu;
    var best_slot = 0u;
    // The callers' rays start at t >= 0 (the capsule's near plane, the trace's biased origins);
    // FAR_AWAY × |dir| may overflow, the query's range stays finite.
    let ray_min = max(t_min, 0.0);
    let ray_max = min(best_t, FAR_AWAY);
    if !rq_ray_ok(origin, d, ray_min, ray_max) {
        return result;
    }
    var rq: ray_query;
    rayQueryInitialize(&rq, rt_scene, RayDesc(RAY_FLAG_NONE, RT_MASK_SPHERES, ray_min, ray_max, origin, d));
    while rayQueryProceed(&rq) {
        let c = rayQueryGetCandidateIntersection(&rq);
        if c.kind != RAY_QUERY_INTERSECTION_AABB {
            continue;
        }
        let slot = c.primitive_index;
        let t = sphere_candidate(origin, d, slot, t_min, best_t, best_id);
        if t >= 0.0 {
            best_t = t;
            best_id = sphere_ids[slot];
            best_slot = slot;
            if any {
                rayQueryTerminate(&rq);
                return SphereHit(true, best_t / len, best_slot);
            }
            // `t` directly (a value computed before this statement): naga 30 does not emit an
            // expression computed in the call itself ("used by a statement before it was
            // introduced"). A t beyond the query's range is skipped by naga's check.
            rayQueryGenerateIntersection(&rq, t);
        }
    }
    if best_id != 0xffffffffu {
        result = SphereHit(true, best_t / len, best_slot);
    }
    return result;
}
