//! The heuristic's inputs taken from a scene: what every backend's heuristic stage does between
//! counting pixels (A) and writing the mask, written once.

use hybrid_scene::{Aabb, Budget, Camera, HeuristicSettings, Scene};

use crate::{FrameInput, Heuristic, ObjectInput, Selection};

/// One [`ObjectInput`] per scene object: `areas[i]` is A of object `i` (from
/// [`crate::count_visible_pixels`]), `object_bounds[i]` its world bounds (empty boxes fall back
/// to the object's position as the centre).
pub fn object_inputs(scene: &Scene, object_bounds: &[Aabb], areas: &[u64]) -> Vec<ObjectInput> {
    let materials = &scene.materials;
    scene
        .objects
        .iter()
        .zip(areas)
        .zip(object_bounds)
        .map(|((o, &area), b)| ObjectInput {
            name: o.name.clone(),
            area,
            bbox_center: if b.is_empty() { o.transform.position } else { b.center() },
            reflective: o.is_reflective(materials),
            refractive: o.is_refractive(materials),
            relevance: o.relevance,
            cost: o.cost,
        })
        .collect()
}

/// The per-frame constants of the heuristic for `camera` on a `width × height` image.
pub fn frame_input(scene: &Scene, camera: &Camera, width: u32, height: u32) -> FrameInput {
    FrameInput {
        view_proj: camera.view_projection(width as f32 / height as f32),
        camera_position: camera.position,
        light_count: scene.lights.count(),
    }
}

impl Heuristic {
    /// The paper's "no heuristic" (mode `all`): the same quantities and report as [`Heuristic::run`],
    /// with an unlimited budget, so every visible object is selected. The user's settings are kept.
    pub fn run_unlimited(&mut self, objects: &[ObjectInput], frame: &FrameInput) -> Selection {
        let settings = self.settings().clone();
        self.set_settings(HeuristicSettings { budget: Budget::Unlimited, ..settings.clone() });
        let selection = self.run(objects, frame);
        self.set_settings(settings);
        selection
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hybrid_scene::demo_scene;

    #[test]
    fn inputs_follow_the_scene_objects() {
        let scene = demo_scene();
        let n = scene.objects.len();
        let bounds = vec![Aabb::EMPTY; n];
        let areas: Vec<u64> = (0..n as u64).collect();
        let inputs = object_inputs(&scene, &bounds, &areas);
        assert_eq!(inputs.len(), n);
        for (i, (inp, o)) in inputs.iter().zip(&scene.objects).enumerate() {
            assert_eq!(inp.area, i as u64);
            assert_eq!(inp.name, o.name);
            assert_eq!(inp.bbox_center, o.transform.position, "empty bounds fall back to the position");
        }
        assert!(inputs.iter().any(|i| i.reflective) && inputs.iter().any(|i| i.refractive), "the demo has mirrors and glass");
    }
}
