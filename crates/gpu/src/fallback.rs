//! Stage 3b, the raster fallbacks (issue 18), on the GPU: the twin of `hybrid_cpu::fallback`
//! with the backend-free maths of `hybrid_core::fallback`. Shadow maps are rendered with a
//! depth-only pipeline (reversed-Z, Depth32Float, compare Greater, cleared to 0) over the caster
//! meshes into two depth texture arrays (one layer per directional cascade or spot map, one per
//! point-light cube face); each light's views are cached as the CPU caches them (a layer is
//! re-rendered only when its `ShadowView` changed). Probes are rendered with this backend's own
//! raster and deferred-lighting passes, six faces per reflective or refractive object, once,
//! when the object first has untraced pixels. Planar and convex refractive objects refract
//! through the see-through layer (`SeeThrough`): the frame's view widened, rendered by the same
//! raster and lighting passes without them into its own targets, when one has untraced pixels
//! and the view has left the kept layer's 2° (`see_through_layer_kept`), before the probes
//! (the objects it shows get probes: its texels are shaded as the trace shades a secondary
//! hit, `FallbackScene::through_layer`). A refracted ray is followed out
//! of a sphere or convex refractor first (`Refractor::leave`; hull planes in one buffer).
//! Probe faces and that layer sample textures at level 0 (`RasterPass::encode_triangles`). One
//! compute pass (`shaders/fallback.wgsl`, the twin of `FallbackScene::pixel`) then writes the
//! three fallback targets.
//!
//! Inputs: the G-buffer targets, the mask, the camera, the per-object pixel counts and selection
//! (which objects need the fallbacks). Outputs: `shadow`, `reflection`, `refraction` fallback
//! targets (Rgba16Float, shadow 1 and the others 0 where no fallback applies) and how many maps
//! and probes were rendered.
//!
//! The point-cloud spheres cast into the maps (with `spheres_in_trace`) as the CPU's discs: a
//! second, instanced draw per map of one square per sphere at the depth of its point nearest the
//! light, its fragments outside the disc discarded. They appear in the probes too: each face
//! traces the capsule first and rasterizes the polygons against its depth, as the main frame.

use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use hybrid_core::Stage;
use hybrid_core::fallback::{
    FallbackSettings, LightShadowMaps, Probe, ProbePlan, Refractor, ShadowKind, ShadowMap, ShadowView, caster_meshes, nearest_see_through,
    plan_light_views, plan_probes, refractors, scene_bounds, see_through_layer_kept, see_through_objects, see_through_view,
};
use hybrid_core::prepare::PreparedScene;
use hybrid_core::shading::{Light, lights};
use hybrid_scene::{Aabb, Camera, Scene};
use wgpu::util::DeviceExt;

use crate::capsule::GpuCapsule;
use crate::context::{GpuContext, GpuError};
use crate::heuristic::{HeuristicPasses, compute_pipeline};
use crate::lighting::LightingPass;
use crate::raster::RasterPass;
use crate::readback::read_texture_layer_bytes;
use crate::scene::SceneGpu;
use crate::shaders;
use crate::spheres::SpheresGpu;
use crate::targets::{COLOR_FORMAT, DEPTH_FORMAT, FrameTargets, Target};
use crate::timing::StageTimer;

/// The view struct and depth conventions both passes share (prepended to each, after common).
pub const SHADOW_VIEW_WGSL: &str = include_str!("shaders/shadow_view.wgsl");
/// WGSL of the shadow-map pass (common/*.wgsl is prepended).
pub const SHADOW_DEPTH_WGSL: &str = include_str!("shaders/shadow_depth.wgsl");
/// WGSL of the probe faces' distance pass (the constants header is prepended).
pub const PROBE_DISTANCE_WGSL: &str = include_str!("shaders/probe_distance.wgsl");
/// WGSL of the lookup pass after the blend's eq. 4–6 (`blend_equations.wgsl`: the see-through
/// layer's texels are composed with their own fallback terms; common/*.wgsl is prepended).
pub const FALLBACK_WGSL: &str = concat!(include_str!("shaders/blend_equations.wgsl"), "\n", include_str!("shaders/fallback.wgsl"));

/// A light's maps in `ShadowLightGpu.kind` (fallback.wgsl).
pub const SHADOW_NONE: u32 = 0;
pub const SHADOW_DIRECTIONAL: u32 = 1;
pub const SHADOW_SPOT: u32 = 2;
pub const SHADOW_POINT: u32 = 3;
/// A refractive object's shape in `ProbeGpu.info.w` (`hybrid_core::fallback::Refractor`).
pub const REFRACTOR_NONE: u32 = 0;
pub const REFRACTOR_SPHERE: u32 = 1;
pub const REFRACTOR_HULL: u32 = 2;
/// Which depth array a view lies in (`ShadowViewGpu.array_index`).
pub const SHADOW_ARRAY_MAPS: u32 = 0;
pub const SHADOW_ARRAY_CUBE: u32 = 1;

/// Lookup workgroup edge (fallback.wgsl `@workgroup_size(8, 8)`).
const GROUP: u32 = 8;

/// One shadow map as fallback.wgsl's `ShadowViewGpu` reads it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuShadowView {
    pub view_proj: [[f32; 4]; 4],
    pub near: f32,
    pub far: f32,
    pub texel_world: f32,
    pub split_far: f32,
    pub size: u32,
    pub orthographic: u32,
    pub array_index: u32,
    pub layer: u32,
}

/// Per light (`ShadowLightGpu`): its kind of maps and its views in the views buffer.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuShadowLight {
    pub kind: u32,
    pub first_view: u32,
    pub view_count: u32,
    pub _pad: u32,
}

