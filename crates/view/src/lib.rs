//! `hybrid-view`: the interactive viewer behind `hybrid view` (issue 17). A winit window with a
//! wgpu surface shows frames from either backend:
//! - GPU: [`GpuRenderer::render_to_targets`] renders into the renderer's own textures (no
//!   read-back) and a blit pass draws the final image into the swapchain image;
//! - CPU: [`CpuRenderer::render`]'s sRGB RGBA8 image is uploaded to a texture and drawn; while the
//!   camera moves, frames render at a reduced resolution chosen to hold `--target-ms`, and the
//!   full-size frame follows when it stops.
//!
//! An egui overlay ([`overlay`]) shows the frame's statistics and heuristic and holds every live
//! knob; keys and overlay controls become [`action::Action`]s applied in one place.
//! `--script FILE` drives the window with events from a file (see [`script`]) for tests and demos.

pub mod action;
pub mod fly;
pub mod open_scene;
pub mod overlay;
pub mod path_record;
pub mod present;
pub mod script;

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use glam::Vec3;
use hybrid_core::buffer_view::{self, BufferKind, FrameView};
use hybrid_core::memory;
use hybrid_core::report::FrameReport;
use hybrid_core::{FrameSettings, Mode, NO_OBJECT, RT_SCENE_OBJECT};
use hybrid_cpu::capsule::PrimaryVisibility;
use hybrid_gpu::{GpuContext, RtChoice};
use hybrid_scene::{
    Aabb, Budget, Camera, CameraPath, HeuristicSettings, Lights, MemoryLimit, Policy, Scene, demo_scene, load_scene_or_model,
};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, ModifiersState, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::action::Action;
use crate::fly::{Fly, MoveKey};
use crate::open_scene::{OpenScene, Renderer, RendererKnobs, frame_bounds, framed, light_names, lights_switched};
use crate::overlay::{HISTORY_FRAMES, Overlay, OverlayModel, Sample};
use crate::path_record::PathRecorder;
use crate::present::{Blit, Upload};
use crate::script::Event;

/// Exit code for bad input (flags, files, no display), as the rest of the CLI.
pub const EXIT_BAD_INPUT: u8 = 2;
/// Exit code for failures that are not the user's input.
pub const EXIT_FAILURE: u8 = 1;

/// Which backend renders the frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendChoice {
    /// A hardware GPU that can present to the window, else the CPU backend.
    Auto,
    Cpu,
    /// Any adapter that can present to the window (lavapipe included).
    Gpu,
}

/// What `hybrid view` was asked to do.
#[derive(Debug, Clone)]
pub struct ViewOptions {
    /// Scene file; the built-in demo scene when `None`.
    pub scene: Option<PathBuf>,
    pub backend: BackendChoice,
    /// Initial window (and frame) size.
    pub size: (u32, u32),
    pub mode: Mode,
    pub budget: Option<Budget>,
    pub policy: Option<Policy>,
    /// CPU backend: frame time to hold while the camera moves (ms).
    pub target_ms: f64,
    pub script: Option<PathBuf>,
    pub clip_capsule: bool,
    pub sphere_effects: bool,
    /// CPU backend: how the capsule finds each primary ray's sphere (`--capsule-visibility`).
    pub primary_visibility: PrimaryVisibility,
    /// GPU backend: hardware or software ray tracing (`--rt`).
    pub rt: RtChoice,
    /// `--fallback`: raster fallbacks for unselected objects, or none (the paper).
    pub fallback: hybrid_core::fallback::Fallback,
}

/// Why the viewer stopped with an error.
#[derive(Debug)]
pub struct ViewError {
    pub code: u8,
    pub message: String,
}

impl ViewError {
    fn bad_input(message: impl Into<String>) -> Self {
        Self { code: EXIT_BAD_INPUT, message: message.into() }
    }
    fn failure(message: impl Into<String>) -> Self {
        Self { code: EXIT_FAILURE, message: message.into() }
    }
}

/// Whether a display server is reachable by the environment's account (X11 or Wayland).
fn display_available() -> bool {
    if cfg!(all(unix, not(target_os = "macos"))) {
        let set = |v: &str| std::env::var_os(v).is_some_and(|s| !s.is_empty());
        set("DISPLAY") || set("WAYLAND_DISPLAY")
    } else {
        true
    }
}

