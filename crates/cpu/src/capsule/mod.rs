//! The RT-scene capsule (paper 2, design §5): a plug-in that ray traces a point cloud of spheres
//! and hands the host a packed frame (colour + depth per texel) for the depth merge.
//!
//! The host sees only [`RtCapsule`]: "give me a packed frame for this camera". The CPU frame
//! calls it in line (the raster needs its frame first, or in `--clip-capsule` order it needs the
//! raster's depth, so there is nothing to overlap it with); [`render_sync`] is that call with a
//! fresh frame. Paper 2's semaphore handshake between a host and a capsule on its own thread is
//! kept as a test (`tests/support/exchange.rs`), which proves the plug-in boundary is enough to
//! run a capsule that way.
//!
//! [`PointCloudCapsule`] builds **one sphere BVH per cloud** (each cloud has its own radius; a
//! scene usually has one cloud) and traces them in turn with a shrinking `t_max`, so the closest
//! hit over all clouds wins. A primary ray finds its sphere one of two ways with the same result,
//! bit for bit ([`PrimaryVisibility`]): through the BVH, 8×8 tiles at a time, or (module
//! `projected`) among the spheres whose projected bounds cover its pixel. The trace stage's
//! secondary rays ([`PointCloudCapsule::closest_surface`], [`PointCloudCapsule::occluded`])
//! always use the BVH.

use std::time::Instant;

use glam::Vec3;
use hybrid_core::Surface;
use hybrid_core::depth_merge::{MISS_TEXEL, PackedRtFrame, encode_hit};
use hybrid_core::point_colors::PointColors;
use hybrid_core::shading::FrameLights;
use hybrid_scene::{Camera, Environment, Lights, PointCloud};
use rayon::prelude::*;

use crate::camera_rays::{PrimaryRay, RayGen};
use crate::spheres::{BatchRay, BatchScratch, SphereBvh, SphereBvhError, TraversalStack};

mod projected;

pub use hybrid_core::depth_merge::CapsuleStats;

/// What the host asks of the capsule each frame. `clip_depth` (optional, beyond the paper) is the
/// raster's reversed-Z depth per pixel (row-major, 0 = nothing drawn): rays stop at the raster
/// surface, since anything behind it would lose the depth test anyway.
#[derive(Debug, Clone, Copy)]
pub struct CapsuleRequest<'a> {
    pub camera: Camera,
    pub width: u32,
    pub height: u32,
    pub clip_depth: Option<&'a [f32]>,
}

/// A ray-tracing plug-in producing a packed RT frame (blocks D and P inside).
pub trait RtCapsule: Send {
    /// Renders `request` into `out` (resized to the request; misses all zero).
    fn render(&mut self, request: &CapsuleRequest<'_>, out: &mut PackedRtFrame) -> CapsuleStats;
}

/// The exchange without a thread: host finished → capsule renders → capsule finished.
pub fn render_sync(capsule: &mut dyn RtCapsule, request: &CapsuleRequest<'_>) -> (PackedRtFrame, CapsuleStats) {
    let mut frame = PackedRtFrame::new(request.width, request.height);
    let stats = capsule.render(request, &mut frame);
    (frame, stats)
}

/// Why a capsule could not be built.
#[derive(Debug, Clone, PartialEq)]
pub struct CapsuleError {
    pub cloud: String,
    pub error: SphereBvhError,
}

impl std::fmt::Display for CapsuleError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "point cloud `{}`: {}", self.cloud, self.error)
    }
}

impl std::error::Error for CapsuleError {}

struct Cloud {
    bvh: SphereBvh,
    color: PointColors,
    specular: Vec3,
    shininess: f32,
}

impl Cloud {
    #[inline]
    fn albedo(&self, slot: u32, center: Vec3) -> Vec3 {
        self.color.albedo(self.bvh.index_of_slot(slot) as usize, center)
    }
}

thread_local! {
    /// Traversal stack for trace-stage queries (one per worker thread, no allocation per ray).
    static SECONDARY_STACK: std::cell::RefCell<TraversalStack> = std::cell::RefCell::new(TraversalStack::default());
    /// A worker's buffers for the projected primary rays' bands (taken out for a band, put back
    /// after it).
    static BAND_SCRATCH: std::cell::Cell<projected::BandScratch> = std::cell::Cell::new(projected::BandScratch::default());
}

