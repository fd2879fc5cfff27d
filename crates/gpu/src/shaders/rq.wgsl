// rq.wgsl — the hardware path's group 3 (`accel.rs`, `RtScene`): the scene's top-level
// acceleration structure (an instance per mesh over its own bottom-level structure, and one
// instance over the spheres as AABB geometry; instance masks RT_MASK_* select which a query
// sees) and per mesh its shadow transparency (listing 8b's class, as bvh.rs's `e1.w`). Needs
// common/*.wgsl before it; the module starts with `enable wgpu_ray_query;` (shaders::module_rq).

@group(3) @binding(0) var rt_scene: acceleration_structure;
@group(3) @binding(1) var<storage, read> rt_mesh_shadow: array<f32>;

/// Whether a ray may be handed to a ray query (Vulkan requires finite origin and direction and
/// 0 <= tmin <= tmax); the software traversals find nothing along the rays that fail this.
fn rq_ray_ok(o: vec3<f32>, d: vec3<f32>, tmin: f32, tmax: f32) -> bool {
    let finite = is_finite(o.x) && is_finite(o.y) && is_finite(o.z) && is_finite(d.x) && is_finite(d.y) && is_finite(d.z);
    return finite && dot(d, d) > 0.0 && tmin >= 0.0 && tmax >= tmin && is_finite(tmax);
}