/// Runs the viewer until its window closes (or the script quits).
pub fn run(options: ViewOptions) -> Result<(), ViewError> {
    if !display_available() {
        return Err(ViewError::bad_input(
            "hybrid view needs a display (neither DISPLAY nor WAYLAND_DISPLAY is set); render to a file with `hybrid render` instead, \
             or run under a virtual display (xvfb-run hybrid view ...)",
        ));
    }
    let script = match &options.script {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| ViewError::bad_input(format!("{}: cannot read the script: {e}", path.display())))?;
            Some(script::parse(path, &text).map_err(ViewError::bad_input)?)
        }
        None => None,
    };
    let scene = match &options.scene {
        Some(path) => load_scene_or_model(path).map_err(|e| ViewError::bad_input(e.to_string()))?,
        None => demo_scene(),
    };
    let event_loop = EventLoop::new()
        .map_err(|e| ViewError::bad_input(format!("cannot open a window ({e}); render to a file with `hybrid render` instead")))?;
    let mut app = App::new(scene, options, script);
    event_loop.run_app(&mut app).map_err(|e| ViewError::failure(format!("the window's event loop failed: {e}")))?;
    match app.error.take() {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Everything that exists once the window does.
struct Gfx {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    config: wgpu::SurfaceConfiguration,
    blit: Blit,
    overlay: Overlay,
    /// The GPU backend's context (`None` on the CPU backend), kept to build renderers for newly
    /// opened scenes.
    gpu: Option<Arc<GpuContext>>,
    /// Frames from the host: the CPU backend's image, or a buffer view.
    upload: Option<Upload>,
    /// The uploaded frame's object ids (for the highlight).
    ids_upload: Option<Upload>,
    /// Backend name and adapter, for messages.
    backend_name: String,
    /// The first error the device reported outside an error scope, or its loss: the viewer
    /// stops with it instead of wgpu's default panic.
    device_error: Arc<Mutex<Option<String>>>,
}

/// What the open scene offers besides its renderer, kept for keys and the overlay.
struct SceneInfo {
    /// File it came from (`None`: the built-in demo).
    path: Option<PathBuf>,
    camera: Camera,
    camera_path: Option<CameraPath>,
    bounds: Option<Aabb>,
    has_point_clouds: bool,
    /// Every light of the file; `lights_on` says which are in the rendered scene.
    all_lights: Lights,
    lights_on: Vec<bool>,
    light_names: Vec<String>,
}

impl SceneInfo {
    fn of(scene: &Scene, path: Option<PathBuf>) -> Self {
        Self {
            path,
            camera: scene.camera,
            camera_path: scene.camera_path.clone(),
            bounds: frame_bounds(scene),
            has_point_clouds: !scene.point_clouds.is_empty(),
            all_lights: scene.lights.clone(),
            lights_on: vec![true; scene.lights.count()],
            light_names: light_names(&scene.lights),
        }
    }
}

struct App {
    options: ViewOptions,
    /// The scene loaded before the window opened (moved into `open` once it exists).
    first_scene: Option<Scene>,
    open: Option<OpenScene>,
    info: SceneInfo,
    gfx: Option<Gfx>,
    fly: Fly,
    knobs: RendererKnobs,
    heuristic: HeuristicSettings,
    mode: Mode,
    buffer: BufferKind,
    highlight: Option<u32>,
    /// Per object: K and E set in the object table (`None`: the scene file's).
    weights: Vec<Option<(f32, f32)>>,
    /// `O`: the point the camera orbits.
    orbit: Option<Vec3>,
    /// `P`: the time on the camera path being played.
    playing: Option<f32>,
    recorder: PathRecorder,
    script: Option<std::vec::IntoIter<Event>>,
    /// Frames left to let pass before the script goes on.
    wait_frames: u32,
    /// `wait-ms`: the script goes on at this instant.
    wait_until: Option<Instant>,
    looking: bool,
    /// Where the cursor is in the window (the window's centre until it moves).
    cursor: Option<(f64, f64)>,
    last_drag: Option<(f64, f64)>,
    modifiers: ModifiersState,
    /// The camera or a setting changed since the last full-size frame.
    dirty: bool,
    /// CPU backend: the shown frame is below full size.
    coarse: bool,
    /// CPU backend: fraction of the window size rendered while moving.
    scale: f32,
    last_frame: Instant,
    /// Frames presented, and of them rendered (the CPU backend shows a still frame again).
    frames: u64,
    rendered: u64,
    /// Sum of the rendered frames' times (ms).
    frame_ms_sum: f64,
    /// The last frame's whole time (render, upload, overlay, present; ms) and rendered size.
    last_ms: f64,
    last_size: (u32, u32),
    history: VecDeque<Sample>,
    last_report: Option<FrameReport>,
    message: Option<String>,
    error: Option<ViewError>,
}

/// Fixed time step of scripted runs (seconds per frame), so movement is reproducible.
pub const SCRIPT_DT: f32 = 1.0 / 30.0;
/// Smallest fraction of the window size the CPU backend renders at while moving.
const MIN_SCALE: f32 = 1.0 / 16.0;

/// The scene's heuristic settings with `--budget`/`--budget-ms` and `--policy` over them.
fn heuristic_settings(scene: &Scene, options: &ViewOptions) -> HeuristicSettings {
    let mut h = scene.heuristic.clone();
    if let Some(b) = options.budget {
        h.budget = b;
    }
    if let Some(p) = options.policy {
        h.policy = p;
    }
    h
}

fn fly_speed(camera: &Camera) -> f32 {
    let dist = (camera.target - camera.position).length();
    if dist.is_finite() && dist > 1e-3 { dist * 0.5 } else { 1.0 }
}

impl App {
    fn new(scene: Scene, options: ViewOptions, script: Option<Vec<Event>>) -> Self {
        let heuristic = heuristic_settings(&scene, &options);
        let info = SceneInfo::of(&scene, options.scene.clone());
        Self {
            fly: Fly::new(scene.camera, fly_speed(&scene.camera)),
            knobs: RendererKnobs {
                clip_capsule: options.clip_capsule,
                sphere_effects: options.sphere_effects,
                primary_visibility: options.primary_visibility,
                rt: options.rt,
                fallback: options.fallback,
            },
            heuristic,
            mode: options.mode,
            buffer: BufferKind::Final,
            highlight: None,
            weights: vec![None; scene.objects.len()],
            orbit: None,
            playing: None,
            recorder: PathRecorder::default(),
            first_scene: Some(scene),
            open: None,
            info,
            gfx: None,
            options,
            script: script.map(|s| s.into_iter()),
            wait_frames: 0,
            wait_until: None,
            looking: false,
            cursor: None,
            last_drag: None,
            modifiers: ModifiersState::empty(),
            dirty: true,
            coarse: false,
            scale: 0.5,
            last_frame: Instant::now(),
            frames: 0,
            rendered: 0,
            frame_ms_sum: 0.0,
            last_ms: 0.0,
            last_size: (0, 0),
            history: VecDeque::with_capacity(HISTORY_FRAMES),
            last_report: None,
            message: None,
            error: None,
        }
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: ViewError) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        event_loop.exit();
    }

    /// Tells the user something in the overlay and on stderr.
    fn say(&mut self, msg: String) {
        eprintln!("{msg}");
        self.message = Some(msg);
    }

    fn title(&self) -> String {
        match &self.info.path {
            Some(p) => format!("hybrid view: {}", p.display()),
            None => "hybrid view: demo scene".into(),
        }
    }

    fn create_gfx(&self, event_loop: &ActiveEventLoop) -> Result<Gfx, ViewError> {
        let (w, h) = self.options.size;
        let attrs = Window::default_attributes().with_title(self.title()).with_inner_size(PhysicalSize::new(w, h));
        let window = Arc::new(
            event_loop
                .create_window(attrs)
                .map_err(|e| ViewError::bad_input(format!("cannot open a window ({e}); render to a file with `hybrid render` instead")))?,
        );
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::PRIMARY;
        let instance = wgpu::Instance::new(desc.with_env());
        let surface =
            instance.create_surface(window.clone()).map_err(|e| ViewError::failure(format!("cannot draw into the window: {e}")))?;
        let want_gpu = self.options.backend != BackendChoice::Cpu;
        let ctx = if want_gpu {
            match GpuContext::for_surface(instance.clone(), &surface) {
                Ok(ctx) => Some(Arc::new(ctx)),
                Err(e) if self.options.backend == BackendChoice::Gpu => return Err(ViewError::bad_input(format!("--backend gpu: {e}"))),
                Err(e) => {
                    eprintln!("backend: cpu (auto: {e})");
                    None
                }
            }
        } else {
            None
        };
        // `auto` keeps the GPU backend only on hardware adapters, as `hybrid render` does.
        let ctx = ctx.filter(|c| {
            let hardware = c.summary.device_type != "cpu" && c.summary.device_type != "other";
            if self.options.backend == BackendChoice::Auto && !hardware {
                eprintln!("backend: cpu (auto: no hardware GPU adapter; {} is software)", c.summary.name);
            }
            self.options.backend == BackendChoice::Gpu || hardware
        });
        // `--rt`: `hw` needs the GPU backend on an adapter with ray queries (exit 2 otherwise).
        match &ctx {
            Some(ctx) => {
                let path = self.options.rt.resolve(ctx).map_err(|e| ViewError::bad_input(format!("--rt hw: {e}")))?;
                let how = if path.hardware { "hardware (ray queries)" } else { "software (BVH2 in WGSL)" };
                eprintln!("ray tracing: {how} ({}{})", if self.options.rt == RtChoice::Auto { "auto: " } else { "" }, path.why);
            }
            None if self.options.rt == RtChoice::Hardware => {
                return Err(ViewError::bad_input(
                    "--rt hw: the CPU backend has no hardware ray tracing (use --backend gpu, or --rt auto|sw)",
                ));
            }
            None => {}
        }
        let (device, queue, adapter, backend_name) = match &ctx {
            Some(ctx) => {
                let name = format!("gpu ({}, {})", ctx.summary.name, ctx.summary.backend);
                (ctx.device.clone(), ctx.queue.clone(), ctx.adapter.clone(), name)
            }
            None => {
                let adapter = pollster::block_on(
                    instance.request_adapter(&wgpu::RequestAdapterOptions { compatible_surface: Some(&surface), ..Default::default() }),
                )
                .map_err(|e| ViewError::failure(format!("no graphics adapter can draw into the window: {e}")))?;
                let (device, queue) = pollster::block_on(
                    adapter.request_device(&wgpu::DeviceDescriptor { label: Some("hybrid view"), ..Default::default() }),
                )
                .map_err(|e| ViewError::failure(format!("cannot open a device to draw into the window: {e}")))?;
                (device, queue, adapter, "cpu".to_string())
            }
        };
        // The surface's formats as seen by the device's adapter.
        let adapter_caps = surface.get_capabilities(&adapter);
        let format = adapter_caps
            .formats
            .iter()
            .copied()
            .find(|f| !f.is_srgb())
            .or_else(|| adapter_caps.formats.first().copied())
            .ok_or_else(|| ViewError::failure("the window's surface offers no format"))?;
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::AutoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: adapter_caps.alpha_modes.first().copied().unwrap_or(wgpu::CompositeAlphaMode::Auto),
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        if size.width > 0 && size.height > 0 {
            surface.configure(&device, &config);
        }
        let device_error: Arc<Mutex<Option<String>>> = Arc::default();
        let slot = device_error.clone();
        device.on_uncaptured_error(Arc::new(move |e| {
            if let Ok(mut s) = slot.lock() {
                s.get_or_insert_with(|| e.to_string());
            }
        }));
        let slot = device_error.clone();
        device.set_device_lost_callback(move |reason, msg| {
            if let Ok(mut s) = slot.lock() {
                s.get_or_insert_with(|| format!("the device was lost ({reason:?}): {msg}"));
            }
        });
        let blit = Blit::new(&device, format);
        let overlay = Overlay::new(&window, &device, format);
        eprintln!("backend: {backend_name}");
        Ok(Gfx {
            window,
            surface,
            device,
            queue,
            config,
            blit,
            overlay,
            gpu: ctx,
            upload: None,
            ids_upload: None,
            backend_name,
            device_error,
        })
    }

    /// Builds the renderer for `scene` (on the window's backend) and makes it the open scene,
    /// with the heuristic's settings and per-object K and E given. On failure the scene that was
    /// open stays open, with its settings.
    fn install(&mut self, scene: Scene, heuristic: HeuristicSettings, weights: Vec<Option<(f32, f32)>>) -> Result<(), String> {
        let gpu = self.gfx.as_ref().and_then(|g| g.gpu.as_ref());
        // Refused before anything is built when the frame at the window's size and the scene do
        // not fit the machine's memory limit (as `hybrid render` checks `--max-memory`).
        let size = self.gfx.as_ref().map_or(self.options.size, |g| (g.config.width.max(1), g.config.height.max(1)));
        let kind = if gpu.is_some() { memory::Backend::Gpu } else { memory::Backend::Cpu };
        memory::estimate(&scene, kind, size.0, size.1, 0).check(&MemoryLimit::machine_default())?;
        let open = OpenScene::open(scene, gpu, self.knobs)?;
        self.open = Some(open);
        self.heuristic = heuristic;
        self.weights = weights;
        self.reapply();
        Ok(())
    }

    /// `open PATH` / a dropped file: the new scene replaces the open one only if it loads and its
    /// renderer builds; otherwise the error is shown and the old scene stays.
    fn open_file(&mut self, path: PathBuf) {
        let scene = match load_scene_or_model(&path) {
            Ok(s) => s,
            Err(e) => return self.say(format!("cannot open {}: {e}", path.display())),
        };
        let info = SceneInfo::of(&scene, Some(path.clone()));
        let heuristic = heuristic_settings(&scene, &self.options);
        let weights = vec![None; scene.objects.len()];
        let camera = scene.camera;
        if let Err(e) = self.install(scene, heuristic, weights) {
            return self.say(format!("cannot open {}: {e}", path.display()));
        }
        self.info = info;
        self.fly = Fly::new(camera, fly_speed(&camera));
        self.highlight = None;
        self.orbit = None;
        self.playing = None;
        self.recorder = PathRecorder::default();
        self.history.clear();
        self.last_report = None;
        if let Some(g) = &self.gfx {
            g.window.set_title(&self.title());
        }
        self.say(format!("opened {}", path.display()));
    }

    /// The live settings (heuristic, per-object K and E) on a newly built renderer.
    fn reapply(&mut self) {
        let settings = self.heuristic.clone();
        let weights = self.weights.clone();
        if let Some(open) = self.open.as_mut() {
            open.with_dependent_mut(|_, r| {
                r.heuristic_mut().set_settings(settings);
                for (id, w) in weights.into_iter().enumerate() {
                    if w.is_some() {
                        r.set_object_weights(id, w);
                    }
                }
            });
        }
        self.dirty = true;
    }

    /// The open scene rebuilt with the lights that are on.
    fn relight(&mut self) -> Result<(), String> {
        let Some(open) = self.open.take() else { return Ok(()) };
        let mut scene = open.into_owner();
        scene.lights = lights_switched(&self.info.all_lights, &self.info.lights_on);
        self.install(scene, self.heuristic.clone(), self.weights.clone())
    }

    /// Applies what a key, the overlay or the script asked for.
    fn apply(&mut self, event_loop: &ActiveEventLoop, action: Action) {
        self.dirty = true;
        match action {
            Action::SetMode(m) => self.mode = m,
            Action::SetBuffer(b) => self.buffer = b,
            Action::SetBudget(b) => self.set_heuristic(|h| h.budget = b),
            Action::SetPolicy(p) => self.set_heuristic(|h| h.policy = p),
            Action::SetImportance(i) => self.set_heuristic(|h| h.importance = i.max(0.0)),
            Action::Highlight(id) => self.highlight = id,
            Action::SetObjectWeights(id, k, e) => {
                if id >= self.weights.len() {
                    return self.say(format!("object {id} does not exist: the scene has {} objects", self.weights.len()));
                }
                self.weights[id] = Some((k.max(0.0), e.max(0.0)));
                let w = self.weights[id];
                if let Some(open) = self.open.as_mut() {
                    open.with_dependent_mut(|_, r| r.set_object_weights(id, w));
                }
            }
            Action::SetClipCapsule(v) => self.set_knobs(|k| k.clip_capsule = v),
            Action::SetSphereEffects(v) => self.set_knobs(|k| k.sphere_effects = v),
            Action::SetFallback(v) => self.set_knobs(|k| k.fallback = v),
            Action::SetPrimaryVisibility(v) => self.set_knobs(|k| k.primary_visibility = v),
            Action::SetLight(i, on) => {
                if i >= self.info.lights_on.len() {
                    return self.say(format!("light {} does not exist: the scene has {} lights", i + 1, self.info.lights_on.len()));
                }
                self.info.lights_on[i] = on;
                if let Err(e) = self.relight() {
                    self.fail(
                        event_loop,
                        ViewError::failure(format!("cannot rebuild the scene with light {} {}: {e}", i + 1, if on { "on" } else { "off" })),
                    );
                }
            }
            Action::FrameBounds => match self.info.bounds {
                Some(b) => {
                    self.fly.camera = framed(&self.fly.camera, b);
                    self.fly.speed = fly_speed(&self.fly.camera);
                    self.orbit = None;
                }
                None => self.say("the scene is empty: nothing to frame".into()),
            },
            Action::Home => {
                self.fly.camera = self.info.camera;
                self.orbit = None;
                self.playing = None;
            }
            Action::ToggleOrbit => {
                self.orbit = match self.orbit {
                    Some(_) => None,
                    None => {
                        let pivot = self.point_under_cursor().unwrap_or(self.fly.camera.target);
                        Some(pivot)
                    }
                };
                if let Some(p) = self.orbit {
                    self.fly.camera.target = p;
                    println!("orbit: around {} {} {}", p.x, p.y, p.z);
                }
            }
            Action::PlayPath => {
                if self.playing.is_some() {
                    self.playing = None;
                } else if let Some(start) = self.path_to_play().map(|p| p.keyframes[0].time) {
                    self.playing = Some(start);
                    self.orbit = None;
                } else {
                    self.say("no camera path to play: the scene has no [camera_path]; record one with K".into());
                }
            }
            Action::AddKeyframe => {
                let k = *self.recorder.add(&self.fly.camera, self.fly.speed);
                self.say(format!("keyframe {} at {:.2} s", self.recorder.keyframes.len(), k.time));
            }
            Action::SavePath => match self.recorder.save_beside(self.info.path.as_deref()) {
                Ok(p) => self.say(format!("camera path: {} keyframes written to {}", self.recorder.keyframes.len(), p.display())),
                Err(e) => self.say(format!("camera path not saved: {e}")),
            },
            Action::Screenshot(path) => {
                let path = path.unwrap_or_else(next_screenshot_path);
                if let Err(e) = self.screenshot(&path) {
                    self.fail(event_loop, e);
                }
            }
            Action::ToggleOverlay => {
                if let Some(g) = self.gfx.as_mut() {
                    g.overlay.visible = !g.overlay.visible;
                }
            }
            Action::Open(path) => self.open_file(path),
        }
    }

    fn set_heuristic(&mut self, f: impl FnOnce(&mut HeuristicSettings)) {
        f(&mut self.heuristic);
        let settings = self.heuristic.clone();
        if let Some(open) = self.open.as_mut() {
            open.with_dependent_mut(|_, r| r.heuristic_mut().set_settings(settings));
        }
    }

    fn set_knobs(&mut self, f: impl FnOnce(&mut RendererKnobs)) {
        f(&mut self.knobs);
        let knobs = self.knobs;
        if let Some(open) = self.open.as_mut() {
            open.with_dependent_mut(|_, r| r.apply(knobs));
        }
    }

    /// The scene's camera path, or the one recorded with `K` when the scene has none.
    fn path_to_play(&self) -> Option<CameraPath> {
        self.info
            .camera_path
            .clone()
            .or_else(|| (self.recorder.keyframes.len() >= 2).then(|| CameraPath { keyframes: self.recorder.keyframes.clone() }))
    }

    /// The world position of the surface under the cursor (window centre when the cursor has not
    /// moved), from a frame rendered for it; `None` over the sky.
    fn point_under_cursor(&mut self) -> Option<Vec3> {
        let g = self.gfx.as_ref()?;
        let (w, h) = (g.config.width.max(1), g.config.height.max(1));
        let (cx, cy) = self.cursor.unwrap_or((w as f64 * 0.5, h as f64 * 0.5));
        let settings = FrameSettings { width: w, height: h, mode: self.mode };
        let camera = self.fly.camera;
        let open = self.open.as_mut()?;
        open.with_dependent_mut(|_, r| {
            let frame = r.render(&camera, settings).ok()?;
            let (x, y) = ((cx.max(0.0) as u32).min(w - 1), (cy.max(0.0) as u32).min(h - 1));
            let i = (y * w + x) as usize;
            let id = frame.gbuffer.object_id[i];
            let p = (id != NO_OBJECT).then_some(frame.gbuffer.position[i]);
            r.recycle(frame);
            p
        })
    }

    /// Key input from the window or the script. `name` is one of [`script::KEYS`].
    fn key(&mut self, event_loop: &ActiveEventLoop, name: &str, down: bool) {
        let mv = match name {
            "w" => Some(MoveKey::Forward),
            "s" => Some(MoveKey::Back),
            "a" => Some(MoveKey::Left),
            "d" => Some(MoveKey::Right),
            "e" => Some(MoveKey::Up),
            "q" => Some(MoveKey::Down),
            "shift" => Some(MoveKey::Fast),
            _ => None,
        };
        if let Some(k) = mv {
            if k != MoveKey::Fast && down {
                // Flying takes the camera back from the path and the orbit.
                self.playing = None;
                self.orbit = None;
            }
            self.fly.key(k, down);
            return;
        }
        if !down {
            return;
        }
        let action = match name {
            "r" => Action::Home,
            "f" => Action::FrameBounds,
            "o" => Action::ToggleOrbit,
            "p" => Action::PlayPath,
            "k" => Action::AddKeyframe,
            "ctrl+s" => Action::SavePath,
            "tab" => Action::ToggleOverlay,
            "f12" => Action::Screenshot(None),
            _ => return,
        };
        self.apply(event_loop, action);
    }

    /// A right-button drag: look around, or orbit the pivot in orbit mode.
    fn drag(&mut self, dx: f32, dy: f32) {
        match self.orbit {
            Some(p) => self.fly.orbit(p, dx, dy),
            None => self.fly.look(dx, dy),
        }
        self.playing = None;
        self.dirty = true;
    }

    /// Renders the current camera at the full window size (read back, no overlay) and writes it
    /// as PNG, with the frame's report as JSON beside it (same name, `.json`).
    fn screenshot(&mut self, path: &Path) -> Result<(), ViewError> {
        let Some(g) = self.gfx.as_ref() else { return Ok(()) };
        let (w, h) = (g.config.width, g.config.height);
        let settings = FrameSettings { width: w, height: h, mode: self.mode };
        let camera = self.fly.camera;
        let Some(open) = self.open.as_mut() else { return Ok(()) };
        let (pixels, report) = open.with_dependent_mut(|_, r| -> Result<_, ViewError> {
            let frame = r.render(&camera, settings).map_err(ViewError::failure)?;
            let out = (frame.buffers.final_srgb.as_flattened().to_vec(), frame.report.clone());
            r.recycle(frame);
            Ok(out)
        })?;
        let report_path = path.with_extension("json");
        let json = serde_json::to_vec_pretty(&report).map_err(|e| ViewError::failure(e.to_string()))?;
        image::save_buffer_with_format(path, &pixels, w, h, image::ExtendedColorType::Rgba8, image::ImageFormat::Png)
            .map_err(|e| ViewError::failure(format!("{}: cannot write the screenshot: {e}", path.display())))?;
        std::fs::write(&report_path, json)
            .map_err(|e| ViewError::failure(format!("{}: cannot write the report: {e}", report_path.display())))?;
        self.say(format!("screenshot: {} ({w}x{h}), report {}", path.display(), report_path.display()));
        Ok(())
    }

    /// Runs script events until one asks for frames to pass. Returns false when it quit.
    fn run_script(&mut self, event_loop: &ActiveEventLoop) -> bool {
        // `wait N` counts presented frames (decremented after `present`): a tick whose surface
        // texture was outdated (as after a resize) shows nothing and does not count.
        if self.wait_frames > 0 {
            return true;
        }
        if let Some(t) = self.wait_until {
            if Instant::now() < t {
                return true;
            }
            self.wait_until = None;
        }
        while let Some(ev) = self.script.as_mut().and_then(|s| s.next()) {
            match ev {
                Event::KeyDown(k) => self.key(event_loop, &k, true),
                Event::KeyUp(k) => self.key(event_loop, &k, false),
                Event::Press(k) => {
                    self.key(event_loop, &k, true);
                    self.key(event_loop, &k, false);
                }
                Event::MouseMove(x, y) => self.cursor = Some((x as f64, y as f64)),
                Event::MouseDrag(dx, dy) => self.drag(dx, dy),
                Event::Scroll(n) => self.fly.scroll(n),
                Event::Wait(n) => {
                    if n > 0 {
                        self.wait_frames = n;
                        return true;
                    }
                }
                Event::WaitMs(ms) => {
                    self.wait_until = Some(Instant::now() + std::time::Duration::from_millis(ms as u64));
                    return true;
                }
                Event::Resize(w, h) => {
                    if let Some(g) = &self.gfx {
                        let _ = g.window.request_inner_size(PhysicalSize::new(w, h));
                    }
                }
                Event::Screenshot(path) => self.apply(event_loop, Action::Screenshot(Some(path))),
                Event::Do(action) => self.apply(event_loop, action),
                Event::PrintCamera => {
                    let c = &self.fly.camera;
                    println!(
                        "camera: position {} {} {} target {} {} {}",
                        c.position.x, c.position.y, c.position.z, c.target.x, c.target.y, c.target.z
                    );
                }
                Event::PrintFrame => {
                    let s = self.gfx.as_ref().map_or("none".to_string(), |g| g.backend_name.clone());
                    println!(
                        "frame: backend {s} scale {:.3} frames {} rendered {} mean frame {:.2} ms last frame {:.2} ms at {}x{}",
                        self.scale,
                        self.frames,
                        self.rendered,
                        self.frame_ms_sum / self.rendered.max(1) as f64,
                        self.last_ms,
                        self.last_size.0,
                        self.last_size.1
                    );
                }
                Event::PrintSelection => {
                    let h = self.last_report.as_ref().and_then(|r| r.heuristic.as_ref());
                    match h {
                        Some(h) => {
                            let ids: Vec<String> = h.objects.iter().filter(|o| o.selected).map(|o| o.id.to_string()).collect();
                            println!(
                                "selection: budget {} spent {} selected [{}]",
                                h.budget.map_or("unlimited".to_string(), |b| b.to_string()),
                                h.spent,
                                ids.join(",")
                            );
                        }
                        None => println!("selection: none"),
                    }
                }
                Event::PrintMemory => {
                    println!("memory: VmRSS {} kB frame {}", script::resident_kb().unwrap_or(0), self.frames);
                }
                Event::Quit => {
                    self.quit(event_loop);
                    return false;
                }
            }
            if self.error.is_some() {
                return false;
            }
        }
        if self.script.as_ref().is_some_and(|s| s.len() == 0) {
            // The script ran out without `quit`: stay open, driven by the window from here.
            self.script = None;
        }
        true
    }

    fn quit(&mut self, event_loop: &ActiveEventLoop) {
        if self.rendered > 0 {
            println!("frames: {} rendered {} mean frame {:.2} ms", self.frames, self.rendered, self.frame_ms_sum / self.rendered as f64);
        }
        event_loop.exit();
    }

    /// Moves the camera along the path being played.
    fn play(&mut self, dt: f32) {
        let Some(t) = self.playing else { return };
        let Some(path) = self.path_to_play() else {
            self.playing = None;
            return;
        };
        let (position, target) = path.sample(t);
        self.fly.camera.position = position;
        self.fly.camera.target = target;
        self.dirty = true;
        let end = path.keyframes.last().map_or(t, |k| k.time);
        self.playing = (t < end).then_some(t + dt);
    }

    /// One frame: input → camera → render → present (frame, then overlay).
    fn redraw(&mut self, event_loop: &ActiveEventLoop) {
        let scripted = self.script.is_some();
        let now = Instant::now();
        let dt = if scripted { SCRIPT_DT } else { (now - self.last_frame).as_secs_f32().min(0.25) };
        self.last_frame = now;
        if scripted && !self.run_script(event_loop) {
            return;
        }
        self.play(dt);
        if self.fly.step(dt) {
            self.dirty = true;
        }
        let Some(g) = self.gfx.as_mut() else { return };
        let Some(open) = self.open.as_mut() else { return };
        let (w, h) = (g.config.width, g.config.height);
        if w == 0 || h == 0 || g.window.is_minimized() == Some(true) {
            return;
        }
        let moving = self.fly.moving() || self.looking || self.playing.is_some();
        let frame_start = Instant::now();
        let is_cpu = g.gpu.is_none();
        let need = !is_cpu || self.dirty || self.coarse || g.upload.is_none();
        let request = FrameRequest {
            camera: self.fly.camera,
            mode: self.mode,
            buffer: self.buffer,
            highlight: self.highlight,
            size: if is_cpu && moving { scaled((w, h), self.scale) } else { (w, h) },
        };
        let shown = if need {
            match open.with_dependent_mut(|_, r| render_frame(r, g, &request)) {
                Ok(s) => {
                    self.last_size = request.size;
                    self.coarse = request.size != (w, h);
                    self.dirty = false;
                    Some(s)
                }
                Err(e) => {
                    self.error.get_or_insert(ViewError::failure(format!("frame failed: {e}")));
                    event_loop.exit();
                    return;
                }
            }
        } else {
            None
        };
        let (src, ids, report) = match shown {
            Some(Shown { src, ids, report }) => (src, ids, Some(report)),
            // The CPU frame did not change: show the uploaded one again (overlay updates).
            None => match &g.upload {
                Some(u) => (u.view.clone(), self.highlight.and(g.ids_upload.as_ref().map(|u| u.view.clone())), None),
                None => return,
            },
        };
        let fps = if self.last_ms > 0.0 { 1000.0 / self.last_ms } else { 0.0 };
        let lights: Vec<(String, bool)> = self.info.light_names.iter().cloned().zip(self.info.lights_on.iter().copied()).collect();
        if let Some(r) = report {
            self.last_report = Some(r);
        }
        let model = OverlayModel {
            backend: &g.backend_name,
            mode: self.mode,
            frame_size: self.last_size,
            fps,
            history: &self.history,
            gpu_stage_times: self.last_report.as_ref().is_some_and(|r| r.gpu_timings_ms.is_some()),
            report: self.last_report.as_ref(),
            budget: self.heuristic.budget,
            policy: self.heuristic.policy,
            importance: self.heuristic.importance,
            buffer: self.buffer,
            has_point_clouds: self.info.has_point_clouds,
            highlight: self.highlight,
            clip_capsule: self.knobs.clip_capsule,
            sphere_effects: self.knobs.sphere_effects,
            fallback: self.knobs.fallback,
            primary_visibility: is_cpu.then_some(self.knobs.primary_visibility),
            lights: &lights,
            keyframes: self.recorder.keyframes.len(),
            playing: self.playing.is_some(),
            orbit: self.orbit.is_some(),
            message: self.message.as_deref(),
        };
        let actions = g.overlay.build(&g.window, &model);
        let surface_texture = match g.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                g.surface.configure(&g.device, &g.config);
                g.window.request_redraw();
                return;
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                g.window.request_redraw();
                return;
            }
            other => {
                self.error.get_or_insert(ViewError::failure(format!("the window's surface failed: {other:?}")));
                event_loop.exit();
                return;
            }
        };
        let target = surface_texture.texture.create_view(&wgpu::TextureViewDescriptor::default());
        let mut enc = g.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("view.present") });
        let highlight = match (self.highlight, &ids) {
            (Some(id), Some(view)) => Some((view, id)),
            _ => None,
        };
        g.blit.encode(&g.device, &g.queue, &mut enc, &src, highlight, (&target, (w, h)));
        g.overlay.paint(&g.device, &g.queue, &mut enc, &target, (w, h));
        g.queue.submit([enc.finish()]);
        g.queue.present(surface_texture);
        // Lets wgpu run its callbacks (device lost) and free what finished frames used.
        let _ = g.device.poll(wgpu::PollType::Poll);
        let device_error = g.device_error.lock().ok().and_then(|mut e| e.take());
        if let Some(e) = device_error {
            self.fail(event_loop, ViewError::failure(format!("the graphics device failed: {e}")));
            return;
        }
        let frame_ms = frame_start.elapsed().as_secs_f64() * 1e3;
        self.frames += 1;
        self.wait_frames = self.wait_frames.saturating_sub(1);
        if need {
            self.rendered += 1;
            self.last_ms = frame_ms;
            self.frame_ms_sum += frame_ms;
            if let Some(r) = &self.last_report {
                if self.history.len() == HISTORY_FRAMES {
                    self.history.pop_front();
                }
                self.history.push_back(Sample { frame_ms, stages: r.gpu_timings_ms.unwrap_or(r.timings_ms) });
            }
            // CPU backend, moving: scale the next frame's pixel count by how far this whole frame
            // (render, upload, overlay, present) was from the target time.
            if is_cpu && moving {
                let ratio = (self.options.target_ms / frame_ms.max(0.1)).sqrt().clamp(0.5, 2.0) as f32;
                self.scale = (self.scale * ratio).clamp(MIN_SCALE, 1.0);
            }
        }
        let cpu_refining = is_cpu && (self.coarse || self.dirty);
        let acted = !actions.is_empty();
        for a in actions {
            self.apply(event_loop, a);
        }
        if let Some(g) = &self.gfx
            && (scripted || moving || cpu_refining || acted)
        {
            g.window.request_redraw();
        }
    }
}