/// How the capsule finds each primary ray's closest sphere. All give the same frame, bit for bit
/// (the closest hit over all spheres, ties to the lower point index); only the speed differs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PrimaryVisibility {
    /// [`PrimaryVisibility::Projected`] when the clouds hold at most
    /// [`AUTO_POINTS_PER_PIXEL`] points per pixel of the request, else [`PrimaryVisibility::Bvh`]
    /// (measured on the 1M-point scan at 1920×1080: projection 2.2× faster at 0.5 points per
    /// pixel; ten copies of it, 5 points per pixel mostly under a pixel each: traversal 1.6×
    /// faster).
    #[default]
    Auto,
    /// Every sphere's bounds projected to a pixel rectangle and filed by band of rows; each ray
    /// tested only against the spheres over its pixel (module `projected`). Costs one projection
    /// per sphere in view, hidden ones included, and a few ray tests per pixel a sphere covers:
    /// fastest when spheres are few per pixel and a few pixels wide.
    Projected,
    /// Each 8×8 tile's rays traced through the sphere BVH from the tile's shared cut (paper 2's
    /// traversal, as RT cores or Embree do). Costs grow with rays and tree depth, not with the
    /// spheres in view: better for many more spheres than pixels.
    Bvh,
}

/// Points per pixel up to which [`PrimaryVisibility::Auto`] projects.
pub const AUTO_POINTS_PER_PIXEL: f64 = 2.0;

/// The point-cloud capsule: spheres traced through their own BVH, Blinn–Phong shaded with the
/// scene's lights and ambient, packed with their synthesized depth.
pub struct PointCloudCapsule {
    clouds: Vec<Cloud>,
    /// How primary rays find their sphere (the frame is the same either way).
    pub primary_visibility: PrimaryVisibility,
    /// Per-cloud bins of the projected path, kept between frames for their allocations.
    bins: Vec<projected::CloudBins>,
    /// The scene's lights and ambient, with their per-frame constants (as `local_lighting`, bit
    /// for bit).
    lights: FrameLights,
    build_ms: f64,
    points: u64,
}

impl PointCloudCapsule {
    /// Builds one sphere BVH per cloud (each cloud keeps its own radius).
    pub fn new(clouds: &[PointCloud], lights: Lights, env: Environment) -> Result<Self, CapsuleError> {
        let start = Instant::now();
        let mut built = Vec::with_capacity(clouds.len());
        for pc in clouds {
            let bvh = SphereBvh::build(&pc.points, pc.radius).map_err(|error| CapsuleError { cloud: pc.name.clone(), error })?;
            let color = PointColors::of(pc);
            built.push(Cloud { bvh, color, specular: pc.specular, shininess: pc.shininess });
        }
        let points = clouds.iter().map(|c| c.points.len() as u64).sum();
        Ok(Self {
            clouds: built,
            primary_visibility: PrimaryVisibility::default(),
            bins: Vec::new(),
            lights: FrameLights::new(&lights, &env),
            build_ms: start.elapsed().as_secs_f64() * 1e3,
            points,
        })
    }

    /// Bytes of the BVHs, sphere centres and colours.
    pub fn bytes(&self) -> usize {
        self.clouds.iter().map(|c| c.bvh.bytes() + if let PointColors::File(v) = &c.color { v.len() * 3 } else { 0 }).sum()
    }

    pub fn build_ms(&self) -> f64 {
        self.build_ms
    }

    /// Traces one primary ray: `Some((linear colour, t))` of the closest sphere before `t_max`.
    #[inline]
    /// The nearest sphere over all clouds: (t, cloud index, BVH slot).
    fn closest_slot(&self, stack: &mut TraversalStack, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, usize, u32)> {
        let mut best: Option<(f32, usize, u32)> = None;
        let mut limit = t_max;
        for (ci, cloud) in self.clouds.iter().enumerate() {
            if let Some((t, slot)) = cloud.bvh.closest_hit_slot_with(stack, origin, dir, t_min, limit)
                && best.is_none_or(|b| t < b.0)
            {
                best = Some((t, ci, slot));
                limit = t;
            }
        }
        best
    }

