//! `overlay`: the viewer's egui panels, drawn over the frame in the swapchain image (`Tab` hides
//! them). The overlay only reads the viewer's state ([`OverlayModel`]) and answers with
//! [`Action`]s, the same ones `--script` sends, so every knob behaves the same whether a person
//! clicks it or a test scripts it.

use std::collections::VecDeque;

use hybrid_core::buffer_view::BufferKind;
use hybrid_core::report::{FrameReport, StageTimings};
use hybrid_core::{Mode, Stage};
use hybrid_cpu::capsule::PrimaryVisibility;
use hybrid_scene::{Budget, Policy};
use winit::window::Window;

use crate::action::Action;

/// Frames kept for the frame-time graph.
pub const HISTORY_FRAMES: usize = 300;

/// One frame in the graph: the whole frame and its stages (ms).
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    pub frame_ms: f64,
    pub stages: StageTimings,
}

/// What the overlay shows (read-only).
pub struct OverlayModel<'a> {
    pub backend: &'a str,
    pub mode: Mode,
    pub frame_size: (u32, u32),
    pub fps: f64,
    pub history: &'a VecDeque<Sample>,
    /// The stage times are the GPU's (timestamp queries), not the host's.
    pub gpu_stage_times: bool,
    pub report: Option<&'a FrameReport>,
    pub budget: Budget,
    pub policy: Policy,
    pub importance: f32,
    pub buffer: BufferKind,
    pub has_point_clouds: bool,
    pub highlight: Option<u32>,
    pub clip_capsule: bool,
    pub sphere_effects: bool,
    /// `--fallback raster` (true) or `none`.
    pub fallback: hybrid_core::fallback::Fallback,
    /// CPU backend only.
    pub primary_visibility: Option<PrimaryVisibility>,
    pub lights: &'a [(String, bool)],
    pub keyframes: usize,
    pub playing: bool,
    pub orbit: bool,
    /// The last thing worth telling (a file that failed to open, where a path was saved).
    pub message: Option<&'a str>,
}

/// egui's context, its winit input state and its wgpu renderer.
pub struct Overlay {
    ctx: egui::Context,
    input: egui_winit::State,
    renderer: egui_wgpu::Renderer,
    pub visible: bool,
    /// The last built frame, waiting to be painted.
    pending: Option<(Vec<egui::ClippedPrimitive>, egui::TexturesDelta, f32)>,
    /// Edited budget value, kept while the kind (cost or ms) is switched.
    budget_cost: f64,
    budget_ms: f64,
}

const STAGE_COLORS: [egui::Color32; 7] = [
    egui::Color32::from_rgb(160, 110, 220), // capsule
    egui::Color32::from_rgb(90, 150, 230),  // raster
    egui::Color32::from_rgb(90, 200, 160),  // lighting
    egui::Color32::from_rgb(230, 200, 80),  // heuristic
    egui::Color32::from_rgb(235, 120, 70),  // trace
    egui::Color32::from_rgb(120, 170, 90),  // fallback
    egui::Color32::from_rgb(200, 200, 200), // blend
];

impl Overlay {
    pub fn new(window: &Window, device: &wgpu::Device, format: wgpu::TextureFormat) -> Self {
        let ctx = egui::Context::default();
        let input = egui_winit::State::new(
            ctx.clone(),
            egui::ViewportId::ROOT,
            window,
            Some(window.scale_factor() as f32),
            None,
            Some(device.limits().max_texture_dimension_2d as usize),
        );
        let renderer = egui_wgpu::Renderer::new(device, format, egui_wgpu::RendererOptions::default());
        Self { ctx, input, renderer, visible: true, pending: None, budget_cost: 100.0, budget_ms: 10.0 }
    }

    /// Gives a window event to egui; true when egui used it (the camera must not see it).
    pub fn on_window_event(&mut self, window: &Window, event: &winit::event::WindowEvent) -> bool {
        let response = self.input.on_window_event(window, event);
        self.visible && response.consumed
    }