/// What one frame shows.
struct FrameRequest {
    camera: Camera,
    mode: Mode,
    buffer: BufferKind,
    highlight: Option<u32>,
    /// Rendered size (the window's, or less on the CPU backend while moving).
    size: (u32, u32),
}

/// A rendered frame, ready to draw: its image and object ids on the GPU, and its report.
struct Shown {
    src: wgpu::TextureView,
    ids: Option<wgpu::TextureView>,
    report: FrameReport,
}

fn scaled((w, h): (u32, u32), s: f32) -> (u32, u32) {
    (((w as f32 * s).round() as u32).max(1), ((h as f32 * s).round() as u32).max(1))
}

/// Renders `req` with `r`. The GPU backend's final image stays on the GPU (no read-back); any
/// other buffer, and every CPU frame, is made an image on the host and uploaded.
fn render_frame(r: &mut Renderer, g: &mut Gfx, req: &FrameRequest) -> Result<Shown, String> {
    let settings = FrameSettings { width: req.size.0, height: req.size.1, mode: req.mode };
    if req.buffer == BufferKind::Final
        && let Renderer::Gpu(gpu) = r
    {
        let report = gpu.render_to_targets(&req.camera, settings, &mut |_| {}).map_err(|e| e.to_string())?;
        let t = gpu.targets().ok_or("the GPU frame has no targets")?;
        let ids = req.highlight.map(|_| t.object_id.view.clone());
        return Ok(Shown { src: t.final_image.view.clone(), ids, report });
    }
    let frame = r.render(&req.camera, settings)?;
    let view = FrameView { gbuffer: &frame.gbuffer, buffers: &frame.buffers, rt_packed: frame.rt_packed.as_ref() };
    let image = buffer_view::view(req.buffer, &view).or_else(|| buffer_view::view(BufferKind::Final, &view)).ok_or("no final image")?;
    let src = Upload::refresh(
        &mut g.upload,
        &g.device,
        &g.queue,
        (image.width, image.height),
        wgpu::TextureFormat::Rgba8Unorm,
        image.pixels.as_flattened(),
    )
    .view
    .clone();
    let ids = match req.highlight {
        Some(_) => {
            let bytes: Vec<u8> =
                frame.gbuffer.object_id.iter().flat_map(|&id| if id == RT_SCENE_OBJECT { NO_OBJECT } else { id }.to_le_bytes()).collect();
            let size = (frame.gbuffer.width, frame.gbuffer.height);
            Some(Upload::refresh(&mut g.ids_upload, &g.device, &g.queue, size, wgpu::TextureFormat::R32Uint, &bytes).view.clone())
        }
        None => None,
    };
    let report = frame.report.clone();
    r.recycle(frame);
    Ok(Shown { src, ids, report })
}