/// Per object (`ProbeGpu`): its probe's placement and faces.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuProbe {
    /// w = the far plane (the distance where nothing was seen).
    pub centre: [f32; 4],
    /// w = 1: box-projected against `[box_min, box_max]`.
    pub box_min: [f32; 4],
    pub box_max: [f32; 4],
    /// Rendered (0/1), first layer of its six faces, see-through object (0/1), refractor
    /// (`hybrid_core::fallback::Refractor`: 0 none, 1 sphere, 2 convex hull).
    pub info: [u32; 4],
    /// A sphere refractor's centre and radius.
    pub sphere: [f32; 4],
    /// A hull refractor's first plane in `refractor_planes` and its plane count.
    pub planes: [u32; 4],
}

/// `ProbeFace` of probe_distance.wgsl: the face being rendered.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuProbeFace {
    /// w = the far plane.
    pub centre: [f32; 4],
    /// x = the face's first texel in the distance buffer.
    pub base: [u32; 4],
}

/// `FallbackParams` of fallback.wgsl: the lookups' settings and this frame's see-through layer
/// (`hybrid_core::fallback::SeeThrough`: its size and view; `see_through` 0 when not rendered).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuFallbackParams {
    pub pcf_radius: u32,
    pub probe_size: u32,
    pub see_width: u32,
    pub see_height: u32,
    pub see_view_proj: [[f32; 4]; 4],
    pub see_through: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// A Depth32Float texture array: the whole (for sampling) and one view per layer (to render).
struct DepthArray {
    texture: wgpu::Texture,
    array_view: wgpu::TextureView,
    layers: Vec<wgpu::TextureView>,
}

impl DepthArray {
    fn new(device: &wgpu::Device, label: &str, size: u32, layers: u32) -> Self {
        let layers = layers.max(1);
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width: size.max(1), height: size.max(1), depth_or_array_layers: layers },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let array_view = texture
            .create_view(&wgpu::TextureViewDescriptor { dimension: Some(wgpu::TextureViewDimension::D2Array), ..Default::default() });
        let layers = (0..layers)
            .map(|l| {
                texture.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: l,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        Self { texture, array_view, layers }
    }
}

/// One shadow-casting light's place in the arrays and its cached views.
struct LightSlot {
    kind: ShadowKind,
    /// Index of its first view in the views buffer (and uniform slots).
    first_view: u32,
    /// (array, layer) per view.
    places: Vec<(u32, u32)>,
    /// The views the layers hold now (`None`: not rendered yet).
    rendered: Vec<Option<ShadowView>>,
}

/// The views one light has (`plan_light_views`): cascades, one spot map or six cube faces.
fn view_count(light: &Light, settings: &FallbackSettings) -> u32 {
    match light {
        Light::Directional(_) => settings.cascades.clamp(1, 4),
        Light::Spot(_) => 1,
        Light::Point(_) => 6,
    }
}

/// Stage 3b's pipelines, maps, probes and outputs, made on first use and kept between frames.
pub struct FallbackGpu {
    device: wgpu::Device,
    settings: FallbackSettings,
    bounds: Aabb,
    casters: wgpu::Buffer,
    /// The point clouds' spheres (`SpheresGpu::spheres`) and how many.
    spheres: wgpu::Buffer,
    sphere_count: u32,
    disc_pipeline: wgpu::RenderPipeline,
    depth_pipeline: wgpu::RenderPipeline,
    depth_layout: wgpu::BindGroupLayout,
    lookup_pipeline: wgpu::ComputePipeline,
    lookup_layout: wgpu::BindGroupLayout,
    /// Per light in `lights()` order (= the GPU's light order).
    slots: Vec<Option<LightSlot>>,
    maps: DepthArray,
    cube: DepthArray,
    /// One `uniform_stride`-byte slot per view: its `GpuShadowView` (the depth pass's dynamic offset).
    view_uniforms: wgpu::Buffer,
    uniform_stride: u64,
    views: wgpu::Buffer,
    shadow_lights: wgpu::Buffer,
    /// Per object: its probe's plan, the first of its six layers, and whether it is rendered.
    plans: Vec<Option<(ProbePlan, u32)>>,
    probe_rendered: Vec<bool>,
    probe_faces: wgpu::Texture,
    probe_faces_view: wgpu::TextureView,
    probes: wgpu::Buffer,
    /// Per probe texel: the distance the probe saw (`Probe::distance`).
    probe_distances: wgpu::Buffer,
    /// The convex refractors' face planes (`GpuProbe::planes` indexes them).
    refractor_planes: wgpu::Buffer,
    probe_face: wgpu::Buffer,
    distance_pipeline: wgpu::ComputePipeline,
    distance_layout: wgpu::BindGroupLayout,
    probe_targets: Option<FrameTargets>,
    /// The capsule's hit ids of a probe face (not the frame's).
    probe_hit_ids: Option<wgpu::Buffer>,
    params: wgpu::Buffer,
    params_data: GpuFallbackParams,
    /// Per mesh: its object and its triangles (the probes leave their object's out).
    mesh_triangles: Vec<(u32, Range<u32>)>,
    /// Per object: the planar refractive objects (`see_through_objects`), whose refraction looks
    /// through the see-through layer (`ProbeGpu.info.z` in the lookups).
    see_through_objects: Vec<bool>,
    /// The triangles the see-through layer draws (all meshes but those objects'), in runs.
    see_through_ranges: Vec<Range<u32>>,
    /// The see-through layer's G-buffer and lighting (the frame's size widened by
    /// `SEE_THROUGH_GUARD`; 1 × 1 until a frame needs it).
    see_through_targets: FrameTargets,
    /// The three fallback targets (shadow, reflection, refraction) of the frame size.
    outputs: Option<[Target; 3]>,
    /// Shadow maps rendered per light (cascades, spot maps, cube faces) since this was made.
    pub shadow_map_renders: Vec<u64>,
    /// Probes rendered since this was made.
    pub probe_renders: u64,
    /// See-through layers rendered since this was made (kept while the view stays close, as on
    /// the CPU: `see_through_layer_kept`).
    pub see_through_renders: u64,
    /// The camera the see-through layer was last rendered with.
    see_through_view: Option<Camera>,
}

impl FallbackGpu {
    pub fn new(
        ctx: &GpuContext,
        scene: &SceneGpu,
        prepared: &PreparedScene,
        spheres: &SpheresGpu,
        spheres_cast: bool,
    ) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let settings = FallbackSettings::default();
        let s = prepared.scene;
        // The same bounds as the CPU's cache (its maps must cover the spheres it splats).
        let bounds = scene_bounds(prepared, spheres_cast);

