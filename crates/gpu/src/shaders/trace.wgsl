// trace.wgsl — stage 3 (paper 1 listings 8a–d), the twin of hybrid-cpu's `trace.rs`
// (`trace_with_spheres`: the RT-scene's spheres block shadow rays and are seen by secondary
// rays). Needs common/*.wgsl, bvh.wgsl (group 1) and spheres.wgsl (group 2) before it. Three entry points, one compute pass each: shadow,
// reflection, refraction, over every pixel (pixels with mask 0 get 1 / 0 / 0).
//
// WGSL has no recursion: listing 8c's tree of secondary rays is walked with a small stack of
// pending rays. The closest-hit combination (eq. 5/6 averaged, `hybrid_core::blend::combine`) is
// linear in its three inputs:
//   combine(c, m, r, om, or) = wc·c + wm·m + wr·r,
//   wc = (1 − om)(1 − or), wm = om(2 − or)/2, wr = or(2 − om)/2   (wc + wm + wr = 1),
// so each pending ray carries the product of the weights on its path and adds its hit's local
// lighting × wc (or × 1 at the depth limit, where both children are the lighting) straight to
// the pixel; a ray that misses adds the sky.

struct TraceParams {
    ray_bias: f32,
    importance_cutoff: f32,
    max_depth: u32,
    _pad: u32,
}

@group(1) @binding(2) var<uniform> params: TraceParams;
@group(1) @binding(3) var g_position: texture_2d<f32>;
@group(1) @binding(4) var g_normal: texture_2d<f32>;
@group(1) @binding(5) var g_diffuse: texture_2d<f32>;
@group(1) @binding(6) var g_specular: texture_2d<f32>;
@group(1) @binding(7) var g_optical: texture_2d<f32>;
@group(1) @binding(8) var g_object: texture_2d<u32>;
@group(1) @binding(9) var g_mask: texture_2d<f32>;
@group(1) @binding(10) var out_shadow: texture_storage_2d<rgba16float, write>;
@group(1) @binding(11) var out_reflection: texture_storage_2d<rgba16float, write>;
@group(1) @binding(12) var out_refraction: texture_storage_2d<rgba16float, write>;
// shadow, reflection, refraction rays traced.
@group(1) @binding(13) var<storage, read_write> ray_counts: array<atomic<u32>, 4>;

const KIND_REFLECTION: u32 = 0u;
const KIND_REFRACTION: u32 = 1u;

/// The G-buffer surface at pixel `p` (hybrid_core::GBuffer::surface).
fn gbuffer_surface(p: vec2<i32>) -> Surface {
    return surface_at(g_position, g_normal, g_diffuse, g_specular, g_optical, p);
}

/// Whether pixel `p` is traced and has a surface (else it sees the sky): 0 = not traced,
/// 1 = sky, 2 = surface.
fn pixel_state(p: vec2<i32>) -> u32 {
    if !(textureLoad(g_mask, p, 0).x > 0.0) {
        return 0u;
    }
    if textureLoad(g_object, p, 0).x == NO_OBJECT {
        return 1u;
    }
    let n = textureLoad(g_normal, p, 0).xyz;
    if !(dot(n, n) > 0.0) {
        return 1u;
    }
    return 2u;
}

/// Direction from the camera to `position` (the camera's forward for orthographic cameras).
fn incident_dir(position: vec3<f32>) -> vec3<f32> {
    let fwd = frame.camera_forward.xyz;
    if frame.camera_position.w == 1.0 {
        return fwd;
    }
    return normalize_or(position - frame.camera_position.xyz, fwd);
}

/// `position` moved by the ray bias along `normal`, to the side `dir` leaves towards.
fn offset_origin(position: vec3<f32>, normal: vec3<f32>, dir: vec3<f32>) -> vec3<f32> {
    let side = dot(normal, dir);
    if side > 0.0 {
        return position + normal * params.ray_bias;
    }
    if side < 0.0 {
        return position - normal * params.ray_bias;
    }
    return position;
}