    /// Whether the pointer is over an overlay panel (mouse input belongs to the overlay).
    pub fn wants_pointer(&self) -> bool {
        self.visible && self.ctx.egui_wants_pointer_input()
    }

    /// Builds this frame's panels; returns what the user asked for.
    pub fn build(&mut self, window: &Window, model: &OverlayModel) -> Vec<Action> {
        let raw = self.input.take_egui_input(window);
        let mut actions = Vec::new();
        let visible = self.visible;
        let (mut budget_cost, mut budget_ms) = (self.budget_cost, self.budget_ms);
        let out = self.ctx.run_ui(raw, |ui| {
            if visible {
                panels(ui.ctx(), model, &mut actions, &mut budget_cost, &mut budget_ms);
            }
        });
        self.budget_cost = budget_cost;
        self.budget_ms = budget_ms;
        self.input.handle_platform_output(window, out.platform_output);
        let primitives = self.ctx.tessellate(out.shapes, out.pixels_per_point);
        self.pending = Some((primitives, out.textures_delta, out.pixels_per_point));
        actions
    }

    /// Draws the last built panels over `target` (which already holds the frame).
    pub fn paint(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        enc: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        size: (u32, u32),
    ) {
        let Some((primitives, textures, ppp)) = self.pending.take() else { return };
        for (id, deltas) in &textures.set {
            for delta in deltas {
                self.renderer.update_texture(device, queue, *id, delta);
            }
        }
        let screen = egui_wgpu::ScreenDescriptor { size_in_pixels: [size.0, size.1], pixels_per_point: ppp };
        let extra = self.renderer.update_buffers(device, queue, enc, &primitives, &screen);
        if !extra.is_empty() {
            queue.submit(extra);
        }
        {
            let pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("view.overlay"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            self.renderer.render(&mut pass.forget_lifetime(), &primitives, &screen);
        }
        for id in &textures.free {
            self.renderer.free_texture(id);
        }
    }
}

fn panels(ctx: &egui::Context, m: &OverlayModel, actions: &mut Vec<Action>, budget_cost: &mut f64, budget_ms: &mut f64) {
    egui::Window::new("hybrid").default_pos([10.0, 10.0]).default_width(330.0).resizable(true).show(ctx, |ui| {
        stats(ui, m, actions);
        ui.separator();
        egui::CollapsingHeader::new("Heuristic").default_open(true).show(ui, |ui| heuristic(ui, m, actions, budget_cost, budget_ms));
        egui::CollapsingHeader::new("Buffers").default_open(false).show(ui, |ui| buffers(ui, m, actions));
        egui::CollapsingHeader::new("Scene").default_open(false).show(ui, |ui| scene(ui, m, actions));
        ui.separator();
        ui.small("WASD/QE fly · right drag look · wheel speed · Shift fast · F frame · R home · O orbit · P play path · K keyframe · Ctrl+S save path · F12 screenshot · Tab hide");
        if let Some(msg) = m.message {
            ui.separator();
            ui.colored_label(egui::Color32::from_rgb(255, 200, 120), msg);
        }
    });
    egui::Window::new("Objects")
        .anchor(egui::Align2::RIGHT_TOP, [-10.0, 10.0])
        .default_width(560.0)
        .default_open(false)
        .show(ctx, |ui| objects(ui, m, actions));
}

fn stats(ui: &mut egui::Ui, m: &OverlayModel, actions: &mut Vec<Action>) {
    // One line each, truncated (hover shows all): rows keep their places whatever the numbers.
    ui.add(egui::Label::new(format!("backend: {}", m.backend)).truncate());
    ui.horizontal(|ui| {
        ui.label("mode");
        let mut mode = m.mode;
        egui::ComboBox::from_id_salt("mode").selected_text(mode.name()).show_ui(ui, |ui| {
            for md in Mode::ALL {
                ui.selectable_value(&mut mode, md, md.name());
            }
        });
        if mode != m.mode {
            actions.push(Action::SetMode(mode));
        }
    });
    let last = m.history.back();
    ui.add(
        egui::Label::new(format!(
            "{:.1} fps · frame {:.2} ms · {}×{}",
            m.fps,
            last.map_or(0.0, |s| s.frame_ms),
            m.frame_size.0,
            m.frame_size.1
        ))
        .truncate(),
    );
    let src = if m.gpu_stage_times { "GPU" } else { "host" };
    let parts: Vec<String> = match last {
        Some(s) => Stage::ALL.iter().filter(|st| s.stages[**st] > 0.0).map(|st| format!("{} {:.2}", st.name(), s.stages[*st])).collect(),
        None => vec!["no frame yet".into()],
    };
    ui.add(egui::Label::new(egui::RichText::new(format!("{src} ms: {}", parts.join(" · "))).small()).truncate());
    frame_graph(ui, m.history);
    ui.horizontal_wrapped(|ui| {
        for (st, c) in Stage::ALL.iter().zip(STAGE_COLORS) {
            ui.colored_label(c, st.name());
        }
        ui.label("(stacked; the line is the whole frame)");
    });
}

/// The last [`HISTORY_FRAMES`] frames: stacked stage times as bars, the frame time as a line.
fn frame_graph(ui: &mut egui::Ui, history: &VecDeque<Sample>) {
    let (rect, _) = ui.allocate_exact_size(egui::vec2(ui.available_width().max(200.0), 70.0), egui::Sense::hover());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, egui::Color32::from_black_alpha(120));
    let max_ms = history.iter().map(|s| s.frame_ms).fold(1.0f64, f64::max) * 1.1;
    let bar_w = rect.width() / HISTORY_FRAMES as f32;
    let y = |ms: f64| rect.bottom() - (ms / max_ms) as f32 * rect.height();
    let start = HISTORY_FRAMES.saturating_sub(history.len());
    let mut line = Vec::with_capacity(history.len());
    for (i, s) in history.iter().enumerate() {
        let x = rect.left() + (start + i) as f32 * bar_w;
        let mut acc = 0.0;
        for (st, c) in Stage::ALL.iter().zip(STAGE_COLORS) {
            let v = s.stages[*st];
            if v > 0.0 {
                let r = egui::Rect::from_min_max(egui::pos2(x, y(acc + v)), egui::pos2(x + bar_w.max(1.0), y(acc)));
                painter.rect_filled(r, 0.0, c);
                acc += v;
            }
        }
        line.push(egui::pos2(x + bar_w * 0.5, y(s.frame_ms)));
    }
    painter.add(egui::Shape::line(line, egui::Stroke::new(1.0, egui::Color32::WHITE)));
    painter.text(
        rect.left_top() + egui::vec2(4.0, 2.0),
        egui::Align2::LEFT_TOP,
        format!("{max_ms:.1} ms"),
        egui::FontId::monospace(10.0),
        egui::Color32::LIGHT_GRAY,
    );
}

