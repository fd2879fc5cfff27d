//! Primary visibility by projection (beyond paper 2, which traverses a BVH per ray): the capsule's
//! rays all leave one pinhole (or one image plane, orthographic), so the pixels whose ray can hit a
//! sphere are known before any ray is traced: those inside the sphere's projected bounds.
//!
//! Per frame and cloud, [`CloudBins::bin`] projects every sphere's bounding cone to a pixel
//! rectangle (exact tangent slopes, padded by [`PAD_PX`]) and files the sphere under each band of
//! [`BAND_ROWS`] rows the rectangle touches. Per band, [`BandScratch::trace_cloud`] then tests
//! each binned sphere against the rays of the pixels in its rectangle, four pixels at a time, with
//! the BVH's own exact ray–sphere test ([`sphere_hits4`]) and its tie rule (lower original index),
//! and keeps the closest hit per pixel. The result is the closest hit over all spheres (brute
//! force), so exactly what [`SphereBvh::closest_hit_slot_with`] returns for the same ray; a test
//! compares whole frames bit for bit.
//!
//! Work skipped without changing the result: a pixel's ray is made only when a sphere first
//! covers it; the bins are taken nearest run of spheres first, and a sphere skips four pixels
//! whose closest hits are all nearer than it can be; with a clip depth ([`FarDepth`]), spheres
//! behind the raster surface of every tile they touch are not filed at all.
//!
//! The trade-off: no BVH nodes are visited and no ray is set up for a pixel that no sphere covers,
//! but every sphere in the view frustum is projected and tested, hidden ones included (a BVH ray
//! stops at its first hit). It wins when the spheres are small on screen (a few pixels each, as
//! a scan of millions of points is); a cloud of a few large spheres that fill the screen is better
//! served by the BVH ([`super::PrimaryVisibility::Bvh`]).

use glam::{BVec4, BVec4A, Mat3, UVec4, Vec3, Vec4};
use hybrid_core::depth_merge::{view_z_from_depth, view_z_from_depth_orthographic};
use hybrid_scene::Camera;
use rayon::prelude::*;

use crate::spheres::{PreparedRay, SphereBvh, sphere_hits4};

/// Rows per band: the unit of binning and of parallel work. Higher values file fewer spheres
/// under two bands at the cost of a larger per-band working set.
pub(super) const BAND_ROWS: usize = 8;
/// Spheres per binning task.
const BIN_CHUNK: usize = 4 * 1024;
/// Fixed margin in pixels around a sphere's projected bounds. The bounds are exact up to f32
/// rounding of the slopes (relative 10⁻⁶, a thousandth of a pixel at 1920 columns), as is each
/// ray's direction, so a tenth of a pixel is ample; the rounding of positions, which grows with
/// the scene's coordinates, gets its own margin ([`Projector::new`]). A larger margin only adds
/// tests.
const PAD_PX: f32 = 0.1;
/// Spheres whose centre is nearer the camera plane than this many radii (only possible when the
/// radius is a large part of the near distance) get the whole screen as bounds: the tangent
/// slopes lose precision there, and a sphere that close covers much of the screen anyway.
const WIDE_RADII: f32 = 1.5;
/// A sphere entirely nearer than the near plane or farther than the far plane, by this fraction
/// of the plane's distance plus the radius, is culled (no ray's `t` range reaches it).
const DEPTH_SLACK: f32 = 1e-2;

/// Relative margin of a sphere's nearest possible hit distance (its computed `t` can be a few
/// ulps below the exact one).
const NEAREST_SLACK: f32 = 1e-5;

/// Largest image side the bins can address.
pub(super) const MAX_SIDE: u32 = u16::MAX as u32;

/// One sphere filed under a band: its leaf-order slot, centre and inclusive pixel rectangle.
#[derive(Debug, Clone, Copy, Default)]
struct Binned {
    c: Vec3,
    slot: u32,
    x0: u16,
    x1: u16,
    y0: u16,
    y1: u16,
}

/// World → pixel constants of one frame, for spheres of radius `r`.
#[derive(Debug, Clone, Copy)]
struct Projector {
    /// World → view rotation.
    rot: Mat3,
    eye: Vec3,
    /// The projection's x and y scales (`P₀₀`, `P₁₁`): view-plane x · `sx` = NDC x.
    sx: f32,
    sy: f32,
    half_w: f32,
    half_h: f32,
    max_x: f32,
    max_y: f32,
    near_cull: f32,
    far_cull: f32,
    ortho: bool,
    r: f32,
    /// Margin in pixels per unit of view-plane error at depth 1 (perspective; the error of a
    /// position, in world units, times the pixels per view-plane unit).
    position_px: f32,
}

