// bvh.wgsl — triangle BVH traversal (the twin of hybrid-cpu's `bvh.rs`; layout in `bvh.rs`,
// `TriangleBvhGpu`). Needs common/*.wgsl before it. Group 1, bindings 0 and 1.

struct BvhNode {
    min: vec4<f32>, // w = bits of first: inner → first child (second at +1), leaf → first slot
    max: vec4<f32>, // w = bits of count: 0 = inner node
}

struct BvhTri {
    v0: vec4<f32>, // w = bits of the triangle index (into `triangles`)
    e1: vec4<f32>, // w = shadow transparency: 1 ignored, 0 opaque, -1 evaluated at the hit
    e2: vec4<f32>,
}

@group(1) @binding(0) var<storage, read> bvh_nodes: array<BvhNode>;
@group(1) @binding(1) var<storage, read> bvh_tris: array<BvhTri>;

const NO_HIT: u32 = 0xffffffffu;

/// A ray–triangle hit: distance, triangle index (NO_HIT on a miss), weights of its corners.
struct Hit {
    t: f32,
    tri: u32,
    bary: vec3<f32>,
}

/// 1/d with zero components made tiny (so the slab test sees no infinities).
fn bvh_inverse(d: vec3<f32>) -> vec3<f32> {
    let tiny = vec3<f32>(1e-30);
    return 1.0 / select(d, tiny, abs(d) < tiny);
}

/// Slab test: (entry, exit) distances of the box clipped to [tmin, tmax]; hit when x <= y.
fn bvh_box(n: BvhNode, o: vec3<f32>, inv: vec3<f32>, tmin: f32, tmax: f32) -> vec2<f32> {
    let a = (n.min.xyz - o) * inv;
    let b = (n.max.xyz - o) * inv;
    let lo = min(a, b);
    let hi = max(a, b);
    return vec2<f32>(max(max(max(lo.x, lo.y), lo.z), tmin), min(min(min(hi.x, hi.y), hi.z), tmax));
}

/// Möller–Trumbore (the CPU's `intersect4` for one lane): (t, u, v, 1 when hit with
/// tmin < t < tmax); u, v are the weights of corners 1 and 2.
fn bvh_triangle(tr: BvhTri, o: vec3<f32>, d: vec3<f32>, tmin: f32, tmax: f32) -> vec4<f32> {
    let e1 = tr.e1.xyz;
    let e2 = tr.e2.xyz;
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det == 0.0 {
        return vec4<f32>(0.0);
    }
    let inv_det = 1.0 / det;
    let s = o - tr.v0.xyz;
    let u = dot(s, p) * inv_det;
    let q = cross(s, e1);
    let v = dot(d, q) * inv_det;
    let t = dot(e2, q) * inv_det;
    let hit = u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > tmin && t < tmax;
    return vec4<f32>(t, u, v, select(0.0, 1.0, hit));
}

/// The closest triangle hit with tmin < t < tmax along o + t·d (tri = NO_HIT when none):
/// ordered traversal, nearer child first; stacked entries farther than the best hit are skipped.
fn closest_hit(o: vec3<f32>, d: vec3<f32>, tmin: f32, tmax: f32) -> Hit {
    var best = Hit(tmax, NO_HIT, vec3<f32>(0.0));
    let inv = bvh_inverse(d);
    let root = bvh_box(bvh_nodes[0], o, inv, tmin, tmax);
    if root.x > root.y {
        return best;
    }
    var stack_node: array<u32, BVH_STACK>;
    var stack_t: array<f32, BVH_STACK>;
    var sp = 0u;
    var cur = 0u;
    loop {
        let n = bvh_nodes[cur];
        let first = bitcast<u32>(n.min.w);
        let count = bitcast<u32>(n.max.w);
        if count == 0u {
            let ta = bvh_box(bvh_nodes[first], o, inv, tmin, best.t);
            let tb = bvh_box(bvh_nodes[first + 1u], o, inv, tmin, best.t);
            let hit_a = ta.x <= ta.y;
            let hit_b = tb.x <= tb.y;
            if hit_a && hit_b {
                var near = first;
                var far = first + 1u;
                var far_t = tb.x;
                if tb.x < ta.x {
                    near = first + 1u;
                    far = first;
                    far_t = ta.x;
                }
                if sp < BVH_STACK {
                    stack_node[sp] = far;
                    stack_t[sp] = far_t;
                    sp += 1u;
                }
                cur = near;
                continue;
            }
            if hit_a {
                cur = first;
                continue;
            }
            if hit_b {
                cur = first + 1u;
                continue;
            }
        } else {
            for (var i = first; i < first + count; i++) {
                let tr = bvh_tris[i];
                let h = bvh_triangle(tr, o, d, tmin, best.t);
                if h.w > 0.0 && h.x < best.t {
                    best = Hit(h.x, bitcast<u32>(tr.v0.w), vec3<f32>(1.0 - h.y - h.z, h.y, h.z));
                }
            }
        }
        // The next stacked node that starts before the closest hit so far.
        var found = false;
        while sp > 0u {
            sp -= 1u;
            if stack_t[sp] <= best.t {
                cur = stack_node[sp];
                found = true;
                break;
            }
        }
        if !found {
            break;
        }
    }
    return best;
}

/// Listing 8b: the fraction of light passing along o + t·d, 0 < t < tmax. Every triangle hit
/// whose material casts shadows multiplies it by its transparency (1 − opacity; textured
/// opacity evaluated at the hit); stops at 0. Each triangle counts once.
fn shadow_attenuation(o: vec3<f32>, d: vec3<f32>, tmax: f32) -> f32 {
    let inv = bvh_inverse(d);
    let root = bvh_box(bvh_nodes[0], o, inv, 0.0, tmax);
    if root.x > root.y {
        return 1.0;
    }
    var att = 1.0;
    var stack: array<u32, BVH_STACK>;
    var sp = 0u;
    var cur = 0u;
    loop {
        let n = bvh_nodes[cur];
        let first = bitcast<u32>(n.min.w);
        let count = bitcast<u32>(n.max.w);
        if count == 0u {
            let ta = bvh_box(bvh_nodes[first], o, inv, 0.0, tmax);
            let tb = bvh_box(bvh_nodes[first + 1u], o, inv, 0.0, tmax);
            let hit_a = ta.x <= ta.y;
            let hit_b = tb.x <= tb.y;
            if hit_a && hit_b {
                if sp < BVH_STACK {
                    stack[sp] = first + 1u;
                    sp += 1u;
                }
                cur = first;
                continue;
            }
            if hit_a {
                cur = first;
                continue;
            }
            if hit_b {
                cur = first + 1u;
                continue;
            }
        } else {
            for (var i = first; i < first + count; i++) {
                let tr = bvh_tris[i];
                var transparency = tr.e1.w;
                if transparency == 1.0 {
                    continue;
                }
                let h = bvh_triangle(tr, o, d, 0.0, tmax);
                if h.w == 0.0 {
                    continue;
                }
                if transparency == SHADOW_EVALUATE {
                    let s = triangle_surface_at(bitcast<u32>(tr.v0.w), vec3<f32>(1.0 - h.y - h.z, h.y, h.z), 0.0);
                    transparency = 1.0 - s.opacity;
                }
                att *= transparency;
                if att <= 0.0 {
                    return 0.0;
                }
            }
        }
        if sp == 0u {
            break;
        }
        sp -= 1u;
        cur = stack[sp];
    }
    return max(att, 0.0);
}