fn heuristic(ui: &mut egui::Ui, m: &OverlayModel, actions: &mut Vec<Action>, budget_cost: &mut f64, budget_ms: &mut f64) {
    // The cost slider's range: everything visible (C summed over the report's objects).
    let total_cost = m.report.and_then(|r| r.heuristic.as_ref()).map_or(0.0, |h| h.objects.iter().map(|o| o.c).sum::<f64>());
    let cost_max = total_cost.max(1.0) * 1.1;
    #[derive(PartialEq, Clone, Copy)]
    enum Kind {
        Unlimited,
        Cost,
        Ms,
    }
    let kind = match m.budget {
        Budget::Unlimited => Kind::Unlimited,
        Budget::Cost(c) => {
            *budget_cost = c;
            Kind::Cost
        }
        Budget::Millis(ms) => {
            *budget_ms = ms;
            Kind::Ms
        }
    };
    let mut k = kind;
    ui.horizontal(|ui| {
        ui.label("budget");
        ui.radio_value(&mut k, Kind::Unlimited, "unlimited");
        ui.radio_value(&mut k, Kind::Cost, "cost");
        ui.radio_value(&mut k, Kind::Ms, "ms");
    });
    let mut new_budget = None;
    if k != kind {
        new_budget = Some(match k {
            Kind::Unlimited => Budget::Unlimited,
            Kind::Cost => Budget::Cost(budget_cost.min(cost_max)),
            Kind::Ms => Budget::Millis(*budget_ms),
        });
    }
    match k {
        Kind::Cost => {
            let mut c = *budget_cost;
            if ui.add(egui::Slider::new(&mut c, 0.0..=cost_max).text("T (cost units)")).changed() {
                new_budget = Some(Budget::Cost(c));
            }
        }
        Kind::Ms => {
            let mut ms = *budget_ms;
            if ui.add(egui::Slider::new(&mut ms, 0.1..=200.0).logarithmic(true).text("T (ms of trace)")).changed() {
                new_budget = Some(Budget::Millis(ms));
            }
        }
        Kind::Unlimited => {}
    }
    if let Some(b) = new_budget {
        actions.push(Action::SetBudget(b));
    }
    ui.horizontal(|ui| {
        ui.label("policy");
        let mut p = m.policy;
        ui.radio_value(&mut p, Policy::Paper, "paper");
        ui.radio_value(&mut p, Policy::Knapsack, "knapsack");
        if p != m.policy {
            actions.push(Action::SetPolicy(p));
        }
    });
    let mut i = m.importance;
    if ui.add(egui::Slider::new(&mut i, 0.0..=10.0).text("I (keep last choice)")).changed() {
        actions.push(Action::SetImportance(i));
    }
    if let Some(h) = m.report.and_then(|r| r.heuristic.as_ref()) {
        let selected = h.objects.iter().filter(|o| o.selected).count();
        ui.label(format!(
            "selected {selected} of {} visible · spent {:.1} of {} · lights {}",
            h.objects.len(),
            h.spent,
            h.budget.map_or("unlimited".to_string(), |b| format!("{b:.1}")),
            h.lights
        ));
        if let Some(mpc) = h.ms_per_cost {
            ui.small(format!("estimate: {mpc:.4} ms per unit of cost"));
        }
    } else {
        ui.label("no heuristic this frame (mode rt-only or raster)");
    }
}

