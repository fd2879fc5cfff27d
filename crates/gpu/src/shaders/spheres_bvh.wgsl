// spheres_bvh.wgsl — the software traversal of the spheres' BVH2 (group 2's nodes), after
// spheres.wgsl: `sphere_trace` for sphere_closest_hit and sphere_any_hit.

/// A 1/d stand-in that stays finite (0·(1/d) would be NaN on a slab plane).
fn sphere_safe_inv(c: f32) -> f32 {
    if abs(c) < 1e-30 {
        return select(1e30, -1e30, c < 0.0);
    }
    return 1.0 / c;
}

/// (entry, exit) of the node's box clipped to [t_min, t_max], padded by 1e-5 relative so tangent
/// hits are never culled (entry > exit: miss).
fn sphere_slab(n: SphereNode, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_max: f32) -> vec2<f32> {
    let a = (n.min - o) * inv;
    let b = (n.max - o) * inv;
    let lo = min(a, b);
    let hi = max(a, b);
    let e = max(max(max(lo.x, lo.y), lo.z), t_min);
    let x = min(min(min(hi.x, hi.y), hi.z), t_max);
    return vec2<f32>(e - abs(e) * 1e-5, x + abs(x) * 1e-5);
}

/// Traversal shared by closest and any hit. `dir` need not be unit length; t is in its units.
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
    let inv = vec3<f32>(sphere_safe_inv(d.x), sphere_safe_inv(d.y), sphere_safe_inv(d.z));

    let root = sphere_slab(sphere_nodes[0], origin, inv, t_min, best_t);
    if root.x > root.y {
        return result;
    }
    var stack_node: array<u32, SPHERE_STACK>;
    var stack_t: array<f32, SPHERE_STACK>;
    var sp = 0u;
    var cur = 0u;
    loop {
        let n = sphere_nodes[cur];
        var descend = false;
        if n.count > 0u {
            for (var slot = n.first; slot < n.first + n.count; slot++) {
                let t = sphere_candidate(origin, d, slot, t_min, best_t, best_id);
                if t >= 0.0 {
                    best_t = t;
                    best_id = sphere_ids[slot];
                    best_slot = slot;
                    if any {
                        return SphereHit(true, best_t / len, best_slot);
                    }
                }
            }
        } else {
            let c0 = sphere_slab(sphere_nodes[n.first], origin, inv, t_min, best_t);
            let c1 = sphere_slab(sphere_nodes[n.first + 1u], origin, inv, t_min, best_t);
            let h0 = c0.x <= c0.y && c0.x <= best_t;
            let h1 = c1.x <= c1.y && c1.x <= best_t;
            if h0 && h1 {
                var near = n.first;
                var far = n.first + 1u;
                var far_e = c1.x;
                if c1.x < c0.x {
                    near = n.first + 1u;
                    far = n.first;
                    far_e = c0.x;
                }
                if sp < SPHERE_STACK {
                    stack_node[sp] = far;
                    stack_t[sp] = far_e;
                    sp++;
                }
                cur = near;
                descend = true;
            } else if h0 {
                cur = n.first;
                descend = true;
            } else if h1 {
                cur = n.first + 1u;
                descend = true;
            }
        }
        if descend {
            continue;
        }
        // Pop the next subtree that can still hold a closer hit.
        var found = false;
        while sp > 0u {
            sp--;
            if stack_t[sp] <= best_t {
                cur = stack_node[sp];
                found = true;
                break;
            }
        }
        if !found {
            break;
        }
    }
    if best_id != 0xffffffffu {
        result = SphereHit(true, best_t / len, best_slot);
    }
    return result;
}