    /// The surface of sphere `slot` of cloud `ci` at `position`, hit by a ray along `dir`: the
    /// shading inputs the capsule uses (albedo as diffuse and ambient, the cloud's specular).
    fn sphere_surface(&self, ci: usize, slot: u32, position: Vec3, dir: Vec3) -> Surface {
        self.sphere_surface_at(ci, slot, self.clouds[ci].bvh.center_of_slot(slot), position, dir)
    }

    /// [`PointCloudCapsule::sphere_surface`] given the sphere's centre.
    #[inline]
    fn sphere_surface_at(&self, ci: usize, slot: u32, center: Vec3, position: Vec3, dir: Vec3) -> Surface {
        let cloud = &self.clouds[ci];
        let normal = ((position - center) / cloud.bvh.radius()).normalize_or(-dir);
        let albedo = cloud.albedo(slot, center);
        Surface {
            position,
            normal,
            diffuse: albedo,
            ambient: albedo,
            opacity: 1.0,
            specular: cloud.specular,
            shininess: cloud.shininess,
            ior: 1.0,
            ..Default::default()
        }
    }

    /// Beyond paper 2: the spheres as geometry of the trace stage. The closest sphere along a
    /// ray within (`t_min`, `t_max`) and its surface, so reflections and refractions show the
    /// point cloud.
    pub fn closest_surface(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<(f32, Surface)> {
        SECONDARY_STACK.with_borrow_mut(|stack| {
            let (t, ci, slot) = self.closest_slot(stack, origin, dir, t_min, t_max)?;
            Some((t, self.sphere_surface(ci, slot, origin + dir * t, dir)))
        })
    }

    /// Beyond paper 2: whether any sphere blocks a shadow ray (spheres are opaque casters).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> bool {
        SECONDARY_STACK.with_borrow_mut(|stack| self.clouds.iter().any(|cloud| cloud.bvh.any_hit_with(stack, origin, dir, t_min, t_max)))
    }

    /// [`PointCloudCapsule::closest_slot`] for a batch of rays (one tile's primary rays): the
    /// clouds in turn, each through [`SphereBvh::closest_hits_batch`], each ray's `t_max` shrinking
    /// to its hit; `best[i]` is exactly `closest_slot` of `rays[i]`.
    fn closest_slots_batch(
        &self,
        scratch: &mut BatchScratch,
        stack: &mut TraversalStack,
        rays: &mut [BatchRay],
        found: &mut Vec<Option<(f32, u32)>>,
        best: &mut [Option<(f32, usize, u32)>],
    ) {
        best.fill(None);
        found.resize(rays.len(), None);
        for (ci, cloud) in self.clouds.iter().enumerate() {
            cloud.bvh.closest_hits_batch(scratch, stack, rays, found);
            for ((hit, ray), b) in found.iter().zip(rays.iter_mut()).zip(best.iter_mut()) {
                if let Some((t, slot)) = *hit
                    && b.is_none_or(|b| t < b.0)
                {
                    *b = Some((t, ci, slot));
                    ray.t_max = t;
                }
            }
        }
    }

    /// The shaded colour of sphere `slot` of cloud `ci` hit at `t` along `ray`.
    fn shade_hit(&self, ray: &PrimaryRay, t: f32, ci: usize, slot: u32) -> Vec3 {
        self.shade_hit_at(ray, t, ci, slot, self.clouds[ci].bvh.center_of_slot(slot))
    }

    /// [`PointCloudCapsule::shade_hit`] given the sphere's centre.
    #[inline]
    fn shade_hit_at(&self, ray: &PrimaryRay, t: f32, ci: usize, slot: u32, center: Vec3) -> Vec3 {
        let s = self.sphere_surface_at(ci, slot, center, ray.origin + ray.dir * t, ray.dir);
        self.lights.local_lighting(&s, -ray.dir)
    }
}