impl Projector {
    /// `extent`: the largest coordinate magnitude of the spheres' centres.
    fn new(camera: &Camera, w: u32, h: u32, r: f32, extent: f32) -> Self {
        let p = camera.projection(w.max(1) as f32 / h.max(1) as f32);
        let (near, far) = camera.near_far();
        let (half_w, half_h) = (w as f32 * 0.5, h as f32 * 0.5);
        // Ray and projector each round a position by a few ulps of the coordinates involved
        // (centre − eye, its rotation, the ray test's projection on the ray): 8 machine epsilons
        // of |centre| + |eye| (each up to √3 × its largest coordinate) bounds their sum twice over.
        let magnitude = 1.75 * (extent + camera.position.abs().max_element()) + r;
        let position_error = 8.0 * f32::EPSILON * magnitude;
        Self {
            rot: Mat3::from_mat4(camera.view()),
            eye: camera.position,
            sx: p.x_axis.x,
            sy: p.y_axis.y,
            half_w,
            half_h,
            max_x: w.saturating_sub(1) as f32,
            max_y: h.saturating_sub(1) as f32,
            near_cull: near - DEPTH_SLACK * (near.abs() + r),
            far_cull: far + DEPTH_SLACK * (far.abs() + r),
            ortho: camera.is_orthographic(),
            r,
            position_px: position_error * (p.x_axis.x.abs() * half_w).max(p.y_axis.y.abs() * half_h),
        }
    }

    /// The inclusive pixel rectangle `[x0, x1, y0, y1]` holding every pixel whose primary ray
    /// (pixel centre, [`super::RayGen`]) may hit the sphere at `c`; `None` when there is none.
    #[cfg(test)]
    fn rect(&self, c: Vec3) -> Option<[u16; 4]> {
        self.rects4(Vec4::splat(c.x), Vec4::splat(c.y), Vec4::splat(c.z))[0].map(|(r, _)| r)
    }

    /// [`Projector::rect`] of four spheres at once (their centres' coordinates as lanes), each
    /// with the view depth of the sphere's nearest point.
    #[inline]
    fn rects4(&self, cx: Vec4, cy: Vec4, cz: Vec4) -> [Option<([u16; 4], f32)>; 4] {
        let splat = Vec4::splat;
        let (px, py, pz) = (cx - splat(self.eye.x), cy - splat(self.eye.y), cz - splat(self.eye.z));
        let (ax, ay, az) = (self.rot.x_axis, self.rot.y_axis, self.rot.z_axis);
        let vx = splat(ax.x) * px + splat(ay.x) * py + splat(az.x) * pz;
        let vy = splat(ax.y) * px + splat(ay.y) * py + splat(az.y) * pz;
        let dz = -(splat(ax.z) * px + splat(ay.z) * py + splat(az.z) * pz);
        let r = splat(self.r);
        let kept = ((dz + r).cmpge(splat(self.near_cull)) & (dz - r).cmple(splat(self.far_cull))).bitmask();
        if kept == 0 {
            return [None; 4];
        }
        // View-plane bounds: x/z and y/z of the sphere's tangent planes through the eye (the
        // sphere projected on the xz or yz plane is a disc of radius r; the slopes m of the lines
        // through the origin tangent to it solve (a − m·dz)² = r²(1 + m²)); orthographic: ± r.
        let (xl, xh, yl, yh, pad) = if self.ortho {
            (vx - r, vx + r, vy - r, vy + r, splat(PAD_PX + self.position_px))
        } else {
            let k = dz * dz - r * r;
            let inv_k = Vec4::ONE / k;
            let (sx, sy) = ((vx * vx + k).sqrt(), (vy * vy + k).sqrt());
            let (bx, by) = (vx * dz, vy * dz);
            // Too near the camera plane for the slopes: the whole screen.
            let wide = dz.cmple(splat(WIDE_RADII * self.r));
            let (lo, hi) = (splat(f32::NEG_INFINITY), splat(f32::INFINITY));
            (
                Vec4::select(wide, lo, (bx - r * sx) * inv_k),
                Vec4::select(wide, hi, (bx + r * sx) * inv_k),
                Vec4::select(wide, lo, (by - r * sy) * inv_k),
                Vec4::select(wide, hi, (by + r * sy) * inv_k),
                // dz/k ≥ 1/dz: a position error δ moves a slope by at most δ/dz.
                splat(PAD_PX) + splat(self.position_px) * (dz * inv_k).abs(),
            )
        };
        // Pixel-centre coordinates (RayGen: view x = (2(col + ½)/w − 1)/sx, view y = (1 − 2(row + ½)/h)/sy).
        let col = |x: Vec4| (x * splat(self.sx) + Vec4::ONE) * splat(self.half_w) - splat(0.5);
        let row = |y: Vec4| (Vec4::ONE - y * splat(self.sy)) * splat(self.half_h) - splat(0.5);
        let (x0, x1) = pixel_spans4(col(xl), col(xh), pad, self.max_x);
        let (y0, y1) = pixel_spans4(row(yl), row(yh), pad, self.max_y);
        let on_screen = kept & (x0.cmple(x1) & y0.cmple(y1)).bitmask();
        let (x0, x1, y0, y1) = (x0.to_array(), x1.to_array(), y0.to_array(), y1.to_array());
        let nearest = (dz - r).to_array();
        std::array::from_fn(|lane| {
            // Whole numbers in [0, 65535]: the casts are exact.
            (on_screen & (1 << lane) != 0).then(|| ([x0[lane] as u16, x1[lane] as u16, y0[lane] as u16, y1[lane] as u16], nearest[lane]))
        })
    }
}