struct PendingRay {
    origin: vec3<f32>,
    importance: f32,
    dir: vec3<f32>,
    weight: f32,
    depth: u32,
    kind: u32,
}

/// Listing 8c/8d from one ray leaving the G-buffer surface (depth 1): the colour it brings
/// back. `rays` counts (reflection, refraction) rays traced.
fn trace_secondary(origin: vec3<f32>, dir: vec3<f32>, importance: f32, kind: u32, rays: ptr<function, vec2<u32>>) -> vec3<f32> {
    var stack: array<PendingRay, TRACE_STACK>;
    stack[0] = PendingRay(origin, importance, dir, 1.0, 1u, kind);
    var sp = 1u;
    // Rays of this tree admitted so far (the root included), against TRACE_RAY_BUDGET: children
    // are admitted reflection first, and popped refraction first, as the CPU visits them.
    var admitted = 1u;
    var color = vec3<f32>(0.0);
    let max_depth = params.max_depth;
    let env_ior = frame.env_ambient.w;
    while sp > 0u {
        sp -= 1u;
        let r = stack[sp];
        if r.kind == KIND_REFLECTION {
            (*rays).x += 1u;
        } else {
            (*rays).y += 1u;
        }
        // The nearer of the closest triangle and the closest sphere (a sphere wins a tie).
        let hit = closest_hit(r.origin, r.dir, 0.0, FAR_AWAY);
        var sphere_tmax = FAR_AWAY;
        if hit.tri != NO_HIT {
            sphere_tmax = hit.t;
        }
        let sphere = sphere_closest_hit(r.origin, r.dir, 0.0, sphere_tmax);
        var s: Surface;
        if sphere.hit {
            s = sphere_surface(sphere.index, r.origin + r.dir * sphere.t, r.dir);
        } else if hit.tri != NO_HIT {
            s = triangle_surface_at(hit.tri, hit.bary, 0.0);
        } else {
            color += r.weight * sky(r.dir);
            continue;
        }
        let om = s.reflectivity;
        let or = 1.0 - s.opacity;
        var lighting = vec3<f32>(0.0);
        if om < 1.0 && or < 1.0 {
            lighting = local_lighting(s, -r.dir);
        }
        let wc = (1.0 - om) * (1.0 - or);
        let wm = 0.5 * om * (2.0 - or);
        let wr = 0.5 * or * (2.0 - om);
        if r.depth >= max_depth {
            // Both children replaced by the lighting: combine(l, l, l) = l.
            color += r.weight * (wc + wm + wr) * lighting;
            continue;
        }
        color += r.weight * wc * lighting;
        let refl_imp = r.importance * om;
        if refl_imp > params.importance_cutoff && sp < TRACE_STACK && admitted < TRACE_RAY_BUDGET {
            admitted += 1u;
            let d = normalize_or(reflect_dir(r.dir, s.normal), vec3<f32>(0.0));
            stack[sp] = PendingRay(offset_origin(s.position, s.normal, d), refl_imp, d, r.weight * wm, r.depth + 1u, KIND_REFLECTION);
            sp += 1u;
        }
        let refr_imp = r.importance * or;
        if refr_imp > params.importance_cutoff && sp < TRACE_STACK && admitted < TRACE_RAY_BUDGET {
            admitted += 1u;
            let d = refract_or_reflect(r.dir, s.normal, env_ior, s.ior).xyz;
            stack[sp] = PendingRay(offset_origin(s.position, s.normal, d), refr_imp, d, r.weight * wr, r.depth + 1u, KIND_REFRACTION);
            sp += 1u;
        }
    }
    return color;
}

fn in_image(id: vec3<u32>) -> bool {
    let size = textureDimensions(g_mask);
    return id.x < size.x && id.y < size.y;
}