impl RtCapsule for PointCloudCapsule {
    fn render(&mut self, request: &CapsuleRequest<'_>, out: &mut PackedRtFrame) -> CapsuleStats {
        let (w, h) = (request.width, request.height);
        out.reset(w, h);
        let start = Instant::now();
        let raygen = RayGen::new(&request.camera, w, h);
        let n = w as usize * h as usize;
        let clip = request.clip_depth.filter(|c| {
            let ok = c.len() == n;
            if !ok {
                tracing::warn!("clip depth has {} values for {n} pixels; tracing unclipped", c.len());
            }
            ok
        });
        let hits = if w == 0 {
            0
        } else if self.resolved_visibility(w, h) == PrimaryVisibility::Projected {
            self.render_projected(request, &raygen, clip, out)
        } else {
            self.render_bvh(&raygen, clip, out)
        };
        CapsuleStats {
            points: self.points,
            build_ms: self.build_ms,
            trace_ms: start.elapsed().as_secs_f64() * 1e3,
            pack_ms: 0.0,
            rays: n as u64,
            hits: hits as u64,
            bytes: self.bytes() as u64,
        }
    }
}

impl PointCloudCapsule {
    /// What [`PointCloudCapsule::primary_visibility`] means for a `w × h` request: `Projected` or
    /// `Bvh` (also `Bvh` for images wider or taller than the bins address).
    pub fn resolved_visibility(&self, w: u32, h: u32) -> PrimaryVisibility {
        let fits = w <= projected::MAX_SIDE && h <= projected::MAX_SIDE;
        let projected = match self.primary_visibility {
            PrimaryVisibility::Auto => self.points as f64 <= AUTO_POINTS_PER_PIXEL * w as f64 * h as f64,
            PrimaryVisibility::Projected => true,
            PrimaryVisibility::Bvh => false,
        };
        if projected && fits { PrimaryVisibility::Projected } else { PrimaryVisibility::Bvh }
    }

    /// Pixel `(col, row)`'s ray `t_max`, clipped at the raster's depth there when `clip` is given.
    #[inline]
    fn clipped_t_max(raygen: &RayGen, ray: &PrimaryRay, clip: Option<&[f32]>, pixel: usize) -> f32 {
        let mut t_max = ray.t_max;
        if let Some(c) = clip {
            let z = c[pixel];
            if z > 0.0 {
                t_max = t_max.min(raygen.t_at_depth(ray, z));
            }
        }
        t_max
    }

    /// [`PrimaryVisibility::Bvh`]: the frame's texels, returning the number of hits.
    fn render_bvh(&self, raygen: &RayGen, clip: Option<&[f32]>, out: &mut PackedRtFrame) -> usize {
        let this = self;
        let w = out.width;
        // Bands of `BAND` rows, one rayon task each (`with_max_len(1)`: ray cost is uneven,
        // KNOWN-GOOD gotcha 12), traced in `TILE`×`TILE` tiles, each one batch of
        // `SphereBvh::closest_hits_batch` (8×8 measured a little faster than 16×16: a narrower
        // frustum gives a deeper cut). Each pixel's ray is the same.
        const BAND: usize = 16;
        const TILE: usize = 8;
        let wu = w as usize;
        // Each pixel's ray is `raygen.ray(col, row)`; the per-column and per-row halves once.
        let view_x: Vec<f32> = (0..w).map(|c| raygen.view_x(c)).collect();
        let view_x = &view_x;
        out.texels
            .par_chunks_mut(wu * BAND)
            .with_max_len(1)
            .enumerate()
            .map(|(band, texels)| {
                let mut hits = 0;
                let mut stack = TraversalStack::default();
                let mut scratch = BatchScratch::default();
                let mut rays = Vec::with_capacity(TILE * TILE);
                let mut batch = Vec::with_capacity(TILE * TILE);
                let mut found = Vec::with_capacity(TILE * TILE);
                let mut best = Vec::with_capacity(TILE * TILE);
                let rows = texels.len() / wu;
                let view_y: Vec<f32> = (0..rows).map(|r| raygen.view_y((band * BAND + r) as u32)).collect();
                for (row0, col0) in (0..rows).step_by(TILE).flat_map(|r| (0..wu).step_by(TILE).map(move |c| (r, c))) {
                    let cols = col0..(col0 + TILE).min(wu);
                    let tile_rows = row0..(row0 + TILE).min(rows);
                    rays.clear();
                    batch.clear();
                    for r in tile_rows.clone() {
                        let row = band * BAND + r;
                        for col in cols.clone() {
                            let ray = raygen.ray_at(view_x[col], view_y[r]);
                            let t_max = Self::clipped_t_max(raygen, &ray, clip, row * wu + col);
                            rays.push(ray);
                            batch.push(BatchRay { origin: ray.origin, dir: ray.dir, t_min: ray.t_min, t_max });
                        }
                    }
                    // The tile's rays as one batch (they share the eye: the tree's levels above
                    // the tile's frustum are skipped), then shaded in the same order.
                    best.resize(rays.len(), None);
                    this.closest_slots_batch(&mut scratch, &mut stack, &mut batch, &mut found, &mut best);
                    let mut i = 0;
                    for r in tile_rows.clone() {
                        for col in cols.clone() {
                            let ray = &rays[i];
                            texels[r * wu + col] = match best[i] {
                                Some((t, ci, slot)) => {
                                    hits += 1;
                                    // Block D then block P, fused as in the paper's ray-generation shader.
                                    encode_hit(this.shade_hit(ray, t, ci, slot), raygen.depth(ray, t))
                                }
                                None => MISS_TEXEL,
                            };
                            i += 1;
                        }
                    }
                }
                hits
            })
            .sum()
    }

