// fallback.wgsl — stage 3b's lookups (issue 18): the WGSL twin of
// hybrid_core::fallback::FallbackScene::pixel for every covered polygon pixel the trace stage
// left out (mask < MASK_EPSILON), from the shadow maps, the objects' probes and (planar and
// convex refractive objects) the see-through layer, whose texel is shaded as the trace shades a
// secondary hit (FallbackScene::through_layer); a refracted ray is followed out of a sphere or
// convex refractor first (Refractor::leave); shadow 1, reflection and refraction 0 elsewhere.
// common/*.wgsl, shadow_view.wgsl and blend_equations.wgsl are prepended.

// Per light (GPU light order = hybrid_core::shading::lights order): its views.
struct ShadowLightGpu {
    kind: u32, // SHADOW_NONE, SHADOW_DIRECTIONAL, SHADOW_SPOT, SHADOW_POINT
    first_view: u32,
    view_count: u32,
    _pad: u32,
}

// Per object: its probe (hybrid_core::fallback::Probe), if rendered.
struct ProbeGpu {
    centre: vec4<f32>,  // w = the far plane (the distance where nothing was seen)
    box_min: vec4<f32>, // w = 1: box-projected against [box_min, box_max]
    box_max: vec4<f32>,
    // Rendered, first layer (+ face), see-through object (0/1), refractor
    // (hybrid_core::fallback::Refractor: REFRACTOR_NONE, _SPHERE, _HULL).
    info: vec4<u32>,
    sphere: vec4<f32>, // a sphere refractor's centre and radius
    planes: vec4<u32>, // a hull refractor's first plane in refractor_planes and plane count
}