        // Layers: cascades and spot maps in one array, cube faces in the other.
        let mut slots = Vec::new();
        let (mut maps_layers, mut cube_layers, mut views) = (0u32, 0u32, 0u32);
        for light in lights(&s.lights) {
            if !light.casts_shadows() {
                slots.push(None);
                continue;
            }
            let (kind, n) = (
                match light {
                    Light::Directional(_) => ShadowKind::Directional,
                    Light::Spot(_) => ShadowKind::Spot,
                    Light::Point(_) => ShadowKind::Point,
                },
                view_count(&light, &settings),
            );
            let places = (0..n)
                .map(|_| {
                    if kind == ShadowKind::Point {
                        cube_layers += 1;
                        (SHADOW_ARRAY_CUBE, cube_layers - 1)
                    } else {
                        maps_layers += 1;
                        (SHADOW_ARRAY_MAPS, maps_layers - 1)
                    }
                })
                .collect();
            slots.push(Some(LightSlot { kind, first_view: views, places, rendered: vec![None; n as usize] }));
            views += n;
        }
        let max_layers = device.limits().max_texture_array_layers;
        if maps_layers.max(cube_layers) > max_layers {
            return Err(GpuError::TooLarge {
                adapter: ctx.summary.name.clone(),
                why: format!("the shadow maps need {} layers, the device allows {max_layers}", maps_layers.max(cube_layers)),
            });
        }
        let maps = DepthArray::new(device, "fallback.shadow_maps", settings.shadow_map_size, maps_layers);
        let cube = DepthArray::new(device, "fallback.shadow_cube", settings.cube_shadow_size, cube_layers);
        // Dynamic offsets must be multiples of the device's alignment.
        let uniform_stride = VIEW_BYTES.next_multiple_of(u64::from(device.limits().min_uniform_buffer_offset_alignment).max(16));
        let view_uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("fallback.view_uniforms"),
            size: uniform_stride * u64::from(views.max(1)),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let views_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("fallback.views"),
            size: (std::mem::size_of::<GpuShadowView>() as u64) * u64::from(views.max(1)),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let shadow_lights = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("fallback.lights"),
            contents: bytemuck::cast_slice(&vec![GpuShadowLight::default(); slots.len().max(1)]),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        });

        let casters: Vec<u32> = caster_meshes(prepared).into_iter().map(u32::from).collect();
        let casters = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("fallback.casters"),
            contents: bytemuck::cast_slice(if casters.is_empty() { &[0u32][..] } else { &casters }),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let mut first = 0u32;
        let mesh_triangles = prepared
            .meshes
            .iter()
            .map(|m| {
                let r = first..first + m.indices.len() as u32;
                first = r.end;
                (m.object, r)
            })
            .collect::<Vec<(u32, Range<u32>)>>();
        let refractors = refractors(prepared);
        let see_through_objects = see_through_objects(prepared, &refractors);
        let see_through_ranges = triangle_runs(&mesh_triangles, |o| !see_through_objects.get(o as usize).copied().unwrap_or(false));

        // Probes: six layers per planned object.
        let mut plans = vec![None; s.objects.len()];
        let mut probe_data = vec![GpuProbe::zeroed(); s.objects.len().max(1)];
        // Per object: see-through, and the shape a refraction ray leaves it by (hull planes
        // gathered into one buffer).
        let mut planes: Vec<[f32; 4]> = Vec::new();
        for ((data, &see), refractor) in probe_data.iter_mut().zip(&see_through_objects).zip(&refractors) {
            data.info[2] = u32::from(see);
            match refractor {
                Some(Refractor::Sphere { centre, radius }) => {
                    data.info[3] = REFRACTOR_SPHERE;
                    data.sphere = centre.extend(*radius).to_array();
                }
                Some(Refractor::Hull(hull)) => {
                    data.info[3] = REFRACTOR_HULL;
                    data.planes = [planes.len() as u32, hull.planes.len() as u32, 0, 0];
                    planes.extend(hull.planes.iter().map(|p| p.to_array()));
                }
                None => {}
            }
        }
        let mut layers = 0u32;
        for plan in plan_probes(prepared, &scene_bounds(prepared, false)) {
            let o = plan.object as usize;
            let b = plan.parallax_box.unwrap_or(Aabb::EMPTY);
            probe_data[o] = GpuProbe {
                centre: plan.centre.extend(plan.far).to_array(),
                box_min: b.min.extend(if plan.parallax_box.is_some() { 1.0 } else { 0.0 }).to_array(),
                box_max: b.max.extend(0.0).to_array(),
                info: [0, layers, probe_data[o].info[2], probe_data[o].info[3]],
                ..probe_data[o]
            };
            plans[o] = Some((plan, layers));
            layers += 6;
        }
        if layers > max_layers {
            return Err(GpuError::TooLarge {
                adapter: ctx.summary.name.clone(),
                why: format!("the probes need {layers} layers, the device allows {max_layers}"),
            });
        }
        let probe_faces = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("fallback.probe_faces"),
            size: wgpu::Extent3d { width: settings.probe_size, height: settings.probe_size, depth_or_array_layers: layers.max(1) },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: COLOR_FORMAT,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let probe_faces_view = probe_faces
            .create_view(&wgpu::TextureViewDescriptor { dimension: Some(wgpu::TextureViewDimension::D2Array), ..Default::default() });
        let probes = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("fallback.probes"),
            contents: bytemuck::cast_slice(&probe_data),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        });
        let refractor_planes = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("fallback.refractor_planes"),
            contents: bytemuck::cast_slice(if planes.is_empty() { &[[0.0f32; 4]][..] } else { &planes[..] }),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let texels = u64::from(settings.probe_size) * u64::from(settings.probe_size);
        let probe_distances = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("fallback.probe_distances"),
            size: u64::from(layers.max(1)) * texels * 4,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let probe_face = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("fallback.probe_face"),
            size: std::mem::size_of::<GpuProbeFace>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let (distance_pipeline, distance_layout) = distance_pipeline(device);
        let params_data = GpuFallbackParams {
            pcf_radius: settings.pcf_radius,
            probe_size: settings.probe_size,
            see_width: 1,
            see_height: 1,
            see_view_proj: glam::Mat4::IDENTITY.to_cols_array_2d(),
            see_through: 0,
            _pad0: 0,
            _pad1: 0,
            _pad2: 0,
        };
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("fallback.params"),
            contents: bytemuck::bytes_of(&params_data),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });

        let sampled = device.limits().max_sampled_textures_per_shader_stage;
        if sampled < LOOKUP_SAMPLED_TEXTURES {
            return Err(GpuError::Unsupported {
                adapter: ctx.summary.name.clone(),
                why: format!(
                    "the fallbacks' lookup pass samples {LOOKUP_SAMPLED_TEXTURES} textures, the device allows {sampled} per shader stage (--fallback none does without)"
                ),
            });
        }
        let (depth_pipeline, disc_pipeline, depth_layout) = depth_pipelines(device, scene);
        let (lookup_pipeline, lookup_layout) = lookup_pipeline(device, scene);
        Ok(Self {
            device: device.clone(),
            settings,
            bounds,
            casters,
            spheres: spheres.spheres.clone(),
            sphere_count: spheres.count,
            disc_pipeline,
            depth_pipeline,
            depth_layout,
            lookup_pipeline,
            lookup_layout,
            shadow_map_renders: vec![0; slots.len()],
            slots,
            maps,
            cube,
            view_uniforms,
            uniform_stride,
            views: views_buffer,
            shadow_lights,
            probe_rendered: vec![false; plans.len()],
            plans,
            probe_faces,
            probe_faces_view,
            probes,
            probe_distances,
            refractor_planes,
            probe_face,
            distance_pipeline,
            distance_layout,
            probe_targets: None,
            probe_hit_ids: None,
            params,
            params_data,
            mesh_triangles,
            see_through_objects,
            see_through_ranges,
            see_through_targets: FrameTargets::raster_layer(device, 1, 1),
            outputs: None,
            probe_renders: 0,
            see_through_renders: 0,
            see_through_view: None,
        })
    }

    /// Every shadow-casting light's maps as last rendered, read back (`--dump`'s
    /// `shadow_map_<light>.exr`, tests); lights not rendered yet are left out. Waits for the GPU.
    pub fn shadow_maps(&self, ctx: &GpuContext) -> Result<Vec<LightShadowMaps>, GpuError> {
        let mut out = Vec::new();
        for (light, slot) in self.slots.iter().enumerate() {
            let Some(slot) = slot else { continue };
            let Some(views) = slot.rendered.iter().copied().collect::<Option<Vec<ShadowView>>>() else { continue };
            let mut maps = Vec::with_capacity(views.len());
            for (view, &(array, layer)) in views.into_iter().zip(&slot.places) {
                let texture = if array == SHADOW_ARRAY_CUBE { &self.cube.texture } else { &self.maps.texture };
                let depth = bytemuck::pod_collect_to_vec(&read_texture_layer_bytes(ctx, texture, layer)?);
                maps.push(ShadowMap { view, depth });
            }
            out.push(LightShadowMaps { light, kind: slot.kind, maps });
        }
        Ok(out)
    }

    /// Per object: whether its refraction looks through the see-through layer (planar
    /// refractive objects, `hybrid_core::fallback::see_through_objects`).
    pub fn see_through_objects(&self) -> &[bool] {
        &self.see_through_objects
    }

    /// The three fallback targets (shadow, reflection, refraction), once a frame has made them.
    pub fn outputs(&self) -> Option<&[Target; 3]> {
        self.outputs.as_ref()
    }

    /// Brings the lights' views up to date for `camera` (`plan_light_views`) and returns the
    /// views whose maps must be re-rendered (their `ShadowView` changed or was never rendered),
    /// as indices into the views buffer. Counts them in `shadow_map_renders`.
    pub fn update_views(&mut self, ctx: &GpuContext, scene: &Scene, camera: &Camera, aspect: f32) -> Vec<u32> {
        let mut to_render = Vec::new();
        let mut lights_data = vec![GpuShadowLight::default(); self.slots.len().max(1)];
        let slots = &self.slots;
        let previous = |light: usize, k: usize| slots.get(light)?.as_ref()?.rendered.get(k).copied().flatten();
        for lv in plan_light_views(scene, &self.bounds, camera, aspect, &self.settings, &previous) {
            let Some(slot) = self.slots.get_mut(lv.light).and_then(Option::as_mut) else { continue };
            if slot.kind != lv.kind || lv.views.len() != slot.places.len() {
                // Cannot happen (the layers were counted from the same lights and settings); a
                // light whose views do not fit keeps no maps rather than wrong ones.
                continue;
            }
            let mut data = Vec::with_capacity(lv.views.len());
            for (k, view) in lv.views.iter().enumerate() {
                let index = slot.first_view + k as u32;
                let (array, layer) = slot.places[k];
                let gpu_view = GpuShadowView {
                    view_proj: view.view_proj.to_cols_array_2d(),
                    near: view.near,
                    far: view.far,
                    texel_world: view.texel_world,
                    split_far: view.split_far,
                    size: view.size,
                    orthographic: u32::from(view.orthographic),
                    array_index: array,
                    layer,
                };
                if slot.rendered[k] != Some(*view) {
                    slot.rendered[k] = Some(*view);
                    to_render.push(index);
                    self.shadow_map_renders[lv.light] += 1;
                    ctx.queue.write_buffer(&self.view_uniforms, u64::from(index) * self.uniform_stride, bytemuck::bytes_of(&gpu_view));
                }
                data.push(gpu_view);
            }
            ctx.queue.write_buffer(
                &self.views,
                u64::from(slot.first_view) * std::mem::size_of::<GpuShadowView>() as u64,
                bytemuck::cast_slice(&data),
            );
            lights_data[lv.light] = GpuShadowLight {
                kind: match lv.kind {
                    ShadowKind::Directional => SHADOW_DIRECTIONAL,
                    ShadowKind::Spot => SHADOW_SPOT,
                    ShadowKind::Point => SHADOW_POINT,
                },
                first_view: slot.first_view,
                view_count: lv.views.len() as u32,
                _pad: 0,
            };
        }
        ctx.queue.write_buffer(&self.shadow_lights, 0, bytemuck::cast_slice(&lights_data));
        to_render
    }

    /// Renders the probe of every object in `needed` that has a plan and no probe yet: six faces
    /// with the raster and deferred-lighting passes (the object's own meshes left out; with
    /// `capsule`, its spheres traced first and merged by depth, as the main frame's), each
    /// face its own submission (the frame uniforms hold the face's camera). The caller must
    /// write the frame's own uniforms again afterwards when this returns more than 0.
    #[allow(clippy::too_many_arguments)]
    pub fn render_probes(
        &mut self,
        ctx: &GpuContext,
        scene_gpu: &SceneGpu,
        scene: &Scene,
        raster: &RasterPass,
        lighting: &LightingPass,
        capsule: Option<(&GpuCapsule, &SpheresGpu)>,
        needed: &[bool],
    ) -> u64 {
        let size = self.settings.probe_size;
        let mut rendered = 0;
        let mut timer = StageTimer::disabled();
        for (object, &need) in needed.iter().enumerate() {
            let Some(Some((plan, first_layer))) = self.plans.get(object) else { continue };
            if !need || self.probe_rendered[object] {
                continue;
            }
            let (plan, first_layer) = (*plan, *first_layer);
            let targets = self.probe_targets.get_or_insert_with(|| FrameTargets::new(&ctx.device, size, size));
            // The triangles of every mesh but the object's own, in runs.
            let ranges = triangle_runs(&self.mesh_triangles, |o| o != plan.object);
            let probe = Probe::new(plan, size);
            for face in 0..6u32 {
                let camera = probe.face_camera(face as usize);
                scene_gpu.write_uniforms(ctx, &camera, size, size, &scene.environment);
                let face_info =
                    GpuProbeFace { centre: plan.centre.extend(plan.far).to_array(), base: [(first_layer + face) * size * size, 0, 0, 0] };
                ctx.queue.write_buffer(&self.probe_face, 0, bytemuck::bytes_of(&face_info));
                let mut enc = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("fallback: probe face") });
                if let Some((capsule, spheres)) = capsule {
                    let ids = self.probe_hit_ids.get_or_insert_with(|| {
                        ctx.device.create_buffer(&wgpu::BufferDescriptor {
                            label: Some("fallback.probe_hit_ids"),
                            size: u64::from(size) * u64::from(size) * 4,
                            usage: wgpu::BufferUsages::STORAGE,
                            mapped_at_creation: false,
                        })
                    });
                    capsule.encode_with_ids(&mut enc, scene_gpu, spheres, targets, false, ids, &mut timer);
                    capsule.encode_unpack(&mut enc, scene_gpu, targets, true, &mut timer);
                }
                raster.encode_triangles(&mut enc, scene_gpu, targets, capsule.is_none(), &ranges, &mut timer);
                lighting.encode(&mut enc, scene_gpu, targets, &mut timer);
                // The distance to what each texel saw (the lookups' parallax march).
                let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("fallback.probe_distance"),
                    layout: &self.distance_layout,
                    entries: &[
                        wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&targets.position.view) },
                        wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&targets.object_id.view) },
                        wgpu::BindGroupEntry { binding: 2, resource: self.probe_distances.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 3, resource: self.probe_face.as_entire_binding() },
                    ],
                });
                {
                    let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some("fallback: probe distances"),
                        timestamp_writes: None,
                    });
                    pass.set_pipeline(&self.distance_pipeline);
                    pass.set_bind_group(0, &bind_group, &[]);
                    pass.dispatch_workgroups(size.div_ceil(GROUP), size.div_ceil(GROUP), 1);
                }
                enc.copy_texture_to_texture(
                    targets.lighting.texture.as_image_copy(),
                    wgpu::TexelCopyTextureInfo {
                        texture: &self.probe_faces,
                        mip_level: 0,
                        origin: wgpu::Origin3d { x: 0, y: 0, z: first_layer + face },
                        aspect: wgpu::TextureAspect::All,
                    },
                    wgpu::Extent3d { width: size, height: size, depth_or_array_layers: 1 },
                );
                ctx.queue.submit([enc.finish()]);
            }
            // Mark it rendered (info.x of its ProbeGpu).
            let offset = object as u64 * std::mem::size_of::<GpuProbe>() as u64 + std::mem::offset_of!(GpuProbe, info) as u64;
            ctx.queue.write_buffer(&self.probes, offset, bytemuck::cast_slice(&[1u32]));
            self.probe_rendered[object] = true;
            self.probe_renders += 1;
            rendered += 1;
        }
        rendered
    }

    /// The see-through layer of a `width` × `height` frame seen by `camera`
    /// (`hybrid_core::fallback::SeeThrough`), when a see-through object is in `needed`
    /// (per object: has untraced pixels): the widened view (`see_through_view`) rasterized
    /// without those objects' meshes (textures at level 0) and lit, in its own submission (the
    /// frame uniforms hold its camera). Its texels are shaded with their own probes, so the
    /// objects that show in it need probes too, as on the CPU. The layer is kept while the view
    /// stays close to its own (`see_through_layer_kept`, as on the CPU). While some object's
    /// planned probe is not rendered yet, `counter` (the heuristic's count pass,
    /// whose counts the frame has already read) counts the layer's pixels per object id in that
    /// submission, read back (the host waits for the GPU then). Writes the lookups' params (the
    /// layer's view, or none). Returns, when the layer was rendered, per object whether it shows
    /// in the layer and still lacks its probe; the caller must write the frame's own uniforms
    /// again then.
    #[allow(clippy::too_many_arguments)]
    pub fn render_see_through(
        &mut self,
        ctx: &GpuContext,
        scene_gpu: &SceneGpu,
        prepared: &PreparedScene,
        raster: &RasterPass,
        lighting: &LightingPass,
        counter: &HeuristicPasses,
        camera: &Camera,
        (width, height): (u32, u32),
        needed: &[bool],
    ) -> Result<Option<Vec<bool>>, GpuError> {
        let need = needed.iter().zip(&self.see_through_objects).any(|(&n, &s)| n && s);
        self.params_data.see_through = u32::from(need);
        let mut shown = None;
        let (view, w, h) = see_through_view(camera, width, height);
        let layer_size = (self.see_through_targets.width, self.see_through_targets.height);
        let kept = |layer: Camera| {
            let nearest = nearest_see_through(camera.position, &prepared.object_bounds, &self.see_through_objects, needed);
            see_through_layer_kept(&layer, layer_size, &view, (w, h), nearest)
        };
        if need && !self.see_through_view.is_some_and(kept) {
            // Per object: a planned probe not rendered yet; with none, nothing is worth counting.
            let missing: Vec<bool> = self.plans.iter().zip(&self.probe_rendered).map(|(p, &done)| p.is_some() && !done).collect();
            let count = missing.iter().any(|&m| m);
            self.see_through_view = Some(view);
            if (self.see_through_targets.width, self.see_through_targets.height) != (w, h) {
                self.see_through_targets = FrameTargets::raster_layer(&ctx.device, w, h);
            }
            let targets = &self.see_through_targets;
            scene_gpu.write_uniforms(ctx, &view, w, h, &prepared.scene.environment);
            let mut timer = StageTimer::disabled();
            let mut enc = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("fallback: see-through") });
            raster.encode_triangles(&mut enc, scene_gpu, targets, true, &self.see_through_ranges, &mut timer);
            lighting.encode(&mut enc, scene_gpu, targets, &mut timer);
            if count {
                counter.encode_count(&mut enc, targets, &mut timer);
            }
            ctx.queue.submit([enc.finish()]);
            shown = Some(if count {
                counter.read_counts(ctx)?.into_iter().zip(missing).map(|(pixels, m)| pixels > 0 && m).collect()
            } else {
                missing // all false
            });
            self.see_through_renders += 1;
            self.params_data.see_width = w;
            self.params_data.see_height = h;
            self.params_data.see_view_proj = view.view_projection(w as f32 / h.max(1) as f32).to_cols_array_2d();
        }
        ctx.queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&self.params_data));
        Ok(shown)
    }

    /// Makes the three fallback targets for a `width` × `height` frame (kept while the size stays).
    pub fn ensure_outputs(&mut self, width: u32, height: u32) {
        if self.outputs.as_ref().is_some_and(|o| o[0].texture.width() == width && o[0].texture.height() == height) {
            return;
        }
        let t = |label| Target::new(&self.device, label, width, height, COLOR_FORMAT);
        self.outputs = Some([t("fallback.shadow"), t("fallback.reflection"), t("fallback.refraction")]);
    }

    /// Records the maps of `to_render` (from [`Self::update_views`]; with the spheres' discs when
    /// `splat_spheres`) and the lookup pass into the fallback targets ([`Self::ensure_outputs`]
    /// first). The first map pass and the lookup pass are timed as `Stage::Fallback` (its span
    /// covers the passes between).
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &SceneGpu,
        targets: &FrameTargets,
        to_render: &[u32],
        splat_spheres: bool,
        timer: &mut StageTimer,
    ) {
        let views_of = |index: u32| {
            self.slots.iter().flatten().find_map(|s| {
                let k = index.checked_sub(s.first_view)? as usize;
                s.places.get(k).copied()
            })
        };
        if !to_render.is_empty() {
            let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("fallback.depth"),
                layout: &self.depth_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &self.view_uniforms,
                            offset: 0,
                            size: wgpu::BufferSize::new(VIEW_BYTES),
                        }),
                    },
                    wgpu::BindGroupEntry { binding: 1, resource: self.casters.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: self.spheres.as_entire_binding() },
                ],
            });
            for (k, &index) in to_render.iter().enumerate() {
                let Some((array, layer)) = views_of(index) else { continue };
                let view = if array == SHADOW_ARRAY_CUBE { &self.cube.layers[layer as usize] } else { &self.maps.layers[layer as usize] };
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("fallback: shadow map"),
                    color_attachments: &[],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view,
                        depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Store }),
                        stencil_ops: None,
                    }),
                    timestamp_writes: if k == 0 { timer.render(Stage::Fallback) } else { None },
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                if scene.triangle_count > 0 {
                    pass.set_pipeline(&self.depth_pipeline);
                    pass.set_bind_group(0, &scene.bind_group, &[]);
                    pass.set_bind_group(1, &bind_group, &[(u64::from(index) * self.uniform_stride) as u32]);
                    pass.draw(0..3 * scene.triangle_count, 0..1);
                }
                if splat_spheres && self.sphere_count > 0 {
                    pass.set_pipeline(&self.disc_pipeline);
                    pass.set_bind_group(0, &scene.bind_group, &[]);
                    pass.set_bind_group(1, &bind_group, &[(u64::from(index) * self.uniform_stride) as u32]);
                    pass.draw(0..6, 0..self.sphere_count);
                }
            }
        }
        let Some(outputs) = &self.outputs else { return };
        let texture = |b: u32, view| (b, wgpu::BindingResource::TextureView(view));
        let resources = [
            texture(0, &targets.position.view),
            texture(1, &targets.normal.view),
            texture(2, &targets.diffuse.view),
            texture(3, &targets.specular.view),
            texture(4, &targets.optical.view),
            texture(5, &targets.object_id.view),
            texture(6, &targets.mask.view),
            texture(7, &outputs[0].view),
            texture(8, &outputs[1].view),
            texture(9, &outputs[2].view),
            texture(10, &self.maps.array_view),
            texture(11, &self.cube.array_view),
            (12, self.views.as_entire_binding()),
            (13, self.shadow_lights.as_entire_binding()),
            texture(14, &self.probe_faces_view),
            (15, self.probes.as_entire_binding()),
            (16, self.params.as_entire_binding()),
            (17, self.probe_distances.as_entire_binding()),
            texture(18, &self.see_through_targets.position.view),
            texture(19, &self.see_through_targets.normal.view),
            texture(20, &self.see_through_targets.object_id.view),
            texture(21, &self.see_through_targets.lighting.view),
            texture(22, &self.see_through_targets.diffuse.view),
            texture(23, &self.see_through_targets.specular.view),
            texture(24, &self.see_through_targets.optical.view),
            (25, self.refractor_planes.as_entire_binding()),
        ];
        let entries: Vec<wgpu::BindGroupEntry> =
            resources.into_iter().map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource }).collect();
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("fallback.lookup"),
            layout: &self.lookup_layout,
            entries: &entries,
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("fallback: lookups"),
            timestamp_writes: timer.compute(Stage::Fallback),
        });
        pass.set_pipeline(&self.lookup_pipeline);
        pass.set_bind_group(0, &scene.bind_group, &[]);
        pass.set_bind_group(1, &bind_group, &[]);
        pass.dispatch_workgroups(targets.width.div_ceil(GROUP), targets.height.div_ceil(GROUP), 1);
    }
}

