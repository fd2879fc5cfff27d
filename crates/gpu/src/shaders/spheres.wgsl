// spheres.wgsl — the RT-scene's spheres (every point of every point cloud) as group 2: a BVH2
// built on the CPU (`spheres.rs`, `SpheresGpu`) and the WGSL twins of hybrid-cpu's sphere code
// (`spheres.rs`: the perpendicular-distance ray–sphere test, ties to the lower index;
// `capsule.rs`: a sphere's surface). Used after common/*.wgsl (Surface, Ray, frame). The
// traversal (`sphere_trace`) comes from one of two files after this one: spheres_bvh.wgsl (the
// software BVH2) or spheres_rq.wgsl (hardware ray queries over the acceleration structure).

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

/// A traversal's ray in unit-direction form: `d = dir / |dir|`, the t range in its units (both
/// traversals, spheres_bvh.wgsl and spheres_rq.wgsl, start here). `ok` is false for a zero or
/// non-finite direction or an empty range: nothing is hit.
struct SphereRay {
    ok: bool,
    d: vec3<f32>,
    len: f32,
    t_min: f32,
    t_max: f32,
}

fn sphere_ray(dir: vec3<f32>, tmin: f32, tmax: f32) -> SphereRay {
    let len = sqrt(dot(dir, dir));
    if !(len > 0.0 && is_finite(len) && tmax >= tmin) {
        return SphereRay(false, vec3<f32>(0.0), 0.0, 0.0, 0.0);
    }
    return SphereRay(true, dir / len, len, tmin * len, tmax * len);
}

/// The sphere in `slot` as a candidate against the best hit so far (t, global id): its t when it
/// is hit closer, or as close with a lower global index (the tie rule), else -1.
fn sphere_candidate(origin: vec3<f32>, d: vec3<f32>, slot: u32, t_min: f32, best_t: f32, best_id: u32) -> f32 {
    let s = spheres[slot];
    let t = sphere_ray_t(origin, d, s.center, s.radius, t_min, best_t);
    if t >= 0.0 && (t < best_t || (t == best_t && sphere_ids[slot] < best_id)) {
        return t;
    }
    return -1.0;
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
