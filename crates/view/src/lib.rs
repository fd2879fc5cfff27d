//! `hybrid-view`: the interactive viewer behind `hybrid view` (issue 17). A winit window with a
//! wgpu surface shows frames from either backend:
//! - GPU: [`GpuRenderer::render_to_targets`] renders into the renderer's own textures (no
//!   read-back) and a blit pass draws the final image into the swapchain image;
//! - CPU: [`CpuRenderer::render`]'s sRGB RGBA8 image is uploaded to a texture and drawn; while the
//!   camera moves, frames render at a reduced resolution chosen to hold `--target-ms`, and the
//!   full-size frame follows when it stops.
//!
//! `--script FILE` drives the window with events from a file (see [`script`]) for tests and demos.

pub mod fly;
pub mod present;
pub mod script;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use hybrid_core::{Frame, FrameSettings, Mode};
use hybrid_cpu::frame::CpuRenderer;
use hybrid_gpu::GpuContext;
use hybrid_gpu::frame::GpuRenderer;
use hybrid_scene::{Budget, Policy, Scene, demo_scene, load_scene_or_model};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::fly::{Fly, MoveKey};
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
    let mut scene = match &options.scene {
        Some(path) => load_scene_or_model(path).map_err(|e| ViewError::bad_input(e.to_string()))?,
        None => demo_scene(),
    };
    if let Some(b) = options.budget {
        scene.heuristic.budget = b;
    }
    if let Some(p) = options.policy {
        scene.heuristic.policy = p;
    }
    let event_loop = EventLoop::new()
        .map_err(|e| ViewError::bad_input(format!("cannot open a window ({e}); render to a file with `hybrid render` instead")))?;
    let mut app = App::new(&scene, options, script);
    event_loop.run_app(&mut app).map_err(|e| ViewError::failure(format!("the window's event loop failed: {e}")))?;
    match app.error.take() {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// A renderer on the backend in use, borrowing the open scene.
enum Renderer<'s> {
    Cpu(Box<CpuRenderer<'s>>),
    Gpu(Box<GpuRenderer<'s>>),
}

/// Everything that exists once the window does.
struct State<'s> {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    config: wgpu::SurfaceConfiguration,
    blit: Blit,
    renderer: Renderer<'s>,
    /// CPU backend: the uploaded frame.
    upload: Option<Upload>,
    /// Backend name and adapter, for messages.
    backend_name: String,
}

struct App<'s> {
    scene: &'s Scene,
    options: ViewOptions,
    state: Option<State<'s>>,
    fly: Fly,
    script: Option<std::vec::IntoIter<Event>>,
    /// Frames left to let pass before the script goes on.
    wait_frames: u32,
    looking: bool,
    last_cursor: Option<(f64, f64)>,
    /// The camera changed since the last full-size frame.
    dirty: bool,
    /// CPU backend: the shown frame is below full size.
    coarse: bool,
    /// CPU backend: fraction of the window size rendered while moving.
    scale: f32,
    last_frame: Instant,
    frames: u64,
    frame_ms_sum: f64,
    /// The last frame's render + present time (ms) and rendered size.
    last_ms: f64,
    last_size: (u32, u32),
    screenshots: u32,
    error: Option<ViewError>,
}

/// Fixed time step of scripted runs (seconds per frame), so movement is reproducible.
pub const SCRIPT_DT: f32 = 1.0 / 30.0;
/// Smallest fraction of the window size the CPU backend renders at while moving.
const MIN_SCALE: f32 = 1.0 / 16.0;