fn objects(ui: &mut egui::Ui, m: &OverlayModel, actions: &mut Vec<Action>) {
    let Some(h) = m.report.and_then(|r| r.heuristic.as_ref()) else {
        ui.label("no heuristic this frame (mode rt-only or raster)");
        return;
    };
    ui.small("A pixels · P centrality on screen · D distance · V = A·P/D · Q rays per pixel (lights, +reflective, +refractive) · C = A·Q·E cost · R = (S·I + V)·K relevance · K static relevance · E estimated cost · S selected last frame (design §4). Click a name to highlight the object.");
    egui::ScrollArea::vertical().max_height(320.0).show(ui, |ui| {
        egui::Grid::new("objects").striped(true).num_columns(13).show(ui, |ui| {
            for head in ["name", "A", "P", "D", "V", "Q", "C", "R", "K", "E", "S", "sel", ""] {
                ui.strong(head);
            }
            ui.end_row();
            for o in &h.objects {
                let id = o.id as u32;
                let is_hl = m.highlight == Some(id);
                if ui.selectable_label(is_hl, &o.name).clicked() {
                    actions.push(Action::Highlight(if is_hl { None } else { Some(id) }));
                }
                ui.label(o.a.to_string());
                ui.label(format!("{:.3}", o.p));
                ui.label(format!("{:.2}", o.d));
                ui.label(format!("{:.3}", o.v));
                ui.label(o.q.to_string());
                ui.label(format!("{:.1}", o.c));
                ui.label(format!("{:.3}", o.r));
                let (mut k, mut e) = (o.k, o.e);
                let dk = ui
                    .add(egui::DragValue::new(&mut k).range(0.0..=100.0).speed(0.05))
                    .on_hover_text("K: static relevance (higher: chosen sooner)");
                let de = ui
                    .add(egui::DragValue::new(&mut e).range(0.0..=100.0).speed(0.05))
                    .on_hover_text("E: estimated cost per pixel and ray (higher: chosen later)");
                if dk.changed() || de.changed() {
                    actions.push(Action::SetObjectWeights(o.id, k, e));
                }
                ui.label(if o.s { "yes" } else { "" });
                ui.label(if o.selected { "yes" } else { "" });
                ui.label(match (o.reflective, o.refractive) {
                    (true, true) => "refl+refr",
                    (true, false) => "refl",
                    (false, true) => "refr",
                    _ => "",
                });
                ui.end_row();
            }
        });
    });
}