/// Listing 8a, shadows (the CPU's `Tracer::shadow_rays`): 1 minus the Blinn–Phong light of each shadow-casting light that
/// occluders block (× 1 − attenuation).
@compute @workgroup_size(8, 8)
fn shadow_rays(@builtin(global_invocation_id) id: vec3<u32>) {
    if !in_image(id) {
        return;
    }
    let p = vec2<i32>(id.xy);
    var shadow = vec3<f32>(1.0);
    var rays = 0u;
    if pixel_state(p) == 2u {
        let s = gbuffer_surface(p);
        let view = -incident_dir(s.position);
        let unlit = all(s.diffuse == vec3<f32>(0.0)) && all(s.specular == vec3<f32>(0.0));
        if !unlit {
            for (var i = 0u; i < frame.counts.x; i++) {
                let light = lights[i];
                if light.kind.y == 0u {
                    continue;
                }
                // Lights that contribute nothing here need no ray.
                let inc = light_incident(light, s.position);
                if all(inc.radiance == vec3<f32>(0.0)) || dot(facing(s.normal, view), inc.dir) <= 0.0 {
                    continue;
                }
                rays += 1u;
                let origin = offset_origin(s.position, s.normal, inc.dir);
                var att = shadow_attenuation(origin, inc.dir, inc.distance);
                // Spheres are opaque casters.
                if att > 0.0 && sphere_any_hit(origin, inc.dir, 0.0, inc.distance) {
                    att = 0.0;
                }
                if att < 1.0 {
                    shadow -= blinn_phong(i, s, view) * (1.0 - att);
                }
            }
        }
    }
    if rays > 0u {
        atomicAdd(&ray_counts[0], rays);
    }
    textureStore(out_shadow, p, vec4<f32>(shadow, 1.0));
}

/// Listing 8a, reflections (the CPU's `Tracer::reflection_ray`): the reflected view ray traced (if reflectivity > 0); a traced
/// pixel without a surface shows the sky behind it.
@compute @workgroup_size(8, 8)
fn reflection_ray(@builtin(global_invocation_id) id: vec3<u32>) {
    if !in_image(id) {
        return;
    }
    let p = vec2<i32>(id.xy);
    var color = vec3<f32>(0.0);
    var rays = vec2<u32>(0u);
    let state = pixel_state(p);
    if state == 1u {
        color = sky(primary_ray(f32(id.x) + 0.5, f32(id.y) + 0.5).dir);
    } else if state == 2u {
        let s = gbuffer_surface(p);
        if s.reflectivity > 0.0 {
            let d = normalize_or(reflect_dir(incident_dir(s.position), s.normal), vec3<f32>(0.0));
            color = trace_secondary(offset_origin(s.position, s.normal, d), d, s.reflectivity, KIND_REFLECTION, &rays);
        }
    }
    if rays.x > 0u {
        atomicAdd(&ray_counts[1], rays.x);
    }
    if rays.y > 0u {
        atomicAdd(&ray_counts[2], rays.y);
    }
    textureStore(out_reflection, p, vec4<f32>(color, 1.0));
}

/// Listing 8a, refractions (the CPU's `Tracer::refraction_ray`): the view ray refracted (reflected on total internal reflection)
/// and traced (if opacity < 1).
@compute @workgroup_size(8, 8)
fn refraction_ray(@builtin(global_invocation_id) id: vec3<u32>) {
    if !in_image(id) {
        return;
    }
    let p = vec2<i32>(id.xy);
    var color = vec3<f32>(0.0);
    var rays = vec2<u32>(0u);
    if pixel_state(p) == 2u {
        let s = gbuffer_surface(p);
        if s.opacity < 1.0 {
            let d = refract_or_reflect(incident_dir(s.position), s.normal, frame.env_ambient.w, s.ior).xyz;
            color = trace_secondary(offset_origin(s.position, s.normal, d), d, 1.0 - s.opacity, KIND_REFRACTION, &rays);
        }
    }
    if rays.x > 0u {
        atomicAdd(&ray_counts[1], rays.x);
    }
    if rays.y > 0u {
        atomicAdd(&ray_counts[2], rays.y);
    }
    textureStore(out_refraction, p, vec4<f32>(color, 1.0));
}