    /// [`PrimaryVisibility::Projected`]: the frame's texels, returning the number of hits. Each
    /// pixel's ray, limits and shading are those of [`PointCloudCapsule::render_bvh`].
    fn render_projected(&mut self, request: &CapsuleRequest<'_>, raygen: &RayGen, clip: Option<&[f32]>, out: &mut PackedRtFrame) -> usize {
        let (w, h) = (request.width, request.height);
        self.bins.resize_with(self.clouds.len(), Default::default);
        // With a clip depth, spheres behind the raster surface are not even filed.
        let far = clip.map(|c| projected::FarDepth::new(c, &request.camera, w, h));
        for (bins, cloud) in self.bins.iter_mut().zip(&self.clouds) {
            bins.bin(&cloud.bvh, &request.camera, w, h, far.as_ref());
        }
        let this = &*self;
        let wu = w as usize;
        let view_x: Vec<f32> = (0..w).map(|c| raygen.view_x(c)).collect();
        let view_x = &view_x;
        // Every perspective ray starts at the eye, exactly ([`RayGen::ray_at`]).
        let shared_origin = (!raygen.ortho).then_some(raygen.eye);
        out.texels
            .par_chunks_mut(wu * projected::BAND_ROWS)
            .with_max_len(1)
            .enumerate()
            .map(|(band, texels)| {
                // The worker's band buffers, reused from band to band and frame to frame (a
                // rayon `map_init` value lives for one task only: here, one band).
                let mut scratch = BAND_SCRATCH.take();
                let s = &mut scratch;
                let rows = texels.len() / wu;
                let row0 = band * projected::BAND_ROWS;
                let view_y: Vec<f32> = (0..rows).map(|r| raygen.view_y((row0 + r) as u32)).collect();
                let primary = |row: usize, col: usize| raygen.ray_at(view_x[col], view_y[row]);
                s.begin(texels.len());
                for (ci, cloud) in this.clouds.iter().enumerate() {
                    s.trace_cloud(&this.bins[ci], &cloud.bvh, ci, band, (wu, rows), shared_origin, |(row, col), limit| {
                        let ray = primary(row, col);
                        let t_max = limit.unwrap_or_else(|| Self::clipped_t_max(raygen, &ray, clip, (row0 + row) * wu + col));
                        cloud.bvh.prepare_ray(ray.origin, ray.dir, ray.t_min, t_max)
                    });
                }
                let mut hits = 0;
                for (row, (texels, best)) in texels.chunks_mut(wu).zip(s.best.chunks(wu)).enumerate() {
                    for (col, (texel, best)) in texels.iter_mut().zip(best).enumerate() {
                        if let Some((t, ci, slot, center)) = *best {
                            hits += 1;
                            let ray = primary(row, col);
                            // Block D then block P, as in the BVH path.
                            *texel = encode_hit(this.shade_hit_at(&ray, t, ci, slot, center), raygen.depth(&ray, t));
                        }
                    }
                }
                BAND_SCRATCH.set(scratch);
                hits
            })
            .sum()
    }
}
