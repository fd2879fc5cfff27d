//! `open_scene`: the scene the viewer shows and the renderer built for it, held together in one
//! value ([`OpenScene`]) so that dropping another file on the window, or switching a light off,
//! can replace both while the window, device and overlay stay.

use std::sync::Arc;

use glam::Vec3;
use hybrid_core::report::FrameReport;
use hybrid_core::{Frame, FrameSettings};
use hybrid_cpu::capsule::PrimaryVisibility;
use hybrid_cpu::frame::CpuRenderer;
use hybrid_gpu::frame::GpuRenderer;
use hybrid_gpu::{GpuContext, RtChoice};
use hybrid_heuristic::Heuristic;
use hybrid_scene::{Aabb, Camera, Lights, Projection, Scene};
use self_cell::self_cell;

/// A renderer on the backend in use, borrowing the open scene.
pub enum Renderer<'s> {
    Cpu(Box<CpuRenderer<'s>>),
    Gpu(Box<GpuRenderer<'s>>),
}

self_cell!(
    /// The open scene and its renderer (which borrows it).
    pub struct OpenScene {
        owner: Scene,
        #[not_covariant]
        dependent: Renderer,
    }
);

/// The renderer's knobs that live outside the scene, re-applied when the scene is rebuilt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RendererKnobs {
    pub clip_capsule: bool,
    pub sphere_effects: bool,
    /// CPU backend only (the GPU capsule has one way to find primary hits).
    pub primary_visibility: PrimaryVisibility,
    /// GPU backend: hardware or software ray tracing (`--rt`).
    pub rt: RtChoice,
    /// `--fallback`.
    pub fallback: hybrid_core::fallback::Fallback,
}

impl OpenScene {
    /// Builds the renderer for `scene` on the GPU context `gpu`, or on the CPU when `None`.
    pub fn open(scene: Scene, gpu: Option<&Arc<GpuContext>>, knobs: RendererKnobs) -> Result<OpenScene, String> {
        OpenScene::try_new(scene, |scene| {
            let mut r = match gpu {
                Some(ctx) => Renderer::Gpu(Box::new(GpuRenderer::with_rt(ctx.clone(), scene, knobs.rt).map_err(|e| e.to_string())?)),
                None => Renderer::Cpu(Box::new(CpuRenderer::new(scene).map_err(|e| e.to_string())?)),
            };
            r.apply(knobs);
            Ok(r)
        })
    }
}

impl Renderer<'_> {
    pub fn apply(&mut self, knobs: RendererKnobs) {
        match self {
            Renderer::Cpu(r) => {
                r.clip_capsule_at_raster_depth = knobs.clip_capsule;
                r.spheres_in_trace = knobs.sphere_effects;
                r.fallback = knobs.fallback;
                r.set_capsule_visibility(knobs.primary_visibility);
            }
            Renderer::Gpu(r) => {
                r.clip_capsule_at_raster_depth = knobs.clip_capsule;
                r.spheres_in_trace = knobs.sphere_effects;
                r.fallback = knobs.fallback;
            }
        }
    }

    pub fn heuristic_mut(&mut self) -> &mut Heuristic {
        match self {
            Renderer::Cpu(r) => r.heuristic_mut(),
            Renderer::Gpu(r) => r.heuristic_mut(),
        }
    }

    /// Object `id`'s K and E in place of the scene file's (`None`: the file's).
    pub fn set_object_weights(&mut self, id: usize, weights: Option<(f32, f32)>) {
        match self {
            Renderer::Cpu(r) => r.heuristic_stage_mut().set_object_weights(id, weights),
            Renderer::Gpu(r) => r.heuristic_stage_mut().set_object_weights(id, weights),
        }
    }

    /// One frame with every buffer on the host (the CPU frame; the GPU frame read back).
    pub fn render(&mut self, camera: &Camera, settings: FrameSettings) -> Result<Frame, String> {
        match self {
            Renderer::Cpu(r) => Ok(r.render(camera, settings, &mut |_| {})),
            Renderer::Gpu(r) => r.render(camera, settings, &mut |_| {}).map_err(|e| e.to_string()),
        }
    }

    /// Hands a frame's buffers back for reuse (CPU backend; the GPU keeps its own targets).
    pub fn recycle(&mut self, frame: Frame) {
        if let Renderer::Cpu(r) = self {
            r.recycle(frame);
        }
    }

    /// GPU backend: one frame into the renderer's targets, nothing read back.
    pub fn render_to_targets(&mut self, camera: &Camera, settings: FrameSettings) -> Option<Result<FrameReport, String>> {
        match self {
            Renderer::Cpu(_) => None,
            Renderer::Gpu(r) => Some(r.render_to_targets(camera, settings, &mut |_| {}).map_err(|e| e.to_string())),
        }
    }
}

