//! Command-line arguments (design §7). Flag names are a contract: keep them.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use hybrid_core::Mode;
use hybrid_scene::{Budget, HeuristicSettings, Policy, parse_byte_size};

use crate::CliError;

#[derive(Debug, Parser)]
#[command(
    name = "hybrid",
    version,
    about = "Hybrid rasterization + ray tracing renderer (Walewski et al. 2019; Timokhin & Mikhaylyuk depth merge)"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Render one frame of a scene (the built-in demo scene when none is given) to a PNG.
    Render(RenderArgs),
    /// Load and validate a scene and print its statistics (the paper's Table 4 row).
    Inspect(InspectArgs),
    /// The paper's experiments (Tables 5 and 6) on one scene, with image error (FLIP) against rt-only
    ///
    /// Repeats the timing tables of Walewski et al. 2019 on one scene, for each mode of --modes,
    /// prints them (Markdown, on stdout) and writes bench.json, frames.csv and frame_times.png
    /// (with --sweep-budget also sweep.csv and sweep.png) into --out. BENCHMARKS.md has results
    /// and the commands that made them.
    ///
    /// Terms:
    ///
    /// - Table 5 and Table 6: the paper's tables of frame and stage times, one for the static
    ///   set and one for the path set. (The paper's Table 4, the size of each test scene, is
    ///   what `hybrid inspect` prints.)
    ///
    /// - static set (Table 5): --frames frames from the scene's own camera, after 2 warm-up
    ///   frames, each mode with a fresh renderer; mean and 95th percentile per stage.
    ///
    /// - path set (Table 6): the scene's camera path ([camera_path] in the scene file) played at
    ///   --fps frames per second of path time for --path-seconds, every frame rendered as fast as
    ///   it goes. Skipped when the scene has no camera path.
    ///
    /// - modes: hybrid (the heuristic chooses which objects get ray-traced shadows, reflections
    ///   and refractions), all (every visible object gets them), rt-only (no rasterization:
    ///   primary rays fill the G-buffer and everything is ray traced; the reference image),
    ///   raster (no ray tracing).
    ///
    /// - FLIP: a perceptual image difference (0 = the same image, 1 = as different as can be)
    ///   of a frame against the rt-only frame from the same camera.
    ///
    /// - capsule: the renderer of the scene's point clouds (Timokhin & Mikhaylyuk): their
    ///   points, drawn as spheres, are ray traced into a colour + depth frame that is merged by
    ///   depth with the polygons. Its time is the CAPSULE row (absent without point clouds).
    ///
    /// - stages: RAST = the G-buffer and its deferred lighting (in rt-only made by primary rays,
    ///   not rasterized; files still call it `raster`), HEUR = the heuristic, RAYT = the
    ///   shadow/reflection/refraction rays, BLEND = combining them into the final image.
    ///
    /// - sweep (--sweep-budget): hybrid frames at several cost budgets with both selection
    ///   policies, to plot image error against frame time.
    #[command(verbatim_doc_comment)]
    Bench(BenchArgs),
    /// Open a scene (the built-in demo scene when none is given) in an interactive window.
    View(ViewArgs),
}