/// Per lane, the whole numbers within `pad` of the interval between `a` and `b` (either order),
/// clamped to `[0, max]`: `(first, last)` as floats, empty when first > last. A NaN bound or pad
/// (not computable) gives the whole `[0, max]`. No library calls: the bounds are clamped to
/// `[0, max + 1]` (`max` < 2²²; an interval below 0 is marked empty first) and rounded by adding
/// and removing 2²³, exact for such values.
#[inline(always)]
fn pixel_spans4(a: Vec4, b: Vec4, pad: Vec4, max: f32) -> (Vec4, Vec4) {
    let splat = Vec4::splat;
    let nan = a.cmpne(a) | b.cmpne(b) | pad.cmpne(pad);
    let lo = Vec4::select(nan, Vec4::ZERO, a.min(b) - pad);
    let hi = Vec4::select(nan, splat(max), a.max(b) + pad);
    let below = hi.cmplt(Vec4::ZERO);
    let (lo, hi) = (lo.clamp(Vec4::ZERO, splat(max + 1.0)), hi.clamp(Vec4::ZERO, splat(max + 1.0)));
    const BIG: f32 = 8_388_608.0;
    let (rl, rh) = ((lo + splat(BIG)) - splat(BIG), (hi + splat(BIG)) - splat(BIG));
    let first = Vec4::select(rl.cmplt(lo), rl + Vec4::ONE, rl);
    let last = Vec4::select(rh.cmpgt(hi), rh - Vec4::ONE, rh);
    (first, Vec4::select(below, splat(-1.0), last.min(splat(max))))
}

/// Pixels per side of a [`FarDepth`] tile.
const FAR_TILE: usize = 8;

/// The farthest raster surface per 8×8-pixel tile, as view depth (+∞ where some pixel has nothing
/// drawn), from the clip depth of a clipped capsule request: a sphere whose nearest point lies
/// beyond it in every tile its rectangle touches cannot be hit by those pixels' clipped rays
/// (their `t_max` ends at the raster surface), so it is not filed.
#[derive(Debug, Default)]
pub(super) struct FarDepth {
    tiles_x: usize,
    depth: Vec<f32>,
}

impl FarDepth {
    /// `clip`: reversed-Z depth per pixel, row-major `w × h` (> 0: a surface; else nothing).
    pub(super) fn new(clip: &[f32], camera: &Camera, w: u32, h: u32) -> Self {
        let (w, h) = (w as usize, h as usize);
        let tiles_x = w.div_ceil(FAR_TILE);
        let (near, far) = camera.near_far();
        let ortho = camera.is_orthographic();
        let mut depth = vec![0.0f32; tiles_x * h.div_ceil(FAR_TILE)];
        depth.par_chunks_mut(tiles_x).enumerate().for_each(|(ty, tiles)| {
            // Reversed-Z: the farthest surface has the smallest depth; a pixel with nothing drawn
            // (or a depth that is not a number) counts as 0, which culls nothing.
            tiles.fill(f32::INFINITY);
            for row in clip.chunks(w).skip(ty * FAR_TILE).take(FAR_TILE) {
                for (x, &z) in row.iter().enumerate() {
                    let t = &mut tiles[x / FAR_TILE];
                    *t = t.min(if z > 0.0 { z } else { 0.0 });
                }
            }
            for t in tiles.iter_mut() {
                *t = if *t > 0.0 && t.is_finite() {
                    let z_e = if ortho { view_z_from_depth_orthographic(*t, near, far) } else { view_z_from_depth(*t, near, far) };
                    // A relative margin far above the rounding of the rays' clipped `t_max`.
                    -z_e * (1.0 + DEPTH_SLACK)
                } else {
                    f32::INFINITY
                };
            }
        });
        Self { tiles_x, depth }
    }