/// Bytes of one view in the depth pass's uniform slots.
const VIEW_BYTES: u64 = std::mem::size_of::<GpuShadowView>() as u64;

/// The depth-only pipelines of the shadow maps (caster triangles; the spheres' discs) and their
/// group 1 (the view by dynamic offset, caster flags, spheres).
fn depth_pipelines(device: &wgpu::Device, scene: &SceneGpu) -> (wgpu::RenderPipeline, wgpu::RenderPipeline, wgpu::BindGroupLayout) {
    let storage = |binding: u32| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::VERTEX,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("fallback.depth"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: true,
                    min_binding_size: wgpu::BufferSize::new(VIEW_BYTES),
                },
                count: None,
            },
            storage(1),
            storage(2),
        ],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("fallback.depth"),
        bind_group_layouts: &[Some(&scene.layout), Some(&layout)],
        immediate_size: 0,
    });
    let module = shaders::module(device, "fallback.depth", &format!("{SHADOW_VIEW_WGSL}\n{SHADOW_DEPTH_WGSL}"));
    let pipeline = |label: &str, vertex: &str, fragment: Option<&str>| {
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(label),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState { module: &module, entry_point: Some(vertex), compilation_options: Default::default(), buffers: &[] },
            primitive: wgpu::PrimitiveState { topology: wgpu::PrimitiveTopology::TriangleList, cull_mode: None, ..Default::default() },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Greater),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: fragment.map(|entry| wgpu::FragmentState {
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                targets: &[],
            }),
            multiview_mask: None,
            cache: None,
        })
    };
    (pipeline("fallback.depth", "vs_shadow", None), pipeline("fallback.discs", "vs_disc", Some("fs_disc")), layout)
}