#[derive(Debug, Args)]
pub struct ViewArgs {
    /// Scene file (TOML), or a model file (.gltf/.glb/.obj/.ply/.las/.laz) opened in a default
    /// scene. Without one, the built-in demo scene opens.
    pub scene: Option<PathBuf>,
    /// Initial window size as WIDTHxHEIGHT (frames render at the window's size: larger windows
    /// show more detail at the cost of frame time).
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Which stages run: hybrid (heuristic on), all, rt-only, raster.
    #[arg(long, default_value = "hybrid", value_parser = parse_mode)]
    pub mode: Mode,
    /// Rendering backend. `auto` picks a hardware GPU that can draw into the window, else the
    /// CPU; `gpu` also accepts software adapters (lavapipe), slower than `cpu`.
    #[arg(long, value_enum, default_value_t = BackendChoice::Auto)]
    pub backend: BackendChoice,
    #[command(flatten)]
    pub heuristic: HeuristicArgs,
    /// CPU backend: whole-frame time (ms: render, upload, overlay, present) to hold while the
    /// camera moves, by rendering at a reduced resolution. Lower values move more smoothly but
    /// blurrier; the full-size frame follows when the camera stops. The default, 90 ms, keeps
    /// moving at 10 frames per second or more with room for the controller's wobble.
    #[arg(long, default_value_t = 90.0)]
    pub target_ms: f64,
    /// Drive the window with the input events in this file (tests, demos); see the README.
    #[arg(long)]
    pub script: Option<PathBuf>,
    #[command(flatten)]
    pub capsule: CapsuleArgs,
}

#[derive(Debug, Args)]
pub struct RenderArgs {
    /// Scene file (TOML), or a model file (.gltf, .glb, .obj, .ply; point clouds .ply, .las,
    /// .laz) to render in a default scene: camera framing it, a sun, a sky, a ground plane.
    /// Without one, the built-in demo scene is rendered.
    pub scene: Option<PathBuf>,
    /// Write the scene being rendered as a TOML scene file to edit (paths in it relative to the
    /// written file). Most useful with a model file, whose default scene is otherwise not saved.
    #[arg(long, value_name = "FILE.toml")]
    pub save_scene: Option<PathBuf>,
    /// Output image (8-bit sRGB PNG).
    #[arg(short = 'o', long = "output", default_value = "out.png")]
    pub output: PathBuf,
    /// Image size as WIDTHxHEIGHT. Larger sizes show more detail at the cost of time
    /// (ray-tracing time grows with the number of masked pixels).
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Which stages run: hybrid (heuristic on), all (every visible object traced),
    /// rt-only (no raster, everything ray traced), raster (no ray tracing).
    #[arg(long, default_value = "hybrid", value_parser = parse_mode)]
    pub mode: Mode,
    /// Rendering backend. `auto` picks a hardware GPU when one exists, else the CPU, and says
    /// which it chose; `gpu` also accepts software adapters (lavapipe), slower than `cpu`.
    #[arg(long, value_enum, default_value_t = BackendChoice::Auto)]
    pub backend: BackendChoice,
    /// Write every buffer of the frame (PNG for viewing, EXR for float data) into this folder.
    #[arg(long)]
    pub dump: Option<PathBuf>,
    /// Write a JSON report of the frame (stage times, rays, heuristic decisions) to this file.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Position on the scene's camera path, in seconds (the scene's camera when absent).
    #[arg(long)]
    pub time: Option<f32>,
    #[command(flatten)]
    pub heuristic: HeuristicArgs,
    /// Worker threads (default: all cores), at most 1024 (`MAX_THREADS`). More threads than
    /// cores adds scheduling overhead without speed; fewer leaves cores idle.
    #[arg(long, value_parser = parse_threads)]
    pub threads: Option<usize>,
    /// Memory this run may plan to use, e.g. `4GiB`, `512MiB`, `1.5GiB` (B, KiB, MiB, GiB, TiB;
    /// kB, MB, GB, TB). A size or scene estimated to need more is refused before anything is
    /// rendered or written (exit 2). Default: 75% of the machine's memory.
    #[arg(long, value_name = "SIZE", value_parser = parse_byte_size)]
    pub max_memory: Option<u64>,
    #[command(flatten)]
    pub capsule: CapsuleArgs,
    /// Print nothing on success: no progress bar, no backend line and no result line (the
    /// image is still written). Warnings and errors are still printed.
    #[arg(short, long)]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub struct InspectArgs {
    /// Scene file (TOML), or a model file (.gltf, .glb, .obj, .ply, .las, .laz) in a default scene.
    pub scene: PathBuf,
    /// Print machine-readable JSON instead of the table row.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Scene file (TOML), or a model file (.gltf, .glb, .obj, .ply, .las, .laz) in a default scene.
    pub scene: PathBuf,
    /// Image size as WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Rendering backend.
    #[arg(long, value_enum, default_value_t = BackendChoice::Auto)]
    pub backend: BackendChoice,
    /// Static set: frames measured at the scene's camera (after 2 warm-up frames).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..))]
    pub frames: u32,
    /// Path set: seconds of the camera path to render (default: 20, or the whole path if shorter).
    #[arg(long)]
    pub path_seconds: Option<f32>,
    /// Path set: frames per second of path time.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
    /// Modes to measure, comma-separated (hybrid, all, rt-only, raster).
    #[arg(long, value_delimiter = ',', default_value = "hybrid,all,rt-only", value_parser = parse_mode)]
    pub modes: Vec<Mode>,
    /// Output folder (bench.json, frames.csv, frame_times.png, sweep.csv, sweep.png).
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    /// Path set: FLIP against rt-only on every K-th frame.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..))]
    pub flip_every: u32,
    /// Also render the path at several cost budgets with both policies (FLIP vs time).
    #[arg(long)]
    pub sweep_budget: bool,
    #[command(flatten)]
    pub heuristic: HeuristicArgs,
    /// Worker threads (default: all cores), at most 1024 (`MAX_THREADS`). More threads than
    /// cores adds scheduling overhead without speed; fewer leaves cores idle.
    #[arg(long, value_parser = parse_threads)]
    pub threads: Option<usize>,
    /// Memory this run may plan to use, e.g. `4GiB`, `512MiB`, `1.5GiB` (B, KiB, MiB, GiB, TiB;
    /// kB, MB, GB, TB). A size or scene estimated to need more is refused before anything is
    /// rendered or written (exit 2). Default: 75% of the machine's memory.
    #[arg(long, value_name = "SIZE", value_parser = parse_byte_size)]
    pub max_memory: Option<u64>,
    #[command(flatten)]
    pub capsule: CapsuleArgs,
    /// No progress lines and no backend line on stderr; the tables are still printed on stdout
    /// and the files written. Warnings and errors are still printed.
    #[arg(short, long)]
    pub quiet: bool,
}

