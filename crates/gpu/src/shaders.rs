//! `shaders`: every pass's WGSL is the generated header of shared constants ([`constants`]), then
//! `common/*.wgsl` (group 0, surfaces, lights, sky), then the pass's own file, which sits beside it
//! in `src/shaders/`.

/// Shared declarations and functions (the WGSL twins of hybrid-core's shading), in named parts
/// under `shaders/common/`, in this order: the scene's group 0 bindings and structs, small
/// helpers (finite checks, sRGB, luminance), texture sampling, surface evaluation, camera rays,
/// shading (lights, Blinn–Phong, reflect/refract), the skybox, the G-buffer outputs.
pub const COMMON: &str = concat!(
    include_str!("shaders/common/scene.wgsl"),
    include_str!("shaders/common/helpers.wgsl"),
    include_str!("shaders/common/sampling.wgsl"),
    include_str!("shaders/common/surface.wgsl"),
    include_str!("shaders/common/camera.wgsl"),
    include_str!("shaders/common/shading.wgsl"),
    include_str!("shaders/common/sky.wgsl"),
    include_str!("shaders/common/gbuffer.wgsl"),
);

/// `constants()`, then `COMMON`, then a pass's own source.
pub fn with_common(pass_source: &str) -> String {
    format!("{}\n{COMMON}\n{pass_source}", constants())
}

/// The WGSL header of every constant that Rust and WGSL share, generated from the Rust
/// definitions so the two cannot drift: object ids, the shadow class that is evaluated at the
/// hit, the blend's mask threshold, mesh flags, light and sky kinds, stack sizes, the count
/// pass's span, the fallbacks' map kinds and shadow-map biases.
pub fn constants() -> String {
    use crate::scene::*;
    let u32s = [
        ("NO_OBJECT", hybrid_core::NO_OBJECT),
        ("RT_SCENE_OBJECT", hybrid_core::RT_SCENE_OBJECT),
        ("MESH_HAS_NORMALS", MESH_HAS_NORMALS),
        ("MESH_HAS_UVS", MESH_HAS_UVS),
        ("MESH_HAS_TANGENTS", MESH_HAS_TANGENTS),
        ("MESH_HAS_COLORS", MESH_HAS_COLORS),
        ("LIGHT_DIRECTIONAL", LIGHT_DIRECTIONAL),
        ("LIGHT_POINT", LIGHT_POINT),
        ("LIGHT_SPOT", LIGHT_SPOT),
        ("BVH_STACK", crate::bvh::STACK_SIZE as u32),
        ("SPHERE_STACK", crate::spheres::STACK),
        ("TRACE_STACK", crate::trace::TRACE_STACK),
        ("TRACE_RAY_BUDGET", hybrid_scene::TRACE_RAY_BUDGET),
        ("SPAN", crate::heuristic::COUNT_SPAN),
        ("RT_MASK_SHADOW_CASTERS", crate::accel::RT_MASK_SHADOW_CASTERS),
        ("RT_MASK_SPHERES", crate::accel::RT_MASK_SPHERES),
        ("RT_MASK_TRIANGLES", crate::accel::RT_MASK_TRIANGLES),
        ("SHADOW_NONE", crate::fallback::SHADOW_NONE),
        ("SHADOW_DIRECTIONAL", crate::fallback::SHADOW_DIRECTIONAL),
        ("SHADOW_SPOT", crate::fallback::SHADOW_SPOT),
        ("SHADOW_POINT", crate::fallback::SHADOW_POINT),
        ("SHADOW_ARRAY_MAPS", crate::fallback::SHADOW_ARRAY_MAPS),
        ("SHADOW_ARRAY_CUBE", crate::fallback::SHADOW_ARRAY_CUBE),
        ("PROBE_MARCH_STEPS", hybrid_core::fallback::PROBE_MARCH_STEPS),
        ("PROBE_REFINE_STEPS", hybrid_core::fallback::PROBE_REFINE_STEPS),
        ("SEE_THROUGH_STEPS", hybrid_core::fallback::SEE_THROUGH_STEPS),
        ("REFRACTOR_BOUNCES", hybrid_core::fallback::REFRACTOR_BOUNCES),
        ("REFRACTOR_NONE", crate::fallback::REFRACTOR_NONE),
        ("REFRACTOR_SPHERE", crate::fallback::REFRACTOR_SPHERE),
        ("REFRACTOR_HULL", crate::fallback::REFRACTOR_HULL),
    ];
    // The sky kind is an i32 in WGSL (compared with a signed uniform field).
    let i32s = [("SKY_COLOR", SKY_COLOR), ("SKY_GRADIENT", SKY_GRADIENT), ("SKY_CUBE", SKY_CUBE)];
    use hybrid_core::fallback as fb;
    let f32s = [
        ("SHADOW_EVALUATE", hybrid_core::prepare::SHADOW_EVALUATE),
        ("MASK_EPSILON", hybrid_core::blend::MASK_EPSILON),
        ("SHADOW_BIAS_TEXELS", fb::SHADOW_BIAS_TEXELS),
        ("SHADOW_SLOPE_BIAS_TEXELS", fb::SHADOW_SLOPE_BIAS_TEXELS),
        ("SHADOW_NORMAL_OFFSET_TEXELS", fb::SHADOW_NORMAL_OFFSET_TEXELS),
        ("SHADOW_MAX_SLOPE", fb::SHADOW_MAX_SLOPE),
    ];
    let mut out = String::from("// Generated from the Rust definitions (hybrid_gpu::shaders::constants).\n");
    for (name, v) in u32s {
        out += &format!("const {name}: u32 = {v}u;\n");
    }
    for (name, v) in i32s {
        out += &format!("const {name}: i32 = {};\n", v as i32);
    }
    for (name, v) in f32s {
        // `{:?}` prints the shortest decimal that reads back to the same f32 (always with a dot or
        // an exponent, so WGSL reads it as a float).
        out += &format!("const {name}: f32 = {v:?};\n");
    }
    // The cube faces' axes (hybrid_core::fallback::CUBE_FACES: +X, −X, +Y, −Y, +Z, −Z).
    let vec3s = |pick: fn(&(glam::Vec3, glam::Vec3)) -> glam::Vec3| {
        let v: Vec<String> = fb::CUBE_FACES.iter().map(pick).map(|v| format!("vec3<f32>({:?}, {:?}, {:?})", v.x, v.y, v.z)).collect();
        v.join(", ")
    };
    out += &format!("const CUBE_FACE_FORWARD: array<vec3<f32>, 6> = array<vec3<f32>, 6>({});\n", vec3s(|f| f.0));
    out += &format!("const CUBE_FACE_UP: array<vec3<f32>, 6> = array<vec3<f32>, 6>({});\n", vec3s(|f| f.1));
    out
}