/// The probe faces' distance pass (probe_distance.wgsl) and its group 0.
fn distance_pipeline(device: &wgpu::Device) -> (wgpu::ComputePipeline, wgpu::BindGroupLayout) {
    let entry = |binding: u32, ty: wgpu::BindingType| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty,
        count: None,
    };
    let texture =
        |sample_type| wgpu::BindingType::Texture { sample_type, view_dimension: wgpu::TextureViewDimension::D2, multisampled: false };
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("fallback.probe_distance"),
        entries: &[
            entry(0, texture(wgpu::TextureSampleType::Float { filterable: false })),
            entry(1, texture(wgpu::TextureSampleType::Uint)),
            entry(
                2,
                wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: false },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
            ),
            entry(3, wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: false, min_binding_size: None }),
        ],
    });
    let pipeline = compute_pipeline(device, "fallback.probe_distance", PROBE_DISTANCE_WGSL, "probe_distance", &layout);
    (pipeline, layout)
}

/// The triangles of the meshes whose object passes `keep`, merged into runs.
fn triangle_runs(mesh_triangles: &[(u32, Range<u32>)], keep: impl Fn(u32) -> bool) -> Vec<Range<u32>> {
    let mut ranges: Vec<Range<u32>> = Vec::new();
    for (o, r) in mesh_triangles {
        if !keep(*o) || r.is_empty() {
            continue;
        }
        match ranges.last_mut() {
            Some(last) if last.end == r.start => last.end = r.end,
            _ => ranges.push(r.clone()),
        }
    }
    ranges
}