/// Point-cloud capsule switches shared by `render` and `bench` (beyond paper 2).
#[derive(Debug, Args)]
pub struct CapsuleArgs {
    /// Beyond paper 2: trace the point-cloud capsule after the raster, clipping its rays at the
    /// polygons' depth. Saves the rays that would end behind polygons, at the cost of running
    /// the capsule after (not beside) the raster.
    #[arg(long)]
    pub clip_capsule: bool,
    /// CPU backend: how the capsule finds each primary ray's sphere (the frame is the same bit
    /// for bit). `projected` projects every sphere to the pixels it may cover and tests only
    /// those rays: fastest when there are fewer spheres than pixels, at the cost of touching
    /// every sphere in view each frame. `bvh` traverses the sphere BVH per 8×8 tile (paper 2's
    /// way): its cost follows rays, not spheres, so it wins with many more spheres than pixels.
    /// `auto` (default) projects up to 2 points per pixel. The GPU backend always traverses
    /// (its sphere BVH, or its acceleration structure: `--rt`).
    #[arg(long, value_enum, default_value_t = CapsuleVisibilityChoice::Auto)]
    pub capsule_visibility: CapsuleVisibilityChoice,
    /// Paper 2's behaviour: the point cloud only merges by depth, it casts no shadows on
    /// polygons and is not seen in reflections or refractions. Faster trace stage, at the cost
    /// of those effects.
    #[arg(long)]
    pub no_sphere_effects: bool,
    /// GPU backend: how rays are traced. `hw`: hardware ray tracing (wgpu ray queries over
    /// acceleration structures built once per scene: a BLAS per mesh, the point-cloud spheres as
    /// AABB geometry); an adapter without ray queries is an error (exit 2), as is the CPU
    /// backend. `sw`: the software BVH2 traversal in WGSL (every adapter). `auto` (default):
    /// hardware where a GPU offers it, else software (a CPU adapter such as lavapipe stays on
    /// software: its ray queries run on the CPU, slower); says which.
    #[arg(long, value_enum, default_value_t = RtArg::Auto)]
    pub rt: RtArg,
    /// What the pixels of objects the heuristic did not select get (issue 18). `raster`
    /// (default): shadow maps (cascaded for directional lights, one per spot, a cube per point
    /// light) and a reflection/refraction probe per reflective or refractive object, so effects
    /// degrade instead of switching off, at the cost of rendering the maps (cached between
    /// frames) and a lookup per pixel; `--mode raster` uses them everywhere. `none`: nothing,
    /// as in paper 1 (for reproducing its tables).
    #[arg(long, value_enum, default_value_t = FallbackArg::Raster)]
    pub fallback: FallbackArg,
}