/// `hybrid-screenshot-N.png` in the current folder, the first N not taken.
fn next_screenshot_path() -> PathBuf {
    (1..).map(|n| PathBuf::from(format!("hybrid-screenshot-{n}.png"))).find(|p| !p.exists()).expect("some screenshot number is free")
}

fn key_name(code: KeyCode, ctrl: bool) -> Option<&'static str> {
    Some(match code {
        KeyCode::KeyS if ctrl => "ctrl+s",
        KeyCode::KeyW => "w",
        KeyCode::KeyA => "a",
        KeyCode::KeyS => "s",
        KeyCode::KeyD => "d",
        KeyCode::KeyQ => "q",
        KeyCode::KeyE => "e",
        KeyCode::KeyR => "r",
        KeyCode::KeyF => "f",
        KeyCode::KeyO => "o",
        KeyCode::KeyP => "p",
        KeyCode::KeyK => "k",
        KeyCode::ShiftLeft | KeyCode::ShiftRight => "shift",
        KeyCode::Tab => "tab",
        KeyCode::F12 => "f12",
        _ => return None,
    })
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.gfx.is_some() {
            return;
        }
        match self.create_gfx(event_loop) {
            Ok(g) => {
                g.window.request_redraw();
                self.gfx = Some(g);
            }
            Err(e) => return self.fail(event_loop, e),
        }
        if let Some(scene) = self.first_scene.take() {
            let file = self.info.path.as_ref().map_or("demo scene".to_string(), |p| p.display().to_string());
            if let Err(e) = self.install(scene, self.heuristic.clone(), self.weights.clone()) {
                self.fail(event_loop, ViewError::bad_input(format!("{file}: {e}")));
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        if let Some(g) = self.gfx.as_mut()
            && !matches!(event, WindowEvent::RedrawRequested)
        {
            let consumed = g.overlay.on_window_event(&g.window, &event);
            g.window.request_redraw();
            // Keys typed into a slider, clicks on a panel: the overlay's, not the camera's. Key
            // releases always reach the camera, so no key stays held.
            let release = matches!(&event, WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Released);
            if consumed && !release {
                return;
            }
        }
        match event {
            WindowEvent::CloseRequested => self.quit(event_loop),
            WindowEvent::Resized(size) => {
                if let Some(g) = self.gfx.as_mut() {
                    g.config.width = size.width;
                    g.config.height = size.height;
                    if size.width > 0 && size.height > 0 {
                        g.surface.configure(&g.device, &g.config);
                        self.dirty = true;
                    }
                }
            }
            WindowEvent::ModifiersChanged(m) => self.modifiers = m.state(),
            WindowEvent::KeyboardInput { event, .. } => {
                if event.repeat {
                    return;
                }
                if let PhysicalKey::Code(code) = event.physical_key
                    && let Some(name) = key_name(code, self.modifiers.control_key())
                {
                    self.key(event_loop, name, event.state == ElementState::Pressed);
                }
            }
            WindowEvent::DroppedFile(path) => self.apply(event_loop, Action::Open(path)),
            WindowEvent::MouseInput { state, button: MouseButton::Right, .. } => {
                let over_overlay = self.gfx.as_ref().is_some_and(|g| g.overlay.wants_pointer());
                self.looking = state == ElementState::Pressed && !over_overlay;
                self.last_drag = None;
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = Some((position.x, position.y));
                if self.looking {
                    if let Some((x, y)) = self.last_drag {
                        self.drag((position.x - x) as f32, (position.y - y) as f32);
                    }
                    self.last_drag = Some((position.x, position.y));
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let notches = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => (p.y / 40.0) as f32,
                };
                self.fly.scroll(notches);
            }
            WindowEvent::Focused(false) => self.fly.release_all(),
            WindowEvent::RedrawRequested => self.redraw(event_loop),
            _ => {}
        }
    }
}