fn buffers(ui: &mut egui::Ui, m: &OverlayModel, actions: &mut Vec<Action>) {
    ui.small("The buffer shown full-window (the same images as `hybrid render --dump`).");
    ui.horizontal_wrapped(|ui| {
        for k in BufferKind::ALL {
            if (k.needs_point_clouds() && !m.has_point_clouds)
                || (k.needs_fallback() && m.fallback == hybrid_core::fallback::Fallback::None)
            {
                continue;
            }
            if ui.selectable_label(m.buffer == k, k.name()).clicked() && m.buffer != k {
                actions.push(Action::SetBuffer(k));
            }
        }
    });
}

fn scene(ui: &mut egui::Ui, m: &OverlayModel, actions: &mut Vec<Action>) {
    let mut raster = m.fallback == hybrid_core::fallback::Fallback::Raster;
    if ui
        .checkbox(&mut raster, "raster fallbacks")
        .on_hover_text("objects the heuristic did not select get shadow maps and probes instead of no effects, at the cost of rendering the maps (cached) and a lookup per pixel; off: the paper")
        .changed()
    {
        actions.push(Action::SetFallback(if raster { hybrid_core::fallback::Fallback::Raster } else { hybrid_core::fallback::Fallback::None }));
    }
    if m.has_point_clouds {
        ui.label("point clouds");
        let mut clip = m.clip_capsule;
        if ui.checkbox(&mut clip, "clip at raster depth").on_hover_text("trace the capsule after the raster with rays ending at the polygons: fewer rays, at the cost of running after (not beside) the raster").changed() {
            actions.push(Action::SetClipCapsule(clip));
        }
        let mut fx = m.sphere_effects;
        if ui
            .checkbox(&mut fx, "sphere effects")
            .on_hover_text("spheres cast shadows and show in reflections and refractions, at the cost of a slower trace stage")
            .changed()
        {
            actions.push(Action::SetSphereEffects(fx));
        }
        if let Some(pv) = m.primary_visibility {
            ui.horizontal(|ui| {
                ui.label("primary visibility");
                let mut v = pv;
                ui.radio_value(&mut v, PrimaryVisibility::Auto, "auto");
                ui.radio_value(&mut v, PrimaryVisibility::Projected, "projected");
                ui.radio_value(&mut v, PrimaryVisibility::Bvh, "bvh");
                if v != pv {
                    actions.push(Action::SetPrimaryVisibility(v));
                }
            });
        }
    }
    ui.label("lights");
    for (i, (name, on)) in m.lights.iter().enumerate() {
        let mut v = *on;
        if ui.checkbox(&mut v, name).changed() {
            actions.push(Action::SetLight(i, v));
        }
    }
    ui.separator();
    ui.horizontal(|ui| {
        if ui.button("frame (F)").clicked() {
            actions.push(Action::FrameBounds);
        }
        if ui.selectable_label(m.orbit, "orbit (O)").clicked() {
            actions.push(Action::ToggleOrbit);
        }
        if ui.selectable_label(m.playing, "play path (P)").clicked() {
            actions.push(Action::PlayPath);
        }
    });
    ui.horizontal(|ui| {
        if ui.button(format!("keyframe (K): {}", m.keyframes)).clicked() {
            actions.push(Action::AddKeyframe);
        }
        if ui.button("save path (Ctrl+S)").clicked() {
            actions.push(Action::SavePath);
        }
        if ui.button("screenshot (F12)").clicked() {
            actions.push(Action::Screenshot(None));
        }
    });
}