/// `lights` with the lights whose entry in `on` is false left out (`on` lists directional, then
/// point, then spot lights, as [`light_names`]).
pub fn lights_switched(lights: &Lights, on: &[bool]) -> Lights {
    let mut i = 0;
    let mut keep = || {
        let k = on.get(i).copied().unwrap_or(true);
        i += 1;
        k
    };
    let directional = lights.directional.iter().filter(|_| keep()).cloned().collect();
    let point = lights.point.iter().filter(|_| keep()).cloned().collect();
    let spot = lights.spot.iter().filter(|_| keep()).cloned().collect();
    Lights { directional, point, spot }
}

/// One name per light, in [`lights_switched`]'s order.
pub fn light_names(lights: &Lights) -> Vec<String> {
    let d = (0..lights.directional.len()).map(|i| format!("directional {}", i + 1));
    let p = (0..lights.point.len()).map(|i| format!("point {}", i + 1));
    let s = (0..lights.spot.len()).map(|i| format!("spot {}", i + 1));
    d.chain(p).chain(s).collect()
}

/// The bounds `F` frames: every object and point cloud, except flat objects (ground planes, which
/// a bare model's default scene makes 8 times wider than the model) unless nothing else is there.
pub fn frame_bounds(scene: &Scene) -> Option<Aabb> {
    let objects: Vec<Aabb> = scene.objects.iter().filter_map(|o| o.world_bounds()).collect();
    let clouds = scene.point_clouds.iter().map(|c| c.bounds()).filter(|b| !b.is_empty());
    let flat = |b: &Aabb| (b.max - b.min).min_element() <= 1e-6 * (b.max - b.min).max_element().max(1e-30);
    let solid: Vec<Aabb> = objects.iter().filter(|b| !flat(b)).copied().chain(clouds).collect();
    let pick = if solid.is_empty() { objects } else { solid };
    let b = pick.iter().fold(Aabb::EMPTY, |acc, b| acc.union(b));
    (!b.is_empty()).then_some(b)
}

/// `camera` moved back along its view direction until the bounding sphere of `bounds` fills its
/// vertical field of view (with a 10% margin), looking at the bounds' centre; the far plane grows
/// to hold the whole sphere.
pub fn framed(camera: &Camera, bounds: Aabb) -> Camera {
    let center = bounds.center();
    let radius = ((bounds.max - bounds.min).length() * 0.5).max(1e-3);
    let forward = (camera.target - camera.position).normalize_or(Vec3::NEG_Z);
    let mut c = *camera;
    let dist = match camera.projection {
        Projection::Perspective { fov_y_deg, .. } => radius / (fov_y_deg.to_radians() * 0.5).sin() * 1.1,
        Projection::Orthographic { .. } => radius * 3.0,
    };
    c.position = center - forward * dist;
    c.target = center;
    match &mut c.projection {
        Projection::Perspective { far, .. } | Projection::Orthographic { far, .. } => *far = far.max(dist + radius * 2.0),
    }
    if let Projection::Orthographic { height, .. } = &mut c.projection {
        *height = radius * 2.2;
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use hybrid_scene::{Attenuation, DirectionalLight, PointLight};

    fn point(intensity: f32) -> PointLight {
        PointLight { position: Vec3::ZERO, color: Vec3::ONE, intensity, attenuation: Attenuation::default(), casts_shadows: true }
    }

    #[test]
    fn switched_lights_keep_order_and_leave_out_the_off_ones() {
        let mut l = Lights::default();
        l.directional.push(DirectionalLight { direction: Vec3::NEG_Y, color: Vec3::ONE, intensity: 1.0, casts_shadows: true });
        l.point.push(point(1.0));
        l.point.push(point(2.0));
        assert_eq!(light_names(&l), ["directional 1", "point 1", "point 2"]);
        let s = lights_switched(&l, &[true, false, true]);
        assert_eq!(s.directional.len(), 1);
        assert_eq!(s.point.len(), 1);
        assert_eq!(s.point[0].intensity, 2.0);
        assert_eq!(lights_switched(&l, &[false, false, false]).count(), 0);
    }

    #[test]
    fn framing_puts_the_bounding_sphere_in_view() {
        let cam = Camera::default();
        let b = Aabb { min: Vec3::new(9.0, -1.0, -1.0), max: Vec3::new(11.0, 1.0, 1.0) };
        let c = framed(&cam, b);
        assert_eq!(c.target, Vec3::new(10.0, 0.0, 0.0));
        // Same direction as before.
        let before = (cam.target - cam.position).normalize();
        let after = (c.target - c.position).normalize();
        assert!(before.dot(after) > 0.9999);
        // Radius √3; fov 60°: distance √3 / sin 30° · 1.1.
        let want = 3f32.sqrt() / 0.5 * 1.1;
        assert!(((c.position - c.target).length() - want).abs() < 1e-4);
    }
}