    /// Whether a sphere whose nearest point has view depth `nearest`, with pixel rectangle `rect`,
    /// lies beyond the raster surface in every tile the rectangle touches.
    #[inline]
    fn hides(&self, [x0, x1, y0, y1]: [u16; 4], nearest: f32) -> bool {
        let (tx0, tx1) = (x0 as usize / FAR_TILE, x1 as usize / FAR_TILE);
        (y0 as usize / FAR_TILE..=y1 as usize / FAR_TILE)
            .all(|ty| self.depth[ty * self.tiles_x + tx0..=ty * self.tiles_x + tx1].iter().all(|&d| nearest > d))
    }
}

/// One cloud's spheres filed by band for one frame (kept between frames for its allocations).
#[derive(Debug, Default)]
pub(super) struct CloudBins {
    chunks: Vec<ChunkBins>,
    /// Chunk indices, nearest first (by their nearest filed sphere): each band takes its spheres
    /// about front to back, so more of them find their pixels already nearer and skip them.
    order: Vec<usize>,
    band_rows: usize,
}

/// The bins of one task's run of spheres (leaf-order slots `k·BIN_CHUNK ..`).
#[derive(Debug, Default)]
struct ChunkBins {
    /// The run's spheres with a rectangle on screen, in slot order.
    rects: Vec<Binned>,
    /// `rects` grouped by band (a sphere under each band it touches): band b's are
    /// `records[start[b]..start[b + 1]]`.
    records: Vec<Binned>,
    start: Vec<u32>,
    cursor: Vec<u32>,
    /// The smallest view depth of a filed sphere's nearest point (+∞ when none is filed).
    nearest: f32,
}

impl CloudBins {
    /// Projects and files every sphere of `bvh` for `camera` at `w × h` (bands of [`BAND_ROWS`]),
    /// but those entirely behind the raster surface `far` gives (clipped rays stop there).
    pub(super) fn bin(&mut self, bvh: &SphereBvh, camera: &Camera, w: u32, h: u32, far: Option<&FarDepth>) {
        let (lo, hi) = bvh.bounds();
        let proj = Projector::new(camera, w, h, bvh.radius(), lo.abs().max(hi.abs()).max_element());
        let n = bvh.len();
        let (xs, ys, zs) = bvh.centers_soa();
        let bands = (h as usize).div_ceil(BAND_ROWS);
        self.band_rows = BAND_ROWS;
        let n_chunks = n.div_ceil(BIN_CHUNK);
        self.chunks.truncate(n_chunks);
        self.chunks.resize_with(n_chunks, ChunkBins::default);
        self.chunks.par_iter_mut().enumerate().with_max_len(1).for_each(|(k, ch)| {
            let slots = k * BIN_CHUNK..((k + 1) * BIN_CHUNK).min(n);
            ch.rects.clear();
            ch.nearest = f32::INFINITY;
            ch.start.clear();
            ch.start.resize(bands + 1, 0);
            // Four slots at a time (the centre arrays are padded past the last sphere).
            for first in slots.clone().step_by(4) {
                let load = |v: &[f32]| Vec4::from_slice(&v[first..first + 4]);
                let rects = proj.rects4(load(xs), load(ys), load(zs));
                for (lane, rect) in rects.into_iter().enumerate().take(slots.end - first) {
                    let Some(([x0, x1, y0, y1], nearest)) = rect else { continue };
                    if far.is_some_and(|f| f.hides([x0, x1, y0, y1], nearest)) {
                        continue;
                    }
                    ch.nearest = ch.nearest.min(nearest);
                    let slot = first + lane;
                    ch.rects.push(Binned { c: Vec3::new(xs[slot], ys[slot], zs[slot]), slot: slot as u32, x0, x1, y0, y1 });
                    for b in y0 as usize / BAND_ROWS..=y1 as usize / BAND_ROWS {
                        ch.start[b + 1] += 1;
                    }
                }
            }
            for b in 0..bands {
                ch.start[b + 1] += ch.start[b];
            }
            ch.records.resize(ch.start[bands] as usize, Binned::default());
            ch.cursor.clear();
            ch.cursor.extend_from_slice(&ch.start[..bands]);
            for rect in &ch.rects {
                for b in rect.y0 as usize / BAND_ROWS..=rect.y1 as usize / BAND_ROWS {
                    ch.records[ch.cursor[b] as usize] = *rect;
                    ch.cursor[b] += 1;
                }
            }
        });
        self.order.clear();
        self.order.extend(0..n_chunks);
        self.order.sort_by(|&a, &b| self.chunks[a].nearest.total_cmp(&self.chunks[b].nearest));
    }