struct FallbackParams {
    pcf_radius: u32,
    probe_size: u32,
    // The see-through layer (hybrid_core::fallback::SeeThrough): its size and view, and whether
    // this frame rendered it.
    see_width: u32,
    see_height: u32,
    see_view_proj: mat4x4<f32>,
    see_through: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(1) @binding(0) var g_position: texture_2d<f32>;
@group(1) @binding(1) var g_normal: texture_2d<f32>;
@group(1) @binding(2) var g_diffuse: texture_2d<f32>;
@group(1) @binding(3) var g_specular: texture_2d<f32>;
@group(1) @binding(4) var g_optical: texture_2d<f32>;
@group(1) @binding(5) var g_object_id: texture_2d<u32>;
@group(1) @binding(6) var g_mask: texture_2d<f32>;
@group(1) @binding(7) var out_shadow: texture_storage_2d<rgba16float, write>;
@group(1) @binding(8) var out_reflection: texture_storage_2d<rgba16float, write>;
@group(1) @binding(9) var out_refraction: texture_storage_2d<rgba16float, write>;
@group(1) @binding(10) var shadow_maps: texture_depth_2d_array;
@group(1) @binding(11) var shadow_cube: texture_depth_2d_array;
@group(1) @binding(12) var<storage, read> shadow_views: array<ShadowViewGpu>;
@group(1) @binding(13) var<storage, read> shadow_lights: array<ShadowLightGpu>;
@group(1) @binding(14) var probe_faces: texture_2d_array<f32>;
@group(1) @binding(15) var<storage, read> probes: array<ProbeGpu>;
@group(1) @binding(16) var<uniform> params: FallbackParams;
// Per probe texel (layer after layer, row-major): the distance from the centre to the surface seen.
@group(1) @binding(17) var<storage, read> probe_distances: array<f32>;
// The see-through layer: the frame's view widened, rasterized without the planar refractive
// objects, lit; its surfaces (as g_*) for their own fallback terms.
@group(1) @binding(18) var st_position: texture_2d<f32>;
@group(1) @binding(19) var st_normal: texture_2d<f32>;
@group(1) @binding(20) var st_object_id: texture_2d<u32>;
@group(1) @binding(21) var st_color: texture_2d<f32>;
@group(1) @binding(22) var st_diffuse: texture_2d<f32>;
@group(1) @binding(23) var st_specular: texture_2d<f32>;
@group(1) @binding(24) var st_optical: texture_2d<f32>;
// The convex refractors' face planes: outward unit normal, w the offset (inside: n·x ≤ w).
@group(1) @binding(25) var<storage, read> refractor_planes: array<vec4<f32>>;

// ShadowMap::lit: 1 where texel (x, y), clamped to the map, is no nearer than z_ref.
fn lit(v: ShadowViewGpu, x: i32, y: i32, z_ref: f32) -> f32 {
    let n = i32(v.size);
    let xy = vec2<i32>(clamp(x, 0, n - 1), clamp(y, 0, n - 1));
    var d: f32;
    if v.array_index == SHADOW_ARRAY_CUBE {
        d = textureLoad(shadow_cube, xy, i32(v.layer), 0);
    } else {
        d = textureLoad(shadow_maps, xy, i32(v.layer), 0);
    }
    return select(0.0, 1.0, d <= z_ref);
}

// ShadowMap::compare_bilinear.
fn compare_bilinear(v: ShadowViewGpu, uv: vec2<f32>, z_ref: f32) -> f32 {
    let t = uv * f32(v.size) - vec2<f32>(0.5);
    let t0 = floor(t);
    let fx = t.x - t0.x;
    let fy = t.y - t0.y;
    let x0 = i32(t0.x);
    let y0 = i32(t0.y);
    let a = lit(v, x0, y0, z_ref) * (1.0 - fx) + lit(v, x0 + 1, y0, z_ref) * fx;
    let b = lit(v, x0, y0 + 1, z_ref) * (1.0 - fx) + lit(v, x0 + 1, y0 + 1, z_ref) * fx;
    return a * (1.0 - fy) + b * fy;
}

// ShadowMap::visibility: normal offset, slope-scaled bias, PCF; points outside the map are lit.
fn visibility(v: ShadowViewGpu, p: vec3<f32>, n: vec3<f32>, to_light: vec3<f32>) -> f32 {
    let m = v.view_proj;
    // One projection: the receiver's clip position, then its normal offset added through the
    // matrix's linear part (the offset is a direction).
    let c0 = m * vec4<f32>(p, 1.0);
    // The texel's world size at the receiver (perspective: clip w is the view distance).
    var texel = v.texel_world;
    if v.orthographic == 0u {
        texel = v.texel_world * max(c0.w, v.near);
    }
    let cos_l = clamp(dot(n, to_light), 1e-3, 1.0);
    let tan_l = min(sqrt(max(1.0 - cos_l * cos_l, 0.0)) / cos_l, SHADOW_MAX_SLOPE);
    let o = n * (texel * SHADOW_NORMAL_OFFSET_TEXELS);
    let c = c0 + m[0] * o.x + m[1] * o.y + m[2] * o.z;
    if c.w <= 0.0 {
        return 1.0;
    }
    let inv_w = 1.0 / c.w;
    let uv = vec2<f32>(c.x * inv_w * 0.5 + 0.5, 0.5 - c.y * inv_w * 0.5);
    let z = c.z * inv_w;
    if !(uv.x >= 0.0 && uv.x <= 1.0 && uv.y >= 0.0 && uv.y <= 1.0) || z > 1.0 {
        return 1.0;
    }
    let bias = texel * (SHADOW_BIAS_TEXELS + SHADOW_SLOPE_BIAS_TEXELS * tan_l);
    // depth_of(linear_depth(z) − bias) without the round trip: orthographic depth is affine in
    // distance, a perspective view's distance is clip w.
    var z_ref: f32;
    if v.orthographic != 0u {
        z_ref = z + bias / (v.far - v.near);
    } else {
        z_ref = depth_of(v, c.w - bias);
    }
    let r = i32(params.pcf_radius);
    if r == 0 {
        return compare_bilinear(v, uv, z_ref);
    }
    let step = 1.0 / f32(v.size);
    var sum = 0.0;
    for (var j = -r; j <= r; j++) {
        for (var i = -r; i <= r; i++) {
            sum += compare_bilinear(v, uv + vec2<f32>(f32(i), f32(j)) * step, z_ref);
        }
    }
    return sum / f32((2 * r + 1) * (2 * r + 1));
}

// hybrid_core::fallback::cube_face: the major axis of d.
fn cube_face_of(d: vec3<f32>) -> u32 {
    let a = abs(d);
    if a.x >= a.y && a.x >= a.z {
        return select(1u, 0u, d.x > 0.0);
    } else if a.y >= a.z {
        return select(3u, 2u, d.y > 0.0);
    }
    return select(5u, 4u, d.z > 0.0);
}

// LightShadowMaps::map_for: the view a point uses (index into shadow_views).
fn view_for(sl: ShadowLightGpu, p: vec3<f32>, view_distance: f32, light_position: vec3<f32>) -> u32 {
    if sl.kind == SHADOW_DIRECTIONAL {
        for (var k = 0u; k < sl.view_count; k++) {
            if view_distance <= shadow_views[sl.first_view + k].split_far {
                return sl.first_view + k;
            }
        }
        return sl.first_view + sl.view_count - 1u;
    }
    if sl.kind == SHADOW_POINT {
        return sl.first_view + min(cube_face_of(p - light_position), sl.view_count - 1u);
    }
    return sl.first_view;
}

// FrameLights::blinn_phong_incident: Blinn–Phong of light arriving along `l` with `radiance`.
fn blinn_phong_incident(l: vec3<f32>, radiance: vec3<f32>, s: Surface, view: vec3<f32>) -> vec3<f32> {
    if all(radiance == vec3<f32>(0.0)) {
        return vec3<f32>(0.0);
    }
    let n = facing(s.normal, view);
    let n_dot_l = dot(n, l);
    if n_dot_l <= 0.0 {
        return vec3<f32>(0.0);
    }
    var spec = vec3<f32>(0.0);
    if any(s.specular != vec3<f32>(0.0)) {
        let h = normalize_or(l + view, vec3<f32>(0.0));
        spec = s.specular * pow(max(dot(n, h), 0.0), specular_exponent(s.shininess));
    }
    return (s.diffuse * n_dot_l + spec) * radiance;
}

// Probe::face_uv: the face and UV a direction from the centre falls on (the face camera's
// projection in closed form); valid = false behind the face.
struct FaceUv {
    face: u32,
    uv: vec2<f32>,
    valid: bool,
}

fn face_uv(d: vec3<f32>) -> FaceUv {
    let face = cube_face_of(d);
    let forward = CUBE_FACE_FORWARD[face];
    let up = CUBE_FACE_UP[face];
    let right = cross(forward, up);
    let z = dot(d, forward);
    if z <= 0.0 {
        return FaceUv(face, vec2<f32>(0.0), false);
    }
    return FaceUv(face, vec2<f32>(0.5 + 0.5 * dot(d, right) / z, 0.5 - 0.5 * dot(d, up) / z), true);
}

// Probe::distance_along: the distance the probe saw along d (nearest texel; far for nothing).
fn distance_along(pr: ProbeGpu, d: vec3<f32>) -> f32 {
    let far = pr.centre.w;
    let f = face_uv(d);
    if !f.valid {
        return far;
    }
    let n = i32(params.probe_size);
    let x = clamp(i32(f.uv.x * f32(n)), 0, n - 1);
    let y = clamp(i32(f.uv.y * f32(n)), 0, n - 1);
    return probe_distances[(pr.info.y + f.face) * u32(n * n) + u32(y * n + x)];
}

// Behind the surface the probe saw along p + t·dir (where it saw one: not the sky).
fn behind(pr: ProbeGpu, p: vec3<f32>, dir: vec3<f32>, t: f32) -> bool {
    let y = p + dir * t - pr.centre.xyz;
    let len = length(y);
    let seen = distance_along(pr, y);
    return len > 0.0 && seen < pr.centre.w * 0.999 && len > seen;
}

// Probe::lookup_direction: from the probe's centre to where the ray meets the scene: where it
// leaves the parallax box, or where it first goes behind the surface the probe saw (marched in
// PROBE_MARCH_STEPS quadratic steps to the far plane, refined in PROBE_REFINE_STEPS bisections);
// dir itself when it never does.
fn lookup_direction(pr: ProbeGpu, p: vec3<f32>, dir: vec3<f32>) -> vec3<f32> {
    if pr.box_min.w > 0.5 {
        let inv = vec3<f32>(1.0) / dir;
        let t1 = (pr.box_min.xyz - p) * inv;
        let t2 = (pr.box_max.xyz - p) * inv;
        let tm = max(t1, t2);
        let t_exit = min(tm.x, min(tm.y, tm.z));
        if is_finite(t_exit) && t_exit > 0.0 {
            return p + dir * t_exit - pr.centre.xyz;
        }
        return dir;
    }
    let far = pr.centre.w;
    var front = 0.0;
    for (var k = 1u; k <= PROBE_MARCH_STEPS; k++) {
        let s = f32(k) / f32(PROBE_MARCH_STEPS);
        let t = far * s * s;
        if behind(pr, p, dir, t) {
            var back = t;
            for (var i = 0u; i < PROBE_REFINE_STEPS; i++) {
                let mid = 0.5 * (front + back);
                if behind(pr, p, dir, mid) {
                    back = mid;
                } else {
                    front = mid;
                }
            }
            let y = p + dir * back - pr.centre.xyz;
            if dot(y, y) > 0.0 {
                return y;
            }
            return dir;
        }
        front = t;
    }
    return dir;
}

// Probe::sample: the probe's colour for a ray from p along unit dir (bilinear within the face,
// clamped to it).
fn probe_sample(pr: ProbeGpu, p: vec3<f32>, dir: vec3<f32>) -> vec3<f32> {
    let d = lookup_direction(pr, p, dir);
    if all(d == vec3<f32>(0.0)) {
        return vec3<f32>(0.0);
    }
    let f = face_uv(d);
    if !f.valid {
        return vec3<f32>(0.0);
    }
    let n = i32(params.probe_size);
    let t = f.uv * f32(n) - vec2<f32>(0.5);
    let t0 = floor(t);
    let fx = t.x - t0.x;
    let fy = t.y - t0.y;
    let x0 = i32(t0.x);
    let y0 = i32(t0.y);
    let layer = i32(pr.info.y + f.face);
    let c00 = textureLoad(probe_faces, vec2<i32>(clamp(x0, 0, n - 1), clamp(y0, 0, n - 1)), layer, 0).xyz;
    let c10 = textureLoad(probe_faces, vec2<i32>(clamp(x0 + 1, 0, n - 1), clamp(y0, 0, n - 1)), layer, 0).xyz;
    let c01 = textureLoad(probe_faces, vec2<i32>(clamp(x0, 0, n - 1), clamp(y0 + 1, 0, n - 1)), layer, 0).xyz;
    let c11 = textureLoad(probe_faces, vec2<i32>(clamp(x0 + 1, 0, n - 1), clamp(y0 + 1, 0, n - 1)), layer, 0).xyz;
    let a = mix(c00, c10, fx);
    let b = mix(c01, c11, fx);
    return mix(a, b, fy);
}

// The object's probe along dir, or the sky without one.
fn look(object: u32, p: vec3<f32>, dir: vec3<f32>) -> vec3<f32> {
    if object < arrayLength(&probes) && probes[object].info.x != 0u {
        return probe_sample(probes[object], p, dir);
    }
    return sky(dir);
}

// SeeThrough::pixel_of: the layer pixel a world point lands on; x = -1 off the layer.
fn see_pixel(x: vec3<f32>) -> vec2<i32> {
    let c = params.see_view_proj * vec4<f32>(x, 1.0);
    if c.w <= 0.0 {
        return vec2<i32>(-1);
    }
    let ndc = c.xyz / c.w;
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    if !(uv.x >= 0.0 && uv.x < 1.0 && uv.y >= 0.0 && uv.y < 1.0) {
        return vec2<i32>(-1);
    }
    let size = vec2<i32>(i32(params.see_width), i32(params.see_height));
    return min(vec2<i32>(uv * vec2<f32>(size)), size - vec2<i32>(1));
}

// SeeThrough::hit_along: what the refraction along unit t from p meets in the layer: xy its
// texel and z = 0 (LayerHit::Texel), z = 1 the sky behind p or where the ray lands
// (LayerHit::Sky), z = 2 not known
// from the layer (LayerHit::Unknown: off it, or the ray turns away from the surface it is aimed
// at; the probe answers). The distance starts as the surface's behind p and is refined
// SEE_THROUGH_STEPS times against the tangent plane of the surface where the point lands; a
// point that leaves the layer keeps the last pixel in it.
fn hit_along(p: vec3<f32>, t: vec3<f32>) -> vec3<i32> {
    let i = see_pixel(p);
    if i.x < 0 {
        return vec3<i32>(-1, -1, 2);
    }
    if textureLoad(st_object_id, i, 0).x == NO_OBJECT {
        return vec3<i32>(-1, -1, 1);
    }
    var d = distance(textureLoad(st_position, i, 0).xyz, p);
    var j = i;
    for (var step = 0u; step < SEE_THROUGH_STEPS; step++) {
        let k = see_pixel(p + t * d);
        if k.x < 0 {
            break;
        }
        j = k;
        if textureLoad(st_object_id, k, 0).x == NO_OBJECT {
            break;
        }
        let q = textureLoad(st_position, k, 0).xyz;
        let n = textureLoad(st_normal, k, 0).xyz;
        let denom = dot(t, n);
        if abs(denom) < 1e-4 {
            break;
        }
        let next = dot(q - p, n) / denom;
        if !(next > 0.0 && is_finite(next)) {
            return vec3<i32>(-1, -1, 2);
        }
        d = next;
    }
    let last = see_pixel(p + t * d);
    if last.x >= 0 {
        j = last;
    }
    if textureLoad(st_object_id, j, 0).x == NO_OBJECT {
        return vec3<i32>(-1, -1, 1);
    }
    return vec3<i32>(j, 0);
}

// FallbackScene::shadow: 1 minus each light's Blinn–Phong share times its maps' occlusion, for
// surface s seen along view (towards the eye).
fn shadow_term(s: Surface, view: vec3<f32>) -> vec3<f32> {
    var shadow = vec3<f32>(1.0);
    let unlit = all(s.diffuse == vec3<f32>(0.0)) && all(s.specular == vec3<f32>(0.0));
    if unlit {
        return shadow;
    }
    let view_distance = dot(s.position - frame.camera_position.xyz, frame.camera_forward.xyz);
    let n = facing(s.normal, view);
    let light_count = min(frame.counts.x, arrayLength(&shadow_lights));
    for (var i = 0u; i < light_count; i++) {
        let sl = shadow_lights[i];
        if sl.view_count == 0u {
            continue;
        }
        let inc = light_incident(lights[i], s.position);
        if all(inc.radiance == vec3<f32>(0.0)) || dot(n, inc.dir) <= 0.0 {
            continue;
        }
        let v = shadow_views[view_for(sl, s.position, view_distance, lights[i].position.xyz)];
        let vis = visibility(v, s.position, n, inc.dir);
        if vis < 1.0 {
            shadow -= blinn_phong_incident(inc.dir, inc.radiance, s, view) * (1.0 - vis);
        }
    }
    return shadow;
}

// Refractor::exit: where a ray inside object pr's refractor, from p along unit t, leaves it:
// the exit point and the outward normal there.
struct Exit {
    point: vec3<f32>,
    normal: vec3<f32>,
    found: bool,
}

fn refractor_exit(pr: ProbeGpu, p: vec3<f32>, t: vec3<f32>) -> Exit {
    if pr.info.w == REFRACTOR_SPHERE {
        // The far root of |p + t·s − c|² = r².
        let o = p - pr.sphere.xyz;
        let b = dot(o, t);
        let disc = b * b - (dot(o, o) - pr.sphere.w * pr.sphere.w);
        if disc < 0.0 {
            return Exit(p, vec3<f32>(0.0), false);
        }
        let q = p + t * max(-b + sqrt(disc), 0.0);
        return Exit(q, (q - pr.sphere.xyz) / pr.sphere.w, true);
    }
    if pr.info.w == REFRACTOR_HULL {
        var best = -1.0;
        var best_n = vec3<f32>(0.0);
        for (var k = 0u; k < pr.planes.y; k++) {
            let q = refractor_planes[pr.planes.x + k];
            let along = dot(q.xyz, t);
            if along > 1e-6 {
                let d = max((q.w - dot(q.xyz, p)) / along, 0.0);
                if best < 0.0 || d < best {
                    best = d;
                    best_n = q.xyz;
                }
            }
        }
        if best >= 0.0 {
            return Exit(p + t * best, best_n, true);
        }
    }
    return Exit(p, vec3<f32>(0.0), false);
}

// Refractor::leave: the ray refracted into the object at p along t, followed out (refracted
// where it meets the surface from inside, reflected on and followed on total internal
// reflection, up to REFRACTOR_BOUNCES times). Returns the exit point and direction (common's
// Ray).

fn refractor_leave(pr: ProbeGpu, p: vec3<f32>, t: vec3<f32>, env_ior: f32, ior: f32) -> Ray {
    var r = Ray(p, t);
    for (var b = 0u; b < REFRACTOR_BOUNCES; b++) {
        let e = refractor_exit(pr, r.origin, r.dir);
        if !e.found {
            break;
        }
        let out = refract_or_reflect(r.dir, e.normal, env_ior, ior);
        r = Ray(e.point, out.xyz);
        if out.w == 0.0 {
            break;
        }
    }
    return r;
}

// A surface's reflection and refraction terms, and where its refraction looks through the
// see-through layer, the layer texel it lands on and the ray it arrives along.
struct Terms {
    reflection: vec3<f32>,
    // Left 0 where `hit.z` is 0 or 1: the caller shades that texel or the sky (layer_texel; WGSL
    // has no recursion).
    refraction: vec3<f32>,
    // hit_along's answer (z = 2 where the layer was not looked up or did not know).
    hit: vec3<i32>,
    // The ray the layer was looked up along.
    along: vec3<f32>,
}

// FallbackScene::reflection_refraction of object id's surface s hit along unit `incident`: its
// probe (or the sky) along the reflected and refracted directions, the refracted ray followed
// out of a sphere or convex refractor first; with `through`, a see-through object's refraction
// through the layer (the frame's pixels; never the layer's own texels).
fn reflection_refraction(id: u32, s: Surface, incident: vec3<f32>, through: bool) -> Terms {
    var t = Terms(vec3<f32>(0.0), vec3<f32>(0.0), vec3<i32>(-1, -1, 2), incident);
    if s.reflectivity > 0.0 {
        t.reflection = look(id, s.position, normalize_or(reflect_dir(incident, s.normal), vec3<f32>(0.0)));
    }
    if s.opacity < 1.0 {
        let dir = refract_or_reflect(incident, s.normal, frame.env_ambient.w, s.ior).xyz;
        var r = Ray(s.position, dir);
        let known = id < arrayLength(&probes);
        if known && probes[id].info.w != REFRACTOR_NONE {
            r = refractor_leave(probes[id], s.position, dir, frame.env_ambient.w, s.ior);
        }
        t.along = r.dir;
        if through && params.see_through != 0u && known && probes[id].info.z != 0u {
            t.hit = hit_along(r.origin, r.dir);
        }
        if t.hit.z == 2 {
            t.refraction = look(id, r.origin, r.dir);
        }
    }
    return t;
}

// FallbackScene::through_layer for a hit: the texel shaded as the trace shades a secondary hit
// reached along `along` (unshadowed lighting combined with its own reflection and refraction,
// from its probe), the sky along the ray where the layer shows none.
fn layer_texel(hit: vec3<i32>, along: vec3<f32>) -> vec3<f32> {
    let j = hit.xy;
    if hit.z == 1 {
        return sky(along);
    }
    let lit = textureLoad(st_color, j, 0).xyz;
    let id = textureLoad(st_object_id, j, 0).x;
    let s = surface_at(st_position, st_normal, st_diffuse, st_specular, st_optical, j);
    if id == RT_SCENE_OBJECT || dot(s.normal, s.normal) <= 0.0 {
        return lit;
    }
    let t = reflection_refraction(id, s, along, false);
    return combine(lit, t.reflection, t.refraction, s.reflectivity, 1.0 - s.opacity);
}

@compute @workgroup_size(8, 8)
fn cs_fallback(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(out_shadow);
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    let px = vec2<i32>(gid.xy);
    var shadow = vec3<f32>(1.0);
    var t = Terms(vec3<f32>(0.0), vec3<f32>(0.0), vec3<i32>(-1, -1, 2), vec3<f32>(0.0));
    let id = textureLoad(g_object_id, px, 0).x;
    let normal = textureLoad(g_normal, px, 0).xyz;
    let untraced = textureLoad(g_mask, px, 0).x < MASK_EPSILON && id != NO_OBJECT && id != RT_SCENE_OBJECT;
    if untraced && dot(normal, normal) > 0.0 {
        let s = surface_at(g_position, g_normal, g_diffuse, g_specular, g_optical, px);
        let view = view_dir(s.position);
        shadow = shadow_term(s, view);
        t = reflection_refraction(id, s, -view, true);
        if t.hit.z != 2 {
            t.refraction = layer_texel(t.hit, t.along);
        }
    }
    textureStore(out_shadow, px, vec4<f32>(shadow, 1.0));
    textureStore(out_reflection, px, vec4<f32>(t.reflection, 1.0));
    textureStore(out_refraction, px, vec4<f32>(t.refraction, 1.0));
}