impl<'s> App<'s> {
    fn new(scene: &'s Scene, options: ViewOptions, script: Option<Vec<Event>>) -> Self {
        let dist = (scene.camera.target - scene.camera.position).length();
        let speed = if dist.is_finite() && dist > 1e-3 { dist * 0.5 } else { 1.0 };
        Self {
            scene,
            fly: Fly::new(scene.camera, speed),
            options,
            state: None,
            script: script.map(|s| s.into_iter()),
            wait_frames: 0,
            looking: false,
            last_cursor: None,
            dirty: true,
            coarse: false,
            scale: 0.5,
            last_frame: Instant::now(),
            frames: 0,
            frame_ms_sum: 0.0,
            last_ms: 0.0,
            last_size: (0, 0),
            screenshots: 0,
            error: None,
        }
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: ViewError) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        event_loop.exit();
    }

    fn create_state(&self, event_loop: &ActiveEventLoop) -> Result<State<'s>, ViewError> {
        let (w, h) = self.options.size;
        let title = match &self.options.scene {
            Some(p) => format!("hybrid view: {}", p.display()),
            None => "hybrid view: demo scene".into(),
        };
        let attrs = Window::default_attributes().with_title(title).with_inner_size(PhysicalSize::new(w, h));
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
        let file = self.options.scene.as_ref().map_or("demo scene".to_string(), |p| p.display().to_string());
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
        let (device, queue, adapter, renderer, backend_name) = match ctx {
            Some(ctx) => {
                let mut r = GpuRenderer::new(ctx.clone(), self.scene).map_err(|e| ViewError::bad_input(format!("{file}: {e}")))?;
                r.clip_capsule_at_raster_depth = self.options.clip_capsule;
                r.spheres_in_trace = self.options.sphere_effects;
                let name = format!("gpu ({}, {})", ctx.summary.name, ctx.summary.backend);
                (ctx.device.clone(), ctx.queue.clone(), ctx.adapter.clone(), Renderer::Gpu(Box::new(r)), name)
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
                let mut r = CpuRenderer::new(self.scene).map_err(|e| ViewError::bad_input(format!("{file}: {e}")))?;
                r.clip_capsule_at_raster_depth = self.options.clip_capsule;
                r.spheres_in_trace = self.options.sphere_effects;
                (device, queue, adapter, Renderer::Cpu(Box::new(r)), "cpu".to_string())
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
        let blit = Blit::new(&device, format);
        eprintln!("backend: {backend_name}");
        Ok(State { window, surface, device, queue, config, blit, renderer, upload: None, backend_name })
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
            self.fly.key(k, down);
            return;
        }
        if !down {
            return;
        }
        match name {
            "r" => {
                self.fly.camera = self.scene.camera;
                self.dirty = true;
            }
            "f12" => {
                self.screenshots += 1;
                let path = PathBuf::from(format!("hybrid-screenshot-{}.png", self.screenshots));
                if let Err(e) = self.screenshot(&path) {
                    self.fail(event_loop, e);
                }
            }
            _ => {}
        }
    }

    /// Renders the current camera at the full window size (read back, no overlay) and writes it
    /// as PNG, with the frame's report as JSON beside it (same name, `.json`).
    fn screenshot(&mut self, path: &Path) -> Result<(), ViewError> {
        let Some(state) = self.state.as_mut() else { return Ok(()) };
        let (w, h) = (state.config.width, state.config.height);
        let settings = FrameSettings { width: w, height: h, mode: self.options.mode };
        let frame: Frame = match &mut state.renderer {
            Renderer::Cpu(r) => r.render(&self.fly.camera, settings, &mut |_| {}),
            Renderer::Gpu(r) => r.render(&self.fly.camera, settings, &mut |_| {}).map_err(|e| ViewError::failure(e.to_string()))?,
        };
        let report_path = path.with_extension("json");
        let json = serde_json::to_vec_pretty(&frame.report).map_err(|e| ViewError::failure(e.to_string()))?;
        image::save_buffer_with_format(
            path,
            frame.buffers.final_srgb.as_flattened(),
            w,
            h,
            image::ExtendedColorType::Rgba8,
            image::ImageFormat::Png,
        )
        .map_err(|e| ViewError::failure(format!("{}: cannot write the screenshot: {e}", path.display())))?;
        std::fs::write(&report_path, json)
            .map_err(|e| ViewError::failure(format!("{}: cannot write the report: {e}", report_path.display())))?;
        if let Renderer::Cpu(r) = &mut state.renderer {
            r.recycle(frame);
        }
        eprintln!("screenshot: {} ({w}x{h}), report {}", path.display(), report_path.display());
        Ok(())
    }

    /// Runs script events until one asks for frames to pass. Returns false when it quit.
    fn run_script(&mut self, event_loop: &ActiveEventLoop) -> bool {
        if self.wait_frames > 0 {
            self.wait_frames -= 1;
            return true;
        }
        while let Some(ev) = self.script.as_mut().and_then(|s| s.next()) {
            match ev {
                Event::KeyDown(k) => self.key(event_loop, &k, true),
                Event::KeyUp(k) => self.key(event_loop, &k, false),
                Event::Press(k) => {
                    self.key(event_loop, &k, true);
                    self.key(event_loop, &k, false);
                }
                Event::MouseDrag(dx, dy) => {
                    self.fly.look(dx, dy);
                    self.dirty = true;
                }
                Event::Scroll(n) => self.fly.scroll(n),
                Event::Wait(n) => {
                    if n > 0 {
                        self.wait_frames = n - 1;
                        return true;
                    }
                }
                Event::Resize(w, h) => {
                    if let Some(s) = &self.state {
                        let _ = s.window.request_inner_size(PhysicalSize::new(w, h));
                    }
                }
                Event::Screenshot(path) => {
                    if let Err(e) = self.screenshot(&path) {
                        self.fail(event_loop, e);
                        return false;
                    }
                }
                Event::PrintCamera => {
                    let c = &self.fly.camera;
                    println!(
                        "camera: position {} {} {} target {} {} {}",
                        c.position.x, c.position.y, c.position.z, c.target.x, c.target.y, c.target.z
                    );
                }
                Event::PrintFrame => {
                    let s = self.state.as_ref().map_or("none".to_string(), |s| s.backend_name.clone());
                    println!(
                        "frame: backend {s} scale {:.3} frames {} mean frame {:.2} ms last frame {:.2} ms at {}x{}",
                        self.scale,
                        self.frames,
                        self.frame_ms_sum / self.frames.max(1) as f64,
                        self.last_ms,
                        self.last_size.0,
                        self.last_size.1
                    );
                }
                Event::PrintMemory => {
                    println!("memory: VmRSS {} kB frame {}", script::resident_kb().unwrap_or(0), self.frames);
                }
                Event::Quit => {
                    self.quit(event_loop);
                    return false;
                }
            }
        }
        if self.script.as_ref().is_some_and(|s| s.len() == 0) {
            // The script ran out without `quit`: stay open, driven by the window from here.
            self.script = None;
        }
        true
    }

    fn quit(&mut self, event_loop: &ActiveEventLoop) {
        if self.frames > 0 {
            println!("frames: {} mean frame {:.2} ms", self.frames, self.frame_ms_sum / self.frames as f64);
        }
        event_loop.exit();
    }

    /// One frame: input → camera → render → present.
    fn redraw(&mut self, event_loop: &ActiveEventLoop) {
        let scripted = self.script.is_some();
        let now = Instant::now();
        let dt = if scripted { SCRIPT_DT } else { (now - self.last_frame).as_secs_f32().min(0.25) };
        self.last_frame = now;
        if scripted && !self.run_script(event_loop) {
            return;
        }
        if self.fly.step(dt) {
            self.dirty = true;
        }
        let Some(state) = self.state.as_mut() else { return };
        let (w, h) = (state.config.width, state.config.height);
        if w == 0 || h == 0 || state.window.is_minimized() == Some(true) {
            return;
        }
        let moving = self.fly.moving() || self.looking;
        let render_start = Instant::now();
        let src_view: wgpu::TextureView = match &mut state.renderer {
            Renderer::Gpu(r) => {
                let settings = FrameSettings { width: w, height: h, mode: self.options.mode };
                if let Err(e) = r.render_to_targets(&self.fly.camera, settings, &mut |_| {}) {
                    self.error.get_or_insert(ViewError::failure(format!("GPU frame failed: {e}")));
                    event_loop.exit();
                    return;
                }
                self.dirty = false;
                self.last_size = (w, h);
                match r.targets() {
                    Some(t) => t.final_image.view.clone(),
                    None => return,
                }
            }
            Renderer::Cpu(r) => {
                let need = self.dirty || self.coarse || state.upload.is_none();
                if need {
                    // Moving: a reduced size that holds the target frame time; still: full size.
                    let s = if moving { self.scale } else { 1.0 };
                    let (fw, fh) = (((w as f32 * s).round() as u32).max(1), ((h as f32 * s).round() as u32).max(1));
                    let settings = FrameSettings { width: fw, height: fh, mode: self.options.mode };
                    let t0 = Instant::now();
                    let frame = r.render(&self.fly.camera, settings, &mut |_| {});
                    let ms = t0.elapsed().as_secs_f64() * 1e3;
                    if moving {
                        let ratio = (self.options.target_ms / ms.max(0.1)).sqrt().clamp(0.5, 2.0) as f32;
                        self.scale = (self.scale * ratio).clamp(MIN_SCALE, 1.0);
                    }
                    if state.upload.as_ref().is_none_or(|u| u.size != (fw, fh)) {
                        state.upload = Some(Upload::new(&state.device, (fw, fh)));
                    }
                    if let Some(u) = &state.upload {
                        u.write(&state.queue, frame.buffers.final_srgb.as_flattened());
                    }
                    r.recycle(frame);
                    self.last_size = (fw, fh);
                    self.coarse = s < 1.0;
                    self.dirty = false;
                }
                match &state.upload {
                    Some(u) => u.view.clone(),
                    None => return,
                }
            }
        };
        let surface_texture = match state.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                state.surface.configure(&state.device, &state.config);
                state.window.request_redraw();
                return;
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                state.window.request_redraw();
                return;
            }
            other => {
                self.error.get_or_insert(ViewError::failure(format!("the window's surface failed: {other:?}")));
                event_loop.exit();
                return;
            }
        };
        let target = surface_texture.texture.create_view(&wgpu::TextureViewDescriptor::default());
        let mut enc = state.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("view.present") });
        state.blit.encode(&state.device, &mut enc, &src_view, &target, (w, h));
        state.queue.submit([enc.finish()]);
        state.queue.present(surface_texture);
        self.frames += 1;
        self.last_ms = render_start.elapsed().as_secs_f64() * 1e3;
        self.frame_ms_sum += self.last_ms;
        let cpu_refining = matches!(state.renderer, Renderer::Cpu(_)) && (self.coarse || self.dirty);
        if scripted || moving || cpu_refining {
            state.window.request_redraw();
        }
    }
}