/// Compiles a hardware-path variant of a pass's shader: `enable wgpu_ray_query;` (WGSL wants it
/// before everything), then as [`module`]. Only built on devices with ray queries.
pub fn module_rq(device: &wgpu::Device, label: &str, pass_source: &str) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(with_common_rq(pass_source).into()),
    })
}

/// `enable wgpu_ray_query;`, then [`with_common`].
pub fn with_common_rq(pass_source: &str) -> String {
    format!("enable wgpu_ray_query;\n{}", with_common(pass_source))
}

/// Compiles a pass's shader (common/*.wgsl prepended).
pub fn module(device: &wgpu::Device, label: &str, pass_source: &str) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(with_common(pass_source).into()),
    })
}

/// Parses and validates WGSL with naga, as wgpu would, without a device (for unit tests).
#[cfg(test)]
pub fn validate(source: &str) -> Result<(), String> {
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .map_err(|e| e.emit_to_string(source))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn common_wgsl_is_valid() {
        // Call the main functions so they are type-checked in use.
        let probe = r#"
@compute @workgroup_size(1)
fn probe() {
    let s = triangle_surface_at(0u, vec3<f32>(1.0, 0.0, 0.0), 0.0);
    let r = primary_ray(0.5, 0.5);
    let c = local_lighting(s, view_dir(s.position)) + sky(r.dir) + refract_or_reflect(r.dir, s.normal, 1.0, 1.5).xyz;
    _ = c + vec3<f32>(linear_to_srgb(luminance(c)));
}
"#;
        if let Err(e) = validate(&with_common(probe)) {
            panic!("{e}");
        }
    }

    /// Every shared constant is defined once, in Rust: no shader file declares one by hand, and the
    /// header holds each value exactly.
    #[test]
    fn shared_constants_come_only_from_the_header() {
        let header = constants();
        let files = [
            ("common/*.wgsl", COMMON),
            ("blend.wgsl", crate::blend::BLEND_WGSL),
            ("bvh.wgsl", crate::bvh::BVH_WGSL),
            ("count.wgsl", crate::heuristic::COUNT_WGSL),
            ("mask.wgsl", crate::heuristic::MASK_WGSL),
            ("spheres.wgsl", crate::spheres::SPHERES_WGSL),
            ("trace.wgsl", crate::trace::TRACE_WGSL),
            ("rq.wgsl + bvh_rq.wgsl", crate::accel::RQ_WGSL),
            ("spheres_rq.wgsl", crate::spheres::SPHERES_RQ_WGSL),
            ("shadow_depth.wgsl", crate::fallback::SHADOW_DEPTH_WGSL),
            ("fallback.wgsl", crate::fallback::FALLBACK_WGSL),
            ("shadow_view.wgsl", crate::fallback::SHADOW_VIEW_WGSL),
            ("probe_distance.wgsl", crate::fallback::PROBE_DISTANCE_WGSL),
        ];
        let names: Vec<&str> = header.lines().filter_map(|l| l.strip_prefix("const ")).map(|l| l.split(':').next().unwrap()).collect();
        assert!(names.len() >= 18, "{header}");
        for name in &names {
            for (file, source) in files {
                assert!(!source.contains(&format!("const {name}:")), "{file} declares {name} by hand");
            }
        }
        assert!(header.contains(&format!("const NO_OBJECT: u32 = {}u;", u32::MAX)));
        assert!(header.contains("const SHADOW_EVALUATE: f32 = -1.0;"));
        assert!(header.contains("const MASK_EPSILON: f32 = 0.0001;"));
        assert!(header.contains(&format!("const TRACE_STACK: u32 = {}u;", crate::trace::TRACE_STACK)));
    }
}
