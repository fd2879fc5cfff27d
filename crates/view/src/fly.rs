//! `fly`: the viewer's camera controller. WASD + Q/E move, a right-button drag looks around,
//! the scroll wheel scales the speed, Shift moves faster. Pure state: the app feeds it key
//! and mouse input (real or scripted) and a time step per frame.

use std::collections::HashSet;

use glam::{Quat, Vec3};
use hybrid_scene::Camera;

/// Keys the controller reacts to while held.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MoveKey {
    Forward,
    Back,
    Left,
    Right,
    Up,
    Down,
    Fast,
}

/// Speed multiplier while Shift is held.
pub const FAST_FACTOR: f32 = 4.0;
/// Speed change per scroll-wheel notch.
pub const SCROLL_FACTOR: f32 = 1.25;
/// Radians of turn per pixel of mouse drag.
pub const LOOK_PER_PIXEL: f32 = 0.004;

pub struct Fly {
    pub camera: Camera,
    /// World units per second.
    pub speed: f32,
    held: HashSet<MoveKey>,
}

impl Fly {
    /// `speed`: world units per second at rest (no Shift, no scroll).
    pub fn new(camera: Camera, speed: f32) -> Self {
        Self { camera, speed, held: HashSet::new() }
    }

    pub fn key(&mut self, key: MoveKey, down: bool) {
        if down {
            self.held.insert(key);
        } else {
            self.held.remove(&key);
        }
    }

    /// True while a movement key is held (the camera will move next step).
    pub fn moving(&self) -> bool {
        self.held.iter().any(|k| *k != MoveKey::Fast)
    }

    pub fn release_all(&mut self) {
        self.held.clear();
    }

    pub fn scroll(&mut self, notches: f32) {
        self.speed = (self.speed * SCROLL_FACTOR.powf(notches)).clamp(1e-4, 1e6);
    }

    fn basis(&self) -> (Vec3, Vec3, Vec3) {
        let forward = (self.camera.target - self.camera.position).normalize_or(Vec3::NEG_Z);
        let right = forward.cross(self.camera.up).normalize_or(Vec3::X);
        let up = right.cross(forward);
        (forward, right, up)
    }

    /// Moves by the held keys over `dt` seconds. Returns whether the camera changed.
    pub fn step(&mut self, dt: f32) -> bool {
        let (forward, right, _) = self.basis();
        let mut dir = Vec3::ZERO;
        for k in &self.held {
            dir += match k {
                MoveKey::Forward => forward,
                MoveKey::Back => -forward,
                MoveKey::Left => -right,
                MoveKey::Right => right,
                MoveKey::Up => self.camera.up.normalize_or(Vec3::Y),
                MoveKey::Down => -self.camera.up.normalize_or(Vec3::Y),
                MoveKey::Fast => Vec3::ZERO,
            };
        }
        if dir == Vec3::ZERO {
            return false;
        }
        let fast = if self.held.contains(&MoveKey::Fast) { FAST_FACTOR } else { 1.0 };
        let delta = dir.normalize() * self.speed * fast * dt;
        self.camera.position += delta;
        self.camera.target += delta;
        true
    }

    /// Turns the view by a mouse drag of `(dx, dy)` pixels (yaw about `up`, pitch about the
    /// right axis, kept short of straight up/down).
    pub fn look(&mut self, dx: f32, dy: f32) {
        let (forward, right, _) = self.basis();
        let up = self.camera.up.normalize_or(Vec3::Y);
        let dist = (self.camera.target - self.camera.position).length().max(1e-3);
        let yaw = Quat::from_axis_angle(up, -dx * LOOK_PER_PIXEL);
        let mut dir = yaw * forward;
        let pitched = Quat::from_axis_angle(yaw * right, -dy * LOOK_PER_PIXEL) * dir;
        if pitched.dot(up).abs() < 0.99 {
            dir = pitched;
        }
        self.camera.target = self.camera.position + dir.normalize() * dist;
    }
}

impl Fly {
    /// Turns the camera around `pivot` by a mouse drag of (`dx`, `dy`) pixels (yaw about the up
    /// axis, pitch about the camera's right axis), keeping its distance to the pivot and looking
    /// at it.
    pub fn orbit(&mut self, pivot: Vec3, dx: f32, dy: f32) {
        let up = self.camera.up.normalize_or(Vec3::Y);
        let offset = self.camera.position - pivot;
        let (_, right, _) = self.basis();
        let yaw = Quat::from_axis_angle(up, -dx * LOOK_PER_PIXEL);
        let mut o = yaw * offset;
        let pitched = Quat::from_axis_angle(yaw * right, -dy * LOOK_PER_PIXEL) * o;
        // Stop short of the poles, where the up vector and the view direction meet.
        if pitched.normalize_or(Vec3::Y).dot(up).abs() < 0.99 {
            o = pitched;
        }
        self.camera.position = pivot + o;
        self.camera.target = pivot;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forward_moves_by_speed_times_time() {
        let mut f = Fly::new(Camera::default(), 2.0);
        let start = f.camera.position;
        let dir = (f.camera.target - start).normalize();
        f.key(MoveKey::Forward, true);
        assert!(f.step(0.5));
        assert!((f.camera.position - (start + dir * 1.0)).length() < 1e-5);
        f.key(MoveKey::Forward, false);
        assert!(!f.step(0.5));
        f.key(MoveKey::Fast, true);
        f.key(MoveKey::Back, true);
        assert!(f.step(0.25));
        assert!((f.camera.position - (start + dir * (1.0 - 2.0))).length() < 1e-5);
    }

    #[test]
    fn look_keeps_distance_and_turns() {
        let mut f = Fly::new(Camera::default(), 1.0);
        let d0 = (f.camera.target - f.camera.position).length();
        let before = f.camera.target;
        f.look(100.0, 0.0);
        assert!(((f.camera.target - f.camera.position).length() - d0).abs() < 1e-4);
        assert!((f.camera.target - before).length() > 0.1);
    }

    #[test]
    fn scroll_scales_speed() {
        let mut f = Fly::new(Camera::default(), 1.0);
        f.scroll(2.0);
        assert!((f.speed - SCROLL_FACTOR * SCROLL_FACTOR).abs() < 1e-5);
    }

    #[test]
    fn orbit_keeps_the_distance_to_the_pivot_and_looks_at_it() {
        let mut f = Fly::new(Camera::default(), 1.0);
        let pivot = Vec3::new(0.5, 0.0, -1.0);
        let d0 = (f.camera.position - pivot).length();
        f.orbit(pivot, 120.0, -40.0);
        assert!(((f.camera.position - pivot).length() - d0).abs() < 1e-4);
        assert_eq!(f.camera.target, pivot);
        // A quarter turn of yaw: 393 px at 0.004 rad/px ≈ π/2, the offset turns about Y.
        let mut g = Fly::new(Camera { position: Vec3::new(0.0, 0.0, 5.0), target: Vec3::ZERO, ..Camera::default() }, 1.0);
        g.orbit(Vec3::ZERO, std::f32::consts::FRAC_PI_2 / LOOK_PER_PIXEL, 0.0);
        assert!((g.camera.position - Vec3::new(-5.0, 0.0, 0.0)).length() < 1e-3, "{}", g.camera.position);
    }
}