/// `--fallback`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FallbackArg {
    Raster,
    None,
}

impl FallbackArg {
    pub fn fallback(self) -> hybrid_core::fallback::Fallback {
        match self {
            FallbackArg::Raster => hybrid_core::fallback::Fallback::Raster,
            FallbackArg::None => hybrid_core::fallback::Fallback::None,
        }
    }
}

/// `--rt`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RtArg {
    Auto,
    Hw,
    Sw,
}

impl RtArg {
    pub fn choice(self) -> hybrid_gpu::RtChoice {
        match self {
            RtArg::Auto => hybrid_gpu::RtChoice::Auto,
            RtArg::Hw => hybrid_gpu::RtChoice::Hardware,
            RtArg::Sw => hybrid_gpu::RtChoice::Software,
        }
    }
}

/// Heuristic overrides shared by `render` and `bench`.
#[derive(Debug, Args)]
pub struct HeuristicArgs {
    /// Heuristic budget T in cost units per frame (overrides the scene). Lower budgets trace
    /// fewer objects: faster frames at the cost of missing shadows/reflections/refractions.
    #[arg(long, conflicts_with = "budget_ms")]
    pub budget: Option<f64>,
    /// Heuristic budget in milliseconds of trace time per frame (overrides the scene).
    #[arg(long)]
    pub budget_ms: Option<f64>,
    /// Heuristic selection policy (overrides the scene).
    #[arg(long, value_enum)]
    pub policy: Option<PolicyChoice>,
}

impl HeuristicArgs {
    /// Rejects budgets that are negative or not finite.
    pub fn check(&self) -> Result<(), CliError> {
        for (flag, v) in [("--budget", self.budget), ("--budget-ms", self.budget_ms)] {
            if let Some(v) = v
                && (!v.is_finite() || v < 0.0)
            {
                return Err(CliError::bad_input(format!("{flag} must be a finite number ≥ 0, got {v}")));
            }
        }
        Ok(())
    }

