//! Test-only: every `Pod` struct the GPU backend uploads has the size and field offsets of the
//! WGSL struct that reads it, as naga's layouter computes them from the shaders themselves. A
//! field added, reordered or resized on one side only fails here instead of as wrong pixels.

use std::mem::{offset_of, size_of};

use crate::bvh::{BVH_WGSL, GpuBvhNode, GpuBvhTri};
use crate::scene::{FrameUniforms, GpuLight, GpuMaterial, GpuMesh, GpuTriangle, GpuVertex};
use crate::shaders::with_common;
use crate::spheres::{GpuSphere, GpuSphereInfo, GpuSphereNode, SPHERES_WGSL};
use crate::trace::{TRACE_WGSL, TraceParams};

/// A Rust struct's size and named field offsets, to hold against the WGSL struct `wgsl`.
struct Layout {
    wgsl: &'static str,
    size: usize,
    fields: Vec<(&'static str, usize)>,
}

macro_rules! layout {
    ($rust:ty, $wgsl:literal, [$($field:ident),* $(,)?]) => {
        Layout { wgsl: $wgsl, size: size_of::<$rust>(), fields: vec![$((stringify!($field), offset_of!($rust, $field))),*] }
    };
}

#[test]
fn uploaded_structs_match_their_wgsl_layouts() {
    let source = with_common(&format!("{BVH_WGSL}\n{SPHERES_WGSL}\n{TRACE_WGSL}"));
    let module = naga::front::wgsl::parse_str(&source).expect("the trace pass's WGSL parses");
    let layouts = [
        layout!(
            FrameUniforms,
            "FrameUniforms",
            [
                view_proj,
                inv_view_proj,
                camera_position,
                camera_forward,
                camera_right,
                camera_up,
                size,
                near_far,
                env_ambient,
                sky_zenith,
                sky_horizon,
                sky_ground,
                sky_faces0,
                sky_faces1,
                counts,
                raygen_rot,
                raygen_eye,
                raygen_proj
            ]
        ),
        layout!(GpuVertex, "Vertex", [position, normal, uv, tangent, color]),
        layout!(GpuTriangle, "Triangle", [v, mesh]),
        layout!(GpuMesh, "MeshInfo", [object, material, flags, first_triangle]),
        layout!(GpuMaterial, "Material", [emission, ambient, diffuse, specular, optical, uv_transform, maps0, maps1]),
        layout!(GpuLight, "Light", [kind, position, direction, power, attenuation, cone]),
        layout!(GpuBvhNode, "BvhNode", [min, max]),
        layout!(GpuBvhTri, "BvhTri", [v0, e1, e2]),
        layout!(GpuSphereInfo, "SphereInfo", [count, nodes, clouds, _pad]),
        layout!(GpuSphereNode, "SphereNode", [min, first, max, count]),
        layout!(GpuSphere, "Sphere", [center, radius, albedo, cloud]),
        layout!(TraceParams, "TraceParams", [ray_bias, importance_cutoff, max_depth, _pad]),
    ];
    check(&module, layouts);
}

#[test]
fn fallback_structs_match_their_wgsl_layouts() {
    use crate::fallback::{FALLBACK_WGSL, GpuFallbackParams, GpuProbe, GpuShadowLight, GpuShadowView, SHADOW_DEPTH_WGSL, SHADOW_VIEW_WGSL};
    let source = with_common(&format!("{SHADOW_VIEW_WGSL}\n{FALLBACK_WGSL}"));
    let module = naga::front::wgsl::parse_str(&source).expect("the fallback pass's WGSL parses");
    check(
        &module,
        [
            layout!(GpuShadowView, "ShadowViewGpu", [view_proj, near, far, texel_world, split_far, size, orthographic, array_index, layer]),
            layout!(GpuShadowLight, "ShadowLightGpu", [kind, first_view, view_count, _pad]),
            layout!(GpuProbe, "ProbeGpu", [centre, box_min, box_max, info, sphere, planes]),
            layout!(
                GpuFallbackParams,
                "FallbackParams",
                [pcf_radius, probe_size, see_width, see_height, see_view_proj, see_through, _pad0, _pad1, _pad2]
            ),
        ],
    );
    let source = format!("{}\n{}", crate::shaders::constants(), crate::fallback::PROBE_DISTANCE_WGSL);
    let module = naga::front::wgsl::parse_str(&source).expect("the probe distance pass's WGSL parses");
    check(&module, [layout!(crate::fallback::GpuProbeFace, "ProbeFace", [centre, base])]);
    // The shadow-map pass reads the views and the spheres with its own copy of `Sphere`.
    let source = with_common(&format!("{SHADOW_VIEW_WGSL}\n{SHADOW_DEPTH_WGSL}"));
    let module = naga::front::wgsl::parse_str(&source).expect("the shadow-map pass's WGSL parses");
    check(
        &module,
        [
            layout!(GpuShadowView, "ShadowViewGpu", [view_proj, near, far, texel_world, split_far, size, orthographic, array_index, layer]),
            layout!(GpuSphere, "Sphere", [center, radius, albedo, cloud]),
        ],
    );
}

/// Each Rust layout against the WGSL struct of its name in `module`.
fn check(module: &naga::Module, layouts: impl IntoIterator<Item = Layout>) {
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).expect("naga lays the types out");
    for want in layouts {
        let (handle, ty) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(want.wgsl))
            .unwrap_or_else(|| panic!("no WGSL struct `{}`", want.wgsl));
        let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("`{}` is not a struct", want.wgsl) };
        assert_eq!(layouter[handle].size as usize, want.size, "size of `{}` (WGSL span {span})", want.wgsl);
        let wgsl: Vec<(String, usize)> = members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize)).collect();
        let rust: Vec<(String, usize)> = want.fields.iter().map(|(n, o)| (n.to_string(), *o)).collect();
        if wgsl.len() == rust.len() {
            // Field by field in order: the same offsets (names may differ between the two sides).
            for ((wn, wo), (rn, ro)) in wgsl.iter().zip(&rust) {
                assert_eq!(wo, ro, "`{}`: WGSL `{wn}` at {wo}, Rust `{rn}` at {ro}", want.wgsl);
            }
        } else {
            // A Rust array spread over several WGSL members (`v: [u32; 3]` = `v0, v1, v2`): every
            // Rust field starts where a WGSL member starts.
            for (rn, ro) in &rust {
                assert!(wgsl.iter().any(|(_, wo)| wo == ro), "`{}`: Rust `{rn}` at {ro} starts no WGSL member of {wgsl:?}", want.wgsl);
            }
        }
    }
}
