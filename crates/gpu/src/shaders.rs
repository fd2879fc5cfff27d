//! `shaders`: every pass's WGSL is `common.wgsl` (group 0, surfaces, lights, sky) followed by the
//! pass's own file, which sits beside it in `src/shaders/`.

/// Shared declarations and functions (the WGSL twins of hybrid-core's shading).
pub const COMMON: &str = include_str!("shaders/common.wgsl");

/// `COMMON` followed by a pass's own source.
pub fn with_common(pass_source: &str) -> String {
    format!("{COMMON}\n{pass_source}")
}

/// Compiles a pass's shader (common.wgsl prepended).
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
}