    /// Applies the overrides to a scene's heuristic settings.
    pub fn apply(&self, settings: &mut HeuristicSettings) {
        if let Some(b) = self.budget {
            settings.budget = Budget::Cost(b);
        }
        if let Some(ms) = self.budget_ms {
            settings.budget = Budget::Millis(ms);
        }
        if let Some(p) = self.policy {
            settings.policy = match p {
                PolicyChoice::Paper => Policy::Paper,
                PolicyChoice::Knapsack => Policy::Knapsack,
            };
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BackendChoice {
    /// A hardware GPU when one exists, else the CPU backend.
    Auto,
    /// The pure-Rust CPU backend.
    Cpu,
    /// The wgpu backend on any adapter wgpu finds that can run it (Vulkan, Metal, DX12; software
    /// adapters such as Mesa's lavapipe included; adapters lacking a format or limit the frame
    /// needs, such as llvmpipe's OpenGL, are refused). No such adapter is an error.
    Gpu,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CapsuleVisibilityChoice {
    /// `projected` up to 2 points per pixel, else `bvh`.
    Auto,
    /// Spheres projected to pixel rectangles, each ray tested against the spheres over it.
    Projected,
    /// Each tile's rays traced through the sphere BVH.
    Bvh,
}

impl CapsuleVisibilityChoice {
    /// The CPU capsule's setting.
    pub fn primary_visibility(self) -> hybrid_cpu::capsule::PrimaryVisibility {
        use hybrid_cpu::capsule::PrimaryVisibility;
        match self {
            Self::Auto => PrimaryVisibility::Auto,
            Self::Projected => PrimaryVisibility::Projected,
            Self::Bvh => PrimaryVisibility::Bvh,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Projected => "projected",
            Self::Bvh => "bvh",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PolicyChoice {
    /// Walewski et al. 2019 (listing 6).
    Paper,
    /// Greedy by relevance per cost.
    Knapsack,
}

/// Largest accepted image side.
pub const MAX_SIDE: u32 = 16384;

pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("size `{s}` must be WIDTHxHEIGHT, e.g. 1280x720"))?;
    let parse = |v: &str, what: &str| -> Result<u32, String> {
        let n: u32 = v.trim().parse().map_err(|_| format!("size `{s}`: {what} `{v}` is not a whole number"))?;
        if n == 0 || n > MAX_SIDE {
            return Err(format!("size `{s}`: {what} must be between 1 and {MAX_SIDE}"));
        }
        Ok(n)
    };
    Ok((parse(w, "width")?, parse(h, "height")?))
}

pub fn parse_mode(s: &str) -> Result<Mode, String> {
    s.parse()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes() {
        assert_eq!(parse_size("1280x720"), Ok((1280, 720)));
        assert_eq!(parse_size("64X32"), Ok((64, 32)));
        assert!(parse_size("0x10").unwrap_err().contains("between 1"));
        assert!(parse_size("10").unwrap_err().contains("WIDTHxHEIGHT"));
        assert!(parse_size("axb").unwrap_err().contains("not a whole number"));
        assert!(parse_size("99999x10").is_err());
    }

    #[test]
    fn modes() {
        assert_eq!(parse_mode("rt-only"), Ok(Mode::RtOnly));
        assert!(parse_mode("fast").unwrap_err().contains("unknown mode"));
    }
}

/// Upper bound of `--threads`: far above any real core count, far below what makes thread
/// creation fail or hang.
pub const MAX_THREADS: usize = 1024;

/// Sizes rayon's global pool to `--threads` (parsed by [`parse_threads`]). Call it before
/// anything uses rayon: loading a scene (BVH builds, smooth normals) starts the default pool,
/// after which it can no longer be sized.
pub fn use_threads(threads: Option<usize>) -> Result<(), CliError> {
    match threads {
        Some(n) => rayon::ThreadPoolBuilder::new().num_threads(n).build_global().map_err(|e| CliError::failure(e.to_string())),
        None => Ok(()),
    }
}

/// `--threads N`: 1 ..= [`MAX_THREADS`].
fn parse_threads(s: &str) -> Result<usize, String> {
    let n: usize = s.trim().parse().map_err(|_| format!("`{s}` is not a whole number of threads"))?;
    if n == 0 || n > MAX_THREADS {
        return Err(format!("{n} threads is out of range: use 1 to {MAX_THREADS}"));
    }
    Ok(n)
}

#[cfg(test)]
mod thread_limit_tests {
    use super::*;

    #[test]
    fn threads_are_bounded() {
        assert_eq!(parse_threads("4"), Ok(4));
        assert_eq!(parse_threads("1024"), Ok(MAX_THREADS));
        assert!(parse_threads("0").is_err());
        assert!(parse_threads("100000").unwrap_err().contains("1 to 1024"));
        assert!(parse_threads("-3").is_err());
    }
}