fn key_name(code: KeyCode) -> Option<&'static str> {
    Some(match code {
        KeyCode::KeyW => "w",
        KeyCode::KeyA => "a",
        KeyCode::KeyS => "s",
        KeyCode::KeyD => "d",
        KeyCode::KeyQ => "q",
        KeyCode::KeyE => "e",
        KeyCode::KeyR => "r",
        KeyCode::KeyF => "f",
        KeyCode::ShiftLeft | KeyCode::ShiftRight => "shift",
        KeyCode::Tab => "tab",
        KeyCode::F12 => "f12",
        _ => return None,
    })
}

impl ApplicationHandler for App<'_> {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.state.is_some() {
            return;
        }
        match self.create_state(event_loop) {
            Ok(s) => {
                s.window.request_redraw();
                self.state = Some(s);
            }
            Err(e) => self.fail(event_loop, e),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => self.quit(event_loop),
            WindowEvent::Resized(size) => {
                if let Some(s) = self.state.as_mut() {
                    s.config.width = size.width;
                    s.config.height = size.height;
                    if size.width > 0 && size.height > 0 {
                        s.surface.configure(&s.device, &s.config);
                        self.dirty = true;
                        s.window.request_redraw();
                    }
                }
            }
            WindowEvent::KeyboardInput { event, .. } => {
                if event.repeat {
                    return;
                }
                if let PhysicalKey::Code(code) = event.physical_key
                    && let Some(name) = key_name(code)
                {
                    self.key(event_loop, name, event.state == ElementState::Pressed);
                    if let Some(s) = &self.state {
                        s.window.request_redraw();
                    }
                }
            }
            WindowEvent::MouseInput { state, button: MouseButton::Right, .. } => {
                self.looking = state == ElementState::Pressed;
                self.last_cursor = None;
            }
            WindowEvent::CursorMoved { position, .. } if self.looking => {
                if let Some((x, y)) = self.last_cursor {
                    self.fly.look((position.x - x) as f32, (position.y - y) as f32);
                    self.dirty = true;
                    if let Some(s) = &self.state {
                        s.window.request_redraw();
                    }
                }
                self.last_cursor = Some((position.x, position.y));
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