/// Sampled textures the lookup pass binds (fallback.wgsl's group 1: the frame's G-buffer and
/// mask, the two shadow-map arrays, the probe faces, the see-through layer's seven targets);
/// `FallbackGpu::new` refuses a device that allows fewer per shader stage (wgpu's default is 16).
pub const LOOKUP_SAMPLED_TEXTURES: u32 = 17;

/// The lookup compute pipeline and its group 1 (fallback.wgsl's bindings 0–25).
fn lookup_pipeline(device: &wgpu::Device, scene: &SceneGpu) -> (wgpu::ComputePipeline, wgpu::BindGroupLayout) {
    let entry = |binding: u32, ty: wgpu::BindingType| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty,
        count: None,
    };
    let texture = |sample_type, view_dimension| wgpu::BindingType::Texture { sample_type, view_dimension, multisampled: false };
    let float = wgpu::TextureSampleType::Float { filterable: false };
    let d2 = wgpu::TextureViewDimension::D2;
    let storage =
        wgpu::BindingType::StorageTexture { access: wgpu::StorageTextureAccess::WriteOnly, format: COLOR_FORMAT, view_dimension: d2 };
    let buffer = |read_only: bool| wgpu::BindingType::Buffer {
        ty: wgpu::BufferBindingType::Storage { read_only },
        has_dynamic_offset: false,
        min_binding_size: None,
    };
    let entries = [
        entry(0, texture(float, d2)),
        entry(1, texture(float, d2)),
        entry(2, texture(float, d2)),
        entry(3, texture(float, d2)),
        entry(4, texture(float, d2)),
        entry(5, texture(wgpu::TextureSampleType::Uint, d2)),
        entry(6, texture(float, d2)),
        entry(7, storage),
        entry(8, storage),
        entry(9, storage),
        entry(10, texture(wgpu::TextureSampleType::Depth, wgpu::TextureViewDimension::D2Array)),
        entry(11, texture(wgpu::TextureSampleType::Depth, wgpu::TextureViewDimension::D2Array)),
        entry(12, buffer(true)),
        entry(13, buffer(true)),
        entry(14, texture(float, wgpu::TextureViewDimension::D2Array)),
        entry(15, buffer(true)),
        entry(16, wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: false, min_binding_size: None }),
        entry(17, buffer(true)),
        entry(18, texture(float, d2)),
        entry(19, texture(float, d2)),
        entry(20, texture(wgpu::TextureSampleType::Uint, d2)),
        entry(21, texture(float, d2)),
        entry(22, texture(float, d2)),
        entry(23, texture(float, d2)),
        entry(24, texture(float, d2)),
        entry(25, buffer(true)),
    ];
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("fallback.lookup"), entries: &entries });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("fallback.lookup"),
        bind_group_layouts: &[Some(&scene.layout), Some(&layout)],
        immediate_size: 0,
    });
    let module = shaders::module(device, "fallback.lookup", &format!("{SHADOW_VIEW_WGSL}\n{FALLBACK_WGSL}"));
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("fallback.lookup"),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some("cs_fallback"),
        compilation_options: Default::default(),
        cache: None,
    });
    (pipeline, layout)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fallback_wgsl_is_valid() {
        for (name, source) in [("shadow_depth.wgsl", SHADOW_DEPTH_WGSL), ("fallback.wgsl", FALLBACK_WGSL)] {
            if let Err(e) = shaders::validate(&shaders::with_common(&format!("{SHADOW_VIEW_WGSL}\n{source}"))) {
                panic!("{name}: {e}");
            }
        }
    }

    /// The sampled textures the lookup pass declares (every stage's textures, group 0's
    /// included) are the number `FallbackGpu::new` checks against the device's limit.
    #[test]
    fn lookup_sampled_textures_are_counted() {
        let source = shaders::with_common(&format!("{SHADOW_VIEW_WGSL}\n{FALLBACK_WGSL}"));
        let module = naga::front::wgsl::parse_str(&source).expect("fallback.wgsl parses");
        let sampled = module
            .global_variables
            .iter()
            .filter(|(_, v)| match module.types[v.ty].inner {
                naga::TypeInner::Image { class, .. } => !matches!(class, naga::ImageClass::Storage { .. }),
                _ => false,
            })
            .count();
        assert_eq!(sampled as u32, LOOKUP_SAMPLED_TEXTURES);
    }

    #[test]
    fn shader_constants_match_rust() {
        assert!(FALLBACK_WGSL.contains(&format!("@workgroup_size({GROUP}, {GROUP})")));
        assert!(PROBE_DISTANCE_WGSL.contains(&format!("@workgroup_size({GROUP}, {GROUP}, 1)")));
        if let Err(e) = shaders::validate(&format!("{}\n{PROBE_DISTANCE_WGSL}", shaders::constants())) {
            panic!("probe_distance.wgsl: {e}");
        }
        for name in [
            "SHADOW_DIRECTIONAL",
            "SHADOW_POINT",
            "SHADOW_ARRAY_CUBE",
            "SHADOW_MAX_SLOPE",
            "SHADOW_BIAS_TEXELS",
            "PROBE_MARCH_STEPS",
            "SEE_THROUGH_STEPS",
            "REFRACTOR_BOUNCES",
            "REFRACTOR_HULL",
            "CUBE_FACE_UP",
        ] {
            assert!(FALLBACK_WGSL.contains(name) && !FALLBACK_WGSL.contains(&format!("const {name}")), "{name}");
        }
    }
}