    /// The spheres filed under band `band`, chunk by chunk nearest first.
    fn band(&self, band: usize) -> impl Iterator<Item = &Binned> {
        self.order.iter().map(|&k| &self.chunks[k]).flat_map(move |ch| match (ch.start.get(band), ch.start.get(band + 1)) {
            (Some(&a), Some(&b)) => &ch.records[a as usize..b as usize],
            _ => &[],
        })
    }

    /// Spheres filed (a sphere once per band it touches).
    #[cfg(test)]
    fn filed(&self) -> usize {
        self.chunks.iter().map(|c| c.records.len()).sum()
    }
}

/// No sphere (in `best_slot`).
const NONE: u32 = u32::MAX;

/// A band worker's buffers: the band's prepared rays as structure of arrays (so four neighbouring
/// pixels load as one vector each) and the closest hit per pixel over the clouds done so far.
#[derive(Debug, Default)]
pub(super) struct BandScratch {
    /// Whether the pixel's ray for the current cloud is made.
    ready: Vec<bool>,
    o: [Vec<f32>; 3],
    d: [Vec<f32>; 3],
    t_min: Vec<f32>,
    t_max: Vec<f32>,
    len: Vec<f32>,
    best_t: Vec<f32>,
    best_slot: Vec<u32>,
    /// The closest sphere's centre per pixel (from its record: shading then reads no centre
    /// array at a random slot).
    best_c: [Vec<f32>; 3],
    /// Per pixel: (t in the primary ray's units, cloud, slot, centre) of the closest sphere so far.
    pub(super) best: Vec<Option<(f32, usize, u32, Vec3)>>,
}

impl BandScratch {
    /// Starts a band of `pixels` pixels: no hit anywhere.
    pub(super) fn begin(&mut self, pixels: usize) {
        self.best.clear();
        self.best.resize(pixels, None);
        // Four-lane loads start at any covered pixel: three pixels of padding.
        let padded = pixels + 3;
        for v in self.o.iter_mut().chain(self.d.iter_mut()).chain(self.best_c.iter_mut()).chain([
            &mut self.t_min,
            &mut self.t_max,
            &mut self.len,
            &mut self.best_t,
        ]) {
            v.resize(padded, 0.0);
        }
        self.best_slot.resize(padded, NONE);
    }

