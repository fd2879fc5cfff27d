// spheres.wgsl — the RT-scene's spheres (every point of every point cloud) as group 2: a BVH2
// built on the CPU (`spheres.rs`, `SpheresGpu`) and the WGSL twins of hybrid-cpu's sphere code
// (`spheres.rs`: the perpendicular-distance ray–sphere test, ties to the lower index;
// `capsule.rs`: a sphere's surface). Used after common/*.wgsl (Surface, Ray, frame).

struct SphereInfo {
    count: u32,   // spheres
    nodes: u32,   // BVH nodes (0 when there are no spheres)
    clouds: u32,
    _pad: u32,
}

/// One BVH2 node: inner when `count` is 0 (children at `first` and `first + 1`), else a leaf of
/// `count` spheres from slot `first`. Boxes are the spheres' boxes (centre ± radius).
struct SphereNode {
    min: vec3<f32>,
    first: u32,
    max: vec3<f32>,
    count: u32,
}

/// One sphere, in leaf order (slot): centre, radius, linear albedo (the CPU capsule's colour rule,
/// evaluated on the host) and its cloud.
struct Sphere {
    center: vec3<f32>,
    radius: f32,
    albedo: vec3<f32>,
    cloud: u32,
}

/// Per cloud: specular rgb, shininess.
@group(2) @binding(0) var<uniform> sphere_info: SphereInfo;
@group(2) @binding(1) var<storage, read> sphere_nodes: array<SphereNode>;
@group(2) @binding(2) var<storage, read> spheres: array<Sphere>;
/// Global index of the sphere in each slot (cloud offset + point index): the tie-break rule.
@group(2) @binding(3) var<storage, read> sphere_ids: array<u32>;
@group(2) @binding(4) var<storage, read> sphere_clouds: array<vec4<f32>>;


struct SphereHit {
    hit: bool,
    /// In units of the ray direction's length.
    t: f32,
    /// Slot of the sphere (for `sphere_surface`, `spheres[index]`, `sphere_ids[index]`).
    index: u32,
}

/// The ray–sphere test in the perpendicular-distance form (hybrid_cpu::spheres::ray_sphere) for a
/// unit direction `d`: the first intersection in [t_min, t_max], or -1.
fn sphere_ray_t(o: vec3<f32>, d: vec3<f32>, center: vec3<f32>, radius: f32, t_min: f32, t_max: f32) -> f32 {
    let oc = center - o;
    let tc = dot(oc, d);
    let perp = oc - tc * d;
    let p2 = dot(perp, perp);
    let r2 = radius * radius;
    if p2 > r2 {
        return -1.0;
    }
    let half = sqrt(r2 - p2);
    let t0 = tc - half;
    if t0 >= t_min {
        return select(-1.0, t0, t0 <= t_max);
    }
    let t1 = tc + half;
    return select(-1.0, t1, t1 >= t_min && t1 <= t_max);
}

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
    if sphere_info.nodes == 0u {
        return result;
    }
    let len = sqrt(dot(dir, dir));
    if !(len > 0.0 && is_finite(len) && tmax >= tmin) {
        return result;
    }
    let d = dir / len;
    let t_min = tmin * len;
    var best_t = tmax * len;
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
                let s = spheres[slot];
                let t = sphere_ray_t(origin, d, s.center, s.radius, t_min, best_t);
                if t >= 0.0 {
                    let id = sphere_ids[slot];
                    if t < best_t || (t == best_t && id < best_id) {
                        best_t = t;
                        best_id = id;
                        best_slot = slot;
                        if any {
                            return SphereHit(true, best_t / len, best_slot);
                        }
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

/// The closest sphere along `origin + t·dir`, tmin ≤ t ≤ tmax (ties: lower global index).
fn sphere_closest_hit(origin: vec3<f32>, dir: vec3<f32>, tmin: f32, tmax: f32) -> SphereHit {
    return sphere_trace(origin, dir, tmin, tmax, false);
}

/// Whether any sphere lies along the ray within [tmin, tmax] (spheres are opaque casters).
fn sphere_any_hit(origin: vec3<f32>, dir: vec3<f32>, tmin: f32, tmax: f32) -> bool {
    return sphere_trace(origin, dir, tmin, tmax, true).hit;
}

/// glam's `normalize_or` (v · 1/|v|, the fallback when that is not finite and positive).
fn sphere_normalize_or(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let rcp = 1.0 / sqrt(dot(v, v));
    if is_finite(rcp) && rcp > 0.0 {
        return v * rcp;
    }
    return fallback;
}

/// The surface of the sphere in `index` (a slot) at `point`, hit along `dir`: the CPU capsule's
/// `sphere_surface` (albedo as diffuse and ambient, the cloud's specular, opaque, IOR 1).
fn sphere_surface(index: u32, point: vec3<f32>, dir: vec3<f32>) -> Surface {
    let sph = spheres[index];
    let cloud = sphere_clouds[sph.cloud];
    var s: Surface;
    s.position = point;
    s.normal = sphere_normalize_or((point - sph.center) / sph.radius, -dir);
    s.emission = vec3<f32>(0.0);
    s.ambient = sph.albedo;
    s.diffuse = sph.albedo;
    s.opacity = 1.0;
    s.specular = cloud.xyz;
    s.shininess = cloud.w;
    s.reflectivity = 0.0;
    s.ior = 1.0;
    return s;
}