    /// Cloud `ci` (its `bins` and `bvh`) over band `band` (`rows` rows of `w` pixels): each pixel
    /// whose ray one of the cloud's spheres may hit gets its ray from `prepare((row in band,
    /// column), t so far)` (`None`: no ray) when a sphere first covers it, and `best` takes the
    /// cloud's closest hit where it is nearer than the clouds' before (ties keep the earlier
    /// cloud), as the BVH path does. `shared_origin`: the origin every prepared ray has, bit for
    /// bit, if there is one (a perspective camera's eye), splatted instead of loaded per pixel.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn trace_cloud(
        &mut self,
        bins: &CloudBins,
        bvh: &SphereBvh,
        ci: usize,
        band: usize,
        (w, rows): (usize, usize),
        shared_origin: Option<Vec3>,
        prepare: impl Fn((usize, usize), Option<f32>) -> Option<PreparedRay>,
    ) {
        let y_lo = band * bins.band_rows;
        let y_hi = y_lo + rows;
        let pixels = rows * w;
        self.ready.clear();
        self.ready.resize(pixels + 3, false);
        self.best_slot[..pixels].fill(NONE);
        let r = bvh.radius();
        let r2 = r * r;
        for b in bins.band(band) {
            // With one origin, no hit on this sphere is nearer than |centre − origin| − r (less a
            // relative margin for rounding): pixels whose closest hit is already nearer skip it.
            let nearest = shared_origin.map_or(f32::NEG_INFINITY, |o| (b.c - o).length() * (1.0 - NEAREST_SLACK) - r);
            for y in (b.y0 as usize).max(y_lo)..(b.y1 as usize + 1).min(y_hi) {
                let row = y - y_lo;
                let base = row * w;
                let (x0, x1) = (b.x0 as usize, b.x1 as usize);
                for x in (x0..=x1).step_by(4) {
                    let i = base + x;
                    let lanes = (x1 - x + 1).min(4);
                    // Each pixel's ray is made when a sphere first covers it.
                    for lane in 0..lanes {
                        if !self.ready[i + lane] {
                            self.ready[i + lane] = true;
                            let j = i + lane;
                            self.set_ray(j, prepare((row, x + lane), self.best[j].map(|b| b.0)));
                        }
                    }
                    let load = |v: &[f32]| Vec4::from_slice(&v[i..i + 4]);
                    let lane_mask = (1u32 << lanes) - 1;
                    if load(&self.best_t).cmplt(Vec4::splat(nearest)).bitmask() & lane_mask == lane_mask {
                        continue;
                    }
                    let o = match shared_origin {
                        Some(o) => [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
                        None => [load(&self.o[0]), load(&self.o[1]), load(&self.o[2])],
                    };
                    let d = [load(&self.d[0]), load(&self.d[1]), load(&self.d[2])];
                    let (t4, mask) = sphere_hits4(b.c, r2, o, d, load(&self.t_min), load(&self.t_max));
                    let mask = mask & lane_mask;
                    if mask == 0 {
                        continue;
                    }
                    self.take_hits(i, mask, t4, b, bvh);
                }
            }
        }

        // The cloud's hits, in the primary ray's units, against the clouds before.
        for i in (0..pixels).filter(|&i| self.best_slot[i] != NONE) {
            let t = self.best_t[i] / self.len[i];
            if self.best[i].is_none_or(|b| t < b.0) {
                let c = Vec3::new(self.best_c[0][i], self.best_c[1][i], self.best_c[2][i]);
                self.best[i] = Some((t, ci, self.best_slot[i], c));
            }
        }
    }

    /// Stores pixel `i`'s prepared ray (`None`: an empty range, which no lane test passes, as
    /// `t ≥ +∞` and `t ≤ −∞` both fail); its closest hit so far is none, at its `t_max`.
    #[inline]
    fn set_ray(&mut self, i: usize, ray: Option<PreparedRay>) {
        match ray {
            Some(r) => {
                for a in 0..3 {
                    self.o[a][i] = r.o[a];
                    self.d[a][i] = r.d[a];
                }
                self.t_min[i] = r.t_min;
                self.t_max[i] = r.t_max;
                self.len[i] = r.len;
                self.best_t[i] = r.t_max;
            }
            None => {
                self.t_min[i] = f32::INFINITY;
                self.t_max[i] = f32::NEG_INFINITY;
            }
        }
    }

    /// Sphere `b`'s hits `t4` on the lanes in `mask` of pixels `i..i + 4`, kept where nearer
    /// than the pixel's closest so far, or as near with a lower original index (the traversal's
    /// rule). Ties are rare: lane by lane; otherwise the four lanes are updated at once.
    #[inline]
    fn take_hits(&mut self, i: usize, mask: u32, t4: Vec4, b: &Binned, bvh: &SphereBvh) {
        let slot = b.slot;
        let best4 = Vec4::from_slice(&self.best_t[i..i + 4]);
        let lanes = BVec4A::new(mask & 1 != 0, mask & 2 != 0, mask & 4 != 0, mask & 8 != 0);
        if (t4.cmpeq(best4) & lanes).any() {
            let mut m = mask;
            while m != 0 {
                let lane = m.trailing_zeros() as usize;
                m &= m - 1;
                let (j, t) = (i + lane, t4[lane]);
                let best = self.best_t[j];
                let closer = t < best
                    || (t == best && (self.best_slot[j] == NONE || bvh.index_of_slot(slot) < bvh.index_of_slot(self.best_slot[j])));
                if closer {
                    self.best_t[j] = t;
                    self.best_slot[j] = slot;
                    for a in 0..3 {
                        self.best_c[a][j] = b.c[a];
                    }
                }
            }
            return;
        }
        let closer = t4.cmplt(best4) & lanes;
        let closer4 = closer;
        Vec4::select(closer, t4, best4).write_to_slice(&mut self.best_t[i..i + 4]);
        let c = closer.bitmask();
        let closer = BVec4::new(c & 1 != 0, c & 2 != 0, c & 4 != 0, c & 8 != 0);
        let slots = UVec4::from_slice(&self.best_slot[i..i + 4]);
        UVec4::select(closer, UVec4::splat(slot), slots).write_to_slice(&mut self.best_slot[i..i + 4]);
        for a in 0..3 {
            let c = Vec4::from_slice(&self.best_c[a][i..i + 4]);
            Vec4::select(closer4, Vec4::splat(b.c[a]), c).write_to_slice(&mut self.best_c[a][i..i + 4]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capsule::RayGen;
    use crate::spheres::closest_hit_brute_force;
    use hybrid_core::test_rng::Rng;
    use hybrid_scene::Projection;

    /// Every pixel whose ray hits a sphere (brute force, the BVH's test) lies in the sphere's
    /// rectangle, for spheres all over and around the frustum (beside, behind, across the near
    /// plane, tiny and screen-filling), perspective and orthographic.
    #[test]
    fn rectangles_hold_every_pixel_a_ray_hits() {
        let (w, h) = (64u32, 40u32);
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let mut hits_checked = 0;
        let mut tight = 0usize;
        for (k, projection) in [
            Projection::Perspective { fov_y_deg: 55.0, near: 0.05, far: 200.0 },
            Projection::Perspective { fov_y_deg: 100.0, near: 0.5, far: 20.0 },
            Projection::Orthographic { height: 6.0, near: 0.1, far: 50.0 },
        ]
        .into_iter()
        .enumerate()
        {
            let camera =
                Camera { position: Vec3::new(1.0 + k as f32, 2.0, 7.0), target: Vec3::new(0.5, 1.0, -1.0), up: Vec3::Y, projection };
            let raygen = RayGen::new(&camera, w, h);
            for _ in 0..300 {
                let r = [0.01, 0.05, 0.3, 0.7][(rng.f() * 4.0) as usize];
                let c = Vec3::new(rng.f() * 16.0 - 8.0, rng.f() * 12.0 - 5.0, rng.f() * 22.0 - 12.0);
                let proj = Projector::new(&camera, w, h, r, c.abs().max_element());
                let rect = proj.rect(c);
                let mut covered = 0;
                for row in 0..h {
                    for col in 0..w {
                        let ray = raygen.ray(col, row);
                        if closest_hit_brute_force(&[c], r, ray.origin, ray.dir, ray.t_min, ray.t_max).is_none() {
                            continue;
                        }
                        covered += 1;
                        let [x0, x1, y0, y1] = rect.unwrap_or_else(|| panic!("sphere {c} r {r}: hit at ({col}, {row}) but culled"));
                        assert!(
                            (x0 as u32..=x1 as u32).contains(&col) && (y0 as u32..=y1 as u32).contains(&row),
                            "sphere {c} r {r} camera {k}: hit at ({col}, {row}) outside {:?}",
                            rect
                        );
                        hits_checked += 1;
                    }
                }
                // The bounds are tight: a rectangle at most a pixel and a margin wider than the hits.
                if let (Some([x0, x1, y0, y1]), true) = (rect, covered > 0) {
                    let area = (x1 as usize - x0 as usize + 1) * (y1 as usize - y0 as usize + 1);
                    if area <= 4 * covered + 16 {
                        tight += 1;
                    }
                }
            }
        }
        assert!(hits_checked > 2000, "only {hits_checked} hit pixels checked");
        assert!(tight > 100, "only {tight} tight rectangles");
    }

    /// The four-lane span equals ceil / floor of the padded interval, clamped, for ordinary,
    /// reversed, infinite and NaN bounds.
    #[test]
    fn pixel_spans_round_outwards_and_clamp() {
        let mut rng = Rng(3);
        let special = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -3.0, -0.5, 0.0, 7.0, 7.5, 63.0, 63.5, 64.0, 1e9];
        for k in 0..20_000 {
            let pick = |rng: &mut Rng| if k % 3 == 0 { special[(rng.f() * special.len() as f32) as usize] } else { rng.f() * 80.0 - 8.0 };
            let (a, b, pad, max) = (pick(&mut rng), pick(&mut rng), [0.1, 0.6, f32::NAN][k % 3], 63.0f32);
            let (first, last) = pixel_spans4(Vec4::splat(a), Vec4::splat(b), Vec4::splat(pad), max);
            let (first, last) = (first.x, last.x);
            if a.is_nan() || b.is_nan() || pad.is_nan() {
                assert_eq!((first, last), (0.0, max), "{a} {b} {pad}");
                continue;
            }
            let (lo, hi) = (a.min(b) as f64 - pad as f64, a.max(b) as f64 + pad as f64);
            let want = (lo.ceil().max(0.0), hi.floor().min(max as f64));
            if want.0 <= want.1 {
                assert_eq!((first as f64, last as f64), want, "{a} {b} {pad}");
            } else {
                assert!(first > last, "{a} {b} {pad}: ({first}, {last}) should be empty");
            }
        }
    }

    #[test]
    fn far_near_and_behind_spheres_are_culled() {
        let camera = Camera {
            position: Vec3::ZERO,
            target: Vec3::NEG_Z,
            up: Vec3::Y,
            projection: Projection::Perspective { fov_y_deg: 60.0, near: 1.0, far: 10.0 },
        };
        let proj = Projector::new(&camera, 32, 32, 0.1, 100.0);
        assert!(proj.rect(Vec3::new(0.0, 0.0, -5.0)).is_some());
        assert!(proj.rect(Vec3::new(0.0, 0.0, 5.0)).is_none(), "behind");
        assert!(proj.rect(Vec3::new(0.0, 0.0, -0.5)).is_none(), "before the near plane");
        assert!(proj.rect(Vec3::new(0.0, 0.0, -11.0)).is_none(), "beyond the far plane");
        assert!(proj.rect(Vec3::new(0.0, 0.0, -0.95)).is_some(), "reaching past the near plane");
        assert!(proj.rect(Vec3::new(100.0, 0.0, -5.0)).is_none(), "beside the frustum");
    }

    /// Binned and traced per band, the closest hits equal brute force per pixel, bit for bit.
    #[test]
    fn band_tracing_equals_brute_force() {
        let (w, h) = (48u32, 21u32);
        let mut rng = Rng(42);
        // Duplicated centres (ties go to the lower index) among random ones.
        let mut centers: Vec<Vec3> = (0..3000).map(|_| Vec3::new(rng.f() * 6.0 - 3.0, rng.f() * 4.0 - 2.0, rng.f() * 6.0 - 6.0)).collect();
        let dup: Vec<Vec3> = centers[..200].to_vec();
        centers.extend(dup);
        let bvh = SphereBvh::build(&centers, 0.08).unwrap();
        let camera = Camera {
            position: Vec3::new(0.3, 0.2, 2.0),
            target: Vec3::new(0.0, 0.0, -3.0),
            up: Vec3::Y,
            projection: Projection::Perspective { fov_y_deg: 60.0, near: 0.05, far: 100.0 },
        };
        let raygen = RayGen::new(&camera, w, h);
        let mut bins = CloudBins::default();
        bins.bin(&bvh, &camera, w, h, None);
        assert!(bins.filed() > 1000, "{} spheres filed", bins.filed());
        let mut s = BandScratch::default();
        let wu = w as usize;
        let mut checked = 0;
        for band in 0..(h as usize).div_ceil(BAND_ROWS) {
            let rows = BAND_ROWS.min(h as usize - band * BAND_ROWS);
            s.begin(rows * wu);
            let ray = |i: usize| raygen.ray((i % wu) as u32, (band * BAND_ROWS + i / wu) as u32);
            s.trace_cloud(&bins, &bvh, 0, band, (wu, rows), Some(camera.position), |(row, col), limit| {
                let r = ray(row * wu + col);
                bvh.prepare_ray(r.origin, r.dir, r.t_min, limit.unwrap_or(r.t_max))
            });
            for i in 0..rows * wu {
                let r = ray(i);
                let want = closest_hit_brute_force(&centers, 0.08, r.origin, r.dir, r.t_min, r.t_max);
                let got = s.best[i].map(|(t, _, slot, c)| {
                    assert_eq!(c, bvh.center_of_slot(slot));
                    (t.to_bits(), bvh.index_of_slot(slot))
                });
                assert_eq!(got, want.map(|(t, idx)| (t.to_bits(), idx)), "pixel {i} of band {band}");
                checked += want.is_some() as usize;
            }
        }
        assert!(checked > 200, "only {checked} hits");
    }
}
