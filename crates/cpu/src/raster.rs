//! Stage 1, `raster` (paper 1 §3.1, listings 1–3): every triangle of the prepared scene into the
//! deferred G-buffer, merged by depth with the RT layer of paper 2 (block U).
//!
//! How it works, in three passes:
//! 1. **Vertices**: every world vertex through the camera's view-projection (reversed-Z), then
//!    projected and snapped to 1/256 pixel, with outcodes against the frustum and the clip planes.
//! 2. **Setup and binning** (parallel over fixed chunks of the scene's triangle list): trivial
//!    reject; triangles crossing the near plane (or leaving the guard band) are clipped in clip
//!    space *before* the divide; each screen triangle gets the perspective planes of its source
//!    triangle (`b_i/w` as affine functions of the pixel position, from the inverse of the
//!    homogeneous vertex matrix) and is binned into horizontal bands of [`BAND_ROWS`] rows.
//! 3. **Bands** (parallel): each band owns its rows of every target. It writes the RT layer's
//!    depth first (so polygons must be nearer, depth test Greater), rasterises its bin in scene
//!    triangle order with integer edge functions and the top-left rule into a local visibility
//!    buffer (triangle id + depth; long rows walk only their exactly computed covered span, not
//!    the whole bounding box), then shades only the winner of each pixel with
//!    [`PreparedScene::surface_at`] (deferred: no cost for overdraw). Runs of one winner go four
//!    pixels at a time: barycentrics, UV footprints and (for triangles without texture maps)
//!    the whole surface as SIMD lanes, each lane bit for bit the one-pixel result.
//!
//! Output is bit-identical for any number of threads: chunking and banding are fixed, each
//! band runs its triangles in scene order, and equal depths keep the earlier triangle.

use glam::{BVec4A, DMat3, DVec3, Mat4, Vec3, Vec4};
use hybrid_core::buffers::BandRows;
use hybrid_core::lanes::V3;
use hybrid_core::{GBuffer, RT_SCENE_OBJECT, RtLayer, Surface};
use hybrid_scene::Camera;
use rayon::prelude::*;

use crate::camera_rays::PrimaryRays;
use crate::depth_merge::{layer_fits, rt_surface_with};
use hybrid_core::prepare::{Plain4, PreparedScene, TriangleRef, TriangleSurface};

/// Rows per band (the unit of parallel work and of binning).
pub const BAND_ROWS: u32 = 16;
/// Sub-pixel precision of snapped vertex positions (1/256 pixel).
const SUB_BITS: u32 = 8;
const SUB: i64 = 1 << SUB_BITS;
const HALF: i64 = SUB / 2;
/// Guard band in pixels beyond each image border: triangles reaching further are clipped, so
/// fixed-point coordinates stay small enough for exact `i64` edge functions.
const GUARD_PX: f32 = 8192.0;
/// Triangles per setup task (fixed, so binning order never depends on the thread count).
const SETUP_CHUNK: usize = 8192;
/// Visibility ids are `chunk << CHUNK_SHIFT | index in chunk` (in scene order). Clipping makes at
/// most 6 screen triangles of one scene triangle, so a chunk holds < 6 · 8192 < 2¹⁶ of them.
const CHUNK_SHIFT: u32 = 16;

/// Visibility-buffer ids: nothing drawn / RT layer visible.
const VIS_NONE: u32 = u32::MAX;
const VIS_RT: u32 = u32::MAX - 1;

// Outcode bits: outside the view frustum (for trivial rejection) and outside the clip planes
// (near + guard band; these need clipping before the divide).
const OUT_RIGHT: u32 = 1;
const OUT_LEFT: u32 = 2;
const OUT_TOP: u32 = 4;
const OUT_BOTTOM: u32 = 8;
const OUT_NEAR: u32 = 16;
const OUT_FAR: u32 = 32;
const CLIP_NEAR: u32 = 64;
const CLIP_RIGHT: u32 = 128;
const CLIP_LEFT: u32 = 256;
const CLIP_TOP: u32 = 512;
const CLIP_BOTTOM: u32 = 1024;
const INVALID: u32 = 2048;
const FRUSTUM: u32 = OUT_RIGHT | OUT_LEFT | OUT_TOP | OUT_BOTTOM | OUT_NEAR | OUT_FAR;
const CLIP: u32 = CLIP_NEAR | CLIP_RIGHT | CLIP_LEFT | CLIP_TOP | CLIP_BOTTOM;

/// Rasterises the prepared scene into a new G-buffer of `width × height` (row 0 at the top).
///
/// `rt_layer` (paper 2, block U): where its depth is > 0 it is written into the depth buffer
/// before any polygon; polygons win only where they are nearer (reversed-Z Greater). Pixels
/// where it stays visible get [`RT_SCENE_OBJECT`] and [`crate::depth_merge::rt_surface`]. A layer of another size
/// is ignored (with a warning).
pub fn rasterize(prepared: &PreparedScene, camera: &Camera, width: u32, height: u32, rt_layer: Option<&RtLayer>) -> GBuffer {
    let mut g = GBuffer::new(width, height);
    raster_into(prepared, camera, rt_layer, &mut g, false);
    g
}

/// As [`rasterize`], into an existing G-buffer (its size is the frame size): every pixel of every
/// target is overwritten (mask cleared to 0), so a buffer can be reused frame after frame.
pub fn rasterize_into(prepared: &PreparedScene, camera: &Camera, rt_layer: Option<&RtLayer>, gbuffer: &mut GBuffer) {
    raster_into(prepared, camera, rt_layer, gbuffer, true);
}

// ---------------------------------------------------------------------------------------------
// Pass 1: vertices.

/// Frame constants of the setup.
#[derive(Clone, Copy)]
struct Viewport {
    vp: Mat4,
    width: u32,
    height: u32,
    /// Guard-band extent in NDC (|x/w| ≤ gx).
    gx: f32,
    gy: f32,
}

/// A vertex in clip space with its snapped screen position (valid when no `CLIP` bit is set).
#[derive(Clone, Copy, Default)]
struct PVert {
    clip: Vec4,
    fx: i32,
    fy: i32,
    code: u32,
}

impl Viewport {
    fn clip_of(&self, p: Vec3) -> Vec4 {
        self.vp * p.extend(1.0)
    }

    fn outcode(&self, c: Vec4) -> u32 {
        if !c.is_finite() {
            return INVALID | FRUSTUM;
        }
        let mut code = 0;
        if c.x > c.w {
            code |= OUT_RIGHT;
        }
        if c.x < -c.w {
            code |= OUT_LEFT;
        }
        if c.y > c.w {
            code |= OUT_TOP;
        }
        if c.y < -c.w {
            code |= OUT_BOTTOM;
        }
        // Reversed-Z: nearer than the near plane ⇔ z > w; beyond the far plane ⇔ z < 0.
        if c.z > c.w {
            code |= OUT_NEAR | CLIP_NEAR;
        }
        if c.z < 0.0 {
            code |= OUT_FAR;
        }
        if c.x > self.gx * c.w {
            code |= CLIP_RIGHT;
        }
        if c.x < -self.gx * c.w {
            code |= CLIP_LEFT;
        }
        if c.y > self.gy * c.w {
            code |= CLIP_TOP;
        }
        if c.y < -self.gy * c.w {
            code |= CLIP_BOTTOM;
        }
        code
    }

    /// Snapped fixed-point screen position of a clip-space point inside the clip planes.
    /// Used for every vertex (original or made by clipping), so shared vertices snap identically.
    #[inline]
    fn snap(&self, c: Vec4) -> (i32, i32) {
        let inv_w = 1.0 / c.w;
        let sx = (c.x * inv_w * 0.5 + 0.5) * self.width as f32;
        let sy = (0.5 - c.y * inv_w * 0.5) * self.height as f32;
        (round_to_i32(sx * SUB as f32), round_to_i32(sy * SUB as f32))
    }

    fn vertex(&self, p: Vec3) -> PVert {
        let clip = self.clip_of(p);
        let code = self.outcode(clip);
        let (fx, fy) = if code & (CLIP | INVALID) == 0 { self.snap(clip) } else { (0, 0) };
        PVert { clip, fx, fy, code }
    }
}

/// `x.round() as i32` (half away from zero, saturating, NaN → 0) without the library `roundf`
/// call of targets lacking SSE4.1.
#[inline(always)]
fn round_to_i32(x: f32) -> i32 {
    let t = x as i32; // truncated (saturating)
    // Exact where it matters (|x| < 2²³); beyond, x is integral or t saturated.
    let frac = x - t as f32;
    // Branch-free: the fraction is as good as random, so branches on it mispredict.
    t.saturating_add(i32::from(frac >= 0.5)).saturating_sub(i32::from(frac <= -0.5))
}

// ---------------------------------------------------------------------------------------------
// Pass 2: setup and binning.

/// What the band rasteriser needs of a screen triangle (counter-clockwise in fixed point).
#[derive(Clone, Copy, Debug)]
struct RasterTri {
    /// Snapped vertices, 1/256 pixel, positive orientation.
    v: [[i32; 2]; 3],
    /// Pixel-centre range covered by the bounding box (inclusive, clamped to the image).
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
    /// Depth plane: reversed-Z depth at pixel centre (x0, y0) and per pixel in x and y.
    z0: f32,
    dzdx: f32,
    dzdy: f32,
}

/// What the shading pass needs: the source triangle and its perspective planes `b_i / w`,
/// each as value at the reference pixel centre (x0 + 0.5, y0 + 0.5) and gradient per pixel.
#[derive(Clone, Copy, Debug)]
struct ShadeTri {
    triangle: TriangleRef,
    ref_px: [f32; 2],
    /// Per corner i: (b_i/w at the reference, d/dx, d/dy).
    planes: [Vec3; 3],
}

impl ShadeTri {
    /// Perspective-correct barycentrics at continuous pixel position (px, py), or `None` when the
    /// planes give no point in front of the camera there (only possible when extrapolating).
    #[inline]
    fn bary(&self, px: f32, py: f32) -> Option<Vec3> {
        let d = Vec3::new(1.0, px - self.ref_px[0], py - self.ref_px[1]);
        let bw = Vec3::new(self.planes[0].dot(d), self.planes[1].dot(d), self.planes[2].dot(d));
        let sum = bw.x + bw.y + bw.z;
        let b = bw / sum;
        (sum.is_finite() && sum != 0.0 && b.is_finite()).then_some(b)
    }

    /// [`Self::bary`] at four pixel positions `px` (lanes) of row position `py`, lane by lane
    /// bit for bit: the barycentrics, and which lanes `bary` gives (the others hold anything).
    #[inline]
    fn bary4(&self, px: Vec4, py: f32) -> (V3, BVec4A) {
        let (dx, dy) = (px - Vec4::splat(self.ref_px[0]), Vec4::splat(py - self.ref_px[1]));
        // `planes[i] · (1, dx, dy)`, with its multiplication by 1, so NaNs match too.
        let bw = self.planes.map(|p| Vec4::splat(p.x) * Vec4::ONE + Vec4::splat(p.y) * dx + Vec4::splat(p.z) * dy);
        let sum = bw[0] + bw[1] + bw[2];
        let b = bw.map(|v| v / sum);
        let finite = b[0].is_finite_mask() & b[1].is_finite_mask() & b[2].is_finite_mask();
        (b, sum.is_finite_mask() & sum.cmpne(Vec4::ZERO) & finite)
    }
}

/// One setup task's output: its screen triangles in scene order and their band bins.
#[derive(Default)]
struct Chunk {
    raster: Vec<RasterTri>,
    shade: Vec<ShadeTri>,
    /// `entries[band_start[b]..band_start[b + 1]]`: indices into `raster` touching band `b`.
    band_start: Vec<u32>,
    entries: Vec<u32>,
}

impl Chunk {
    fn bin(&self, band: usize) -> &[u32] {
        &self.entries[self.band_start[band] as usize..self.band_start[band + 1] as usize]
    }
}

/// A screen-space vertex of a (possibly clipped) triangle.
#[derive(Clone, Copy)]
struct ClipVert {
    c: Vec4,
}

/// Fills `chunk` (its vectors reused from frame to frame) with the screen triangles of scene
/// triangles `first..first + SETUP_CHUNK` and their band bins.
#[allow(clippy::too_many_arguments)]
fn setup_chunk(
    chunk: &mut Chunk,
    first: usize,
    prepared: &PreparedScene,
    verts: &[PVert],
    mesh_base: &[usize],
    vpt: &Viewport,
    bands: usize,
    include: Option<&[bool]>,
) {
    let end = (first + SETUP_CHUNK).min(prepared.triangles.len());
    let Chunk { raster, shade, band_start, entries } = chunk;
    raster.clear();
    shade.clear();
    // Sized for every triangle up front: no reallocation while filling.
    raster.reserve(end - first);
    shade.reserve(end - first);
    for t in &prepared.triangles[first..end] {
        if include.is_some_and(|inc| !inc.get(t.mesh as usize).copied().unwrap_or(false)) {
            continue;
        }
        let mesh = &prepared.meshes[t.mesh as usize];
        let idx = mesh.indices[t.triangle as usize];
        let mv = &verts[mesh_base[t.mesh as usize]..mesh_base[t.mesh as usize + 1]];
        let (Some(a), Some(b), Some(c)) = (mv.get(idx[0] as usize), mv.get(idx[1] as usize), mv.get(idx[2] as usize)) else {
            continue;
        };
        if a.code & b.code & c.code & FRUSTUM != 0 || (a.code | b.code | c.code) & INVALID != 0 {
            continue;
        }
        let clip = [a.clip, b.clip, c.clip];
        if (a.code | b.code | c.code) & CLIP == 0 {
            let tri = [[a.fx, a.fy], [b.fx, b.fy], [c.fx, c.fy]];
            if let Some(rt) = coverage(tri, vpt) {
                // Planes are only built for triangles that cover a pixel centre.
                if let Some((rt, st)) = planes(rt, clip, *t, vpt) {
                    raster.push(rt);
                    shade.push(st);
                }
            }
        } else {
            let mut poly = [ClipVert { c: Vec4::ZERO }; 9];
            let n = clip_polygon(&mut poly, clip, a.code | b.code | c.code, vpt);
            for k in 1..n.saturating_sub(1) {
                let tri = [poly[0], poly[k], poly[k + 1]].map(|v| {
                    let (x, y) = vpt.snap(v.c);
                    [x, y]
                });
                if let Some(rt) = coverage(tri, vpt)
                    && let Some((rt, st)) = planes(rt, clip, *t, vpt)
                {
                    raster.push(rt);
                    shade.push(st);
                }
            }
        }
    }
    // Bin: counting sort by band, keeping scene order inside each band.
    band_start.clear();
    band_start.resize(bands + 2, 0);
    for t in raster.iter() {
        for b in (t.y0 / BAND_ROWS)..=(t.y1 / BAND_ROWS) {
            band_start[b as usize + 2] += 1;
        }
    }
    for b in 0..bands {
        band_start[b + 2] += band_start[b + 1];
    }
    // band_start[b + 1] is now where band b starts; filling advances it to where b ends, i.e.
    // where b + 1 starts, which leaves band_start[b]..band_start[b + 1] = band b.
    entries.clear();
    entries.resize(band_start[bands + 1] as usize, 0);
    for (i, t) in raster.iter().enumerate() {
        for b in (t.y0 / BAND_ROWS)..=(t.y1 / BAND_ROWS) {
            let f = &mut band_start[b as usize + 1];
            entries[*f as usize] = i as u32;
            *f += 1;
        }
    }
    band_start.truncate(bands + 1);
}

/// Sutherland–Hodgman clipping of a triangle against the planes named in `code` (near first,
/// then the guard band). Intersections are always computed from the inside endpoint, so an edge
/// shared by two triangles is cut at bit-identical points. Returns the vertex count.
fn clip_polygon(out: &mut [ClipVert; 9], tri: [Vec4; 3], code: u32, vpt: &Viewport) -> usize {
    let (gx, gy) = (vpt.gx, vpt.gy);
    let planes: [(u32, Vec4); 5] = [
        (CLIP_NEAR, Vec4::new(0.0, 0.0, -1.0, 1.0)),
        (CLIP_RIGHT, Vec4::new(-1.0, 0.0, 0.0, gx)),
        (CLIP_LEFT, Vec4::new(1.0, 0.0, 0.0, gx)),
        (CLIP_TOP, Vec4::new(0.0, -1.0, 0.0, gy)),
        (CLIP_BOTTOM, Vec4::new(0.0, 1.0, 0.0, gy)),
    ];
    let mut cur = [ClipVert { c: Vec4::ZERO }; 9];
    let mut n = 3;
    for (i, c) in tri.iter().enumerate() {
        cur[i] = ClipVert { c: *c };
    }
    for (bit, plane) in planes {
        if code & bit == 0 {
            continue;
        }
        let mut m = 0;
        for i in 0..n {
            let (p, q) = (cur[i], cur[(i + 1) % n]);
            let (dp, dq) = (plane.dot(p.c), plane.dot(q.c));
            let (p_in, q_in) = (dp >= 0.0, dq >= 0.0);
            if p_in {
                out[m] = p;
                m += 1;
            }
            if p_in != q_in && m < out.len() {
                let (inside, outside, di, dout) = if p_in { (p, q, dp, dq) } else { (q, p, dq, dp) };
                let t = di / (di - dout);
                out[m] = ClipVert { c: inside.c + (outside.c - inside.c) * t };
                m += 1;
            }
        }
        n = m;
        cur[..n].copy_from_slice(&out[..n]);
        if n < 3 {
            return 0;
        }
    }
    out[..n].copy_from_slice(&cur[..n]);
    // Clipped vertices must be in front of the camera and finite to be projected.
    if cur[..n].iter().any(|v| v.c.w <= 0.0 || !v.c.is_finite()) {
        return 0;
    }
    n
}

/// Coverage part of the setup: orientation, bounding box of pixel centres. `None` when the
/// triangle has no area or covers no pixel centre.
#[inline]
fn coverage(mut v: [[i32; 2]; 3], vpt: &Viewport) -> Option<RasterTri> {
    let min_x = v[0][0].min(v[1][0]).min(v[2][0]) as i64;
    let max_x = v[0][0].max(v[1][0]).max(v[2][0]) as i64;
    let min_y = v[0][1].min(v[1][1]).min(v[2][1]) as i64;
    let max_y = v[0][1].max(v[1][1]).max(v[2][1]) as i64;
    // Pixel x is covered by the box when its centre x·SUB + HALF lies in [min, max].
    let x0 = (min_x - HALF + SUB - 1).div_euclid(SUB).max(0);
    let x1 = (max_x - HALF).div_euclid(SUB).min(vpt.width as i64 - 1);
    let y0 = (min_y - HALF + SUB - 1).div_euclid(SUB).max(0);
    let y1 = (max_y - HALF).div_euclid(SUB).min(vpt.height as i64 - 1);
    if x0 > x1 || y0 > y1 {
        return None;
    }
    let det = area2(v);
    if det == 0 {
        return None;
    }
    if det < 0 {
        v.swap(1, 2);
    }
    Some(RasterTri { v, x0: x0 as u32, x1: x1 as u32, y0: y0 as u32, y1: y1 as u32, z0: 0.0, dzdx: 0.0, dzdy: 0.0 })
}

/// Twice the signed area of a fixed-point triangle (positive = the orientation we raster).
#[inline]
fn area2(v: [[i32; 2]; 3]) -> i64 {
    let [[x0, y0], [x1, y1], [x2, y2]] = v.map(|p| p.map(i64::from));
    (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
}

/// Perspective planes of the source triangle (clip-space corners `clip`) in pixel coordinates:
/// `b_i / w = P_i · (px, py, 1)` with `P = M⁻¹ S`, M the homogeneous (x, y, w) corner matrix and
/// S the pixel → NDC map. Valid for any corner signs of w, so clipped pieces share the planes.
/// Depth (z/w, reversed-Z) is `Σ z_i P_i`, affine in screen space. Inlined into the setup, so
/// the two results it returns are written straight to their lists (returned through memory,
/// they were reloaded before their stores had landed).
#[inline(always)]
fn planes(mut rt: RasterTri, clip: [Vec4; 3], triangle: TriangleRef, vpt: &Viewport) -> Option<(RasterTri, ShadeTri)> {
    let m = DMat3::from_cols(
        DVec3::new(clip[0].x as f64, clip[0].y as f64, clip[0].w as f64),
        DVec3::new(clip[1].x as f64, clip[1].y as f64, clip[1].w as f64),
        DVec3::new(clip[2].x as f64, clip[2].y as f64, clip[2].w as f64),
    );
    let det = m.determinant();
    if !det.is_normal() {
        return None;
    }
    let inv = m.inverse();
    let (w, h) = (vpt.width as f64, vpt.height as f64);
    // (X, Y, 1) = S (px, py, 1): X = 2 px / w − 1, Y = 1 − 2 py / h.
    let s = DMat3::from_cols(DVec3::new(2.0 / w, 0.0, 0.0), DVec3::new(0.0, -2.0 / h, 0.0), DVec3::new(-1.0, 1.0, 1.0));
    let p = (inv * s).transpose(); // columns = rows of M⁻¹ S = the planes (a, b, c) of b_i / w
    let (rx, ry) = (rt.x0 as f64 + 0.5, rt.y0 as f64 + 0.5);
    let plane = |a: DVec3| DVec3::new(a.x * rx + a.y * ry + a.z, a.x, a.y);
    let pl = [plane(p.x_axis), plane(p.y_axis), plane(p.z_axis)];
    let z = pl[0] * clip[0].z as f64 + pl[1] * clip[1].z as f64 + pl[2] * clip[2].z as f64;
    if !z.is_finite() || !pl.iter().all(|q| q.is_finite()) {
        return None;
    }
    rt.z0 = z.x as f32;
    rt.dzdx = z.y as f32;
    rt.dzdy = z.z as f32;
    let st = ShadeTri { triangle, ref_px: [rx as f32, ry as f32], planes: pl.map(|q| q.as_vec3()) };
    Some((rt, st))
}

// ---------------------------------------------------------------------------------------------
// Pass 3: bands.

/// The edge functions of a screen triangle in fixed point, with the top-left rule folded into
/// the constant: a pixel centre is covered when all three are ≥ 0.
#[derive(Clone, Copy, Debug)]
struct Edges {
    a: [i64; 3],
    b: [i64; 3],
    c: [i64; 3],
}

impl Edges {
    #[inline]
    fn new(v: [[i32; 2]; 3]) -> Self {
        let mut e = Edges { a: [0; 3], b: [0; 3], c: [0; 3] };
        for k in 0..3 {
            let [ax, ay] = v[k].map(i64::from);
            let [bx, by] = v[(k + 1) % 3].map(i64::from);
            // E(p) = (b − a) × (p − a) = A·px + B·py + C, positive inside (positive orientation).
            let (a, b) = (ay - by, bx - ax);
            let c = ax * by - ay * bx;
            // Top-left rule (row 0 at the top): pixels exactly on a left edge (inside to the
            // right, A > 0) or a top edge (horizontal, inside below, B > 0) are covered; on any
            // other edge they belong to the neighbour, so E must be > 0, i.e. E − 1 ≥ 0.
            let top_left = a > 0 || (a == 0 && b > 0);
            e.a[k] = a;
            e.b[k] = b;
            e.c[k] = if top_left { c } else { c - 1 };
        }
        e
    }

    /// Edge values at the centre of pixel (x, y).
    #[inline]
    fn at(&self, x: u32, y: u32) -> [i64; 3] {
        let (px, py) = (x as i64 * SUB + HALF, y as i64 * SUB + HALF);
        [0, 1, 2].map(|k| self.a[k] * px + self.b[k] * py + self.c[k])
    }
}

/// Walks the rows `rows` of the bounding box of `t`: calls `row(y, e, step)` with the three edge
/// values at the centre of pixel (x0, y) and their change per pixel in x. A pixel centre is
/// covered by the top-left rule when all three are ≥ 0.
#[inline(always)]
fn walk_rows(t: &RasterTri, rows: std::ops::Range<u32>, mut row: impl FnMut(u32, [i64; 3], [i64; 3])) {
    let y_start = t.y0.max(rows.start);
    let y_end = (t.y1 + 1).min(rows.end);
    if y_start >= y_end {
        return;
    }
    let e = Edges::new(t.v);
    let step = [e.a[0] * SUB, e.a[1] * SUB, e.a[2] * SUB];
    let mut at = e.at(t.x0, y_start);
    for y in y_start..y_end {
        row(y, at, step);
        for (r, b) in at.iter_mut().zip(e.b) {
            *r += b * SUB;
        }
    }
}

/// Depth test of `t` (visibility id `id`) against a band's visibility buffer (`depth`, `ids`:
/// rows `y_lo..y_hi`, `w` pixels each): covered pixels (by the top-left rule) where the
/// triangle's depth is Greater take its depth and id.
///
/// Inlined, with its per-row closure, into the band loop: a room of 255K triangles at 1280×720
/// tests about 730K rows per frame, most of them 1–8 pixels long, and a call per row (with
/// its captures reloaded) was a fifth of the visibility pass.
#[inline(always)]
fn depth_test(t: &RasterTri, id: u32, y_lo: u32, y_hi: u32, w: usize, depth: &mut [f32], ids: &mut [u32]) {
    let (z0, dzdx, dzdy) = (t.z0, t.dzdx, t.dzdy);
    let (xa, xb) = (t.x0 as usize, t.x1 as usize);
    walk_rows(
        t,
        y_lo..y_hi,
        #[inline(always)]
        |y, [e0, e1, e2], step| {
            // The row's pixels in the band's buffers: `row..=end`, `len` of them.
            let base = (y - y_lo) as usize * w;
            let (row, end, len) = (base + xa, base + xb, xb + 1 - xa);
            if end >= depth.len().min(ids.len()) {
                return;
            }
            // Same sum, in the same order, as z0 + dzdx·(x − x0) + dzdy·(y − y0).
            let zy = dzdy * (y - t.y0) as f32;
            if len >= SPAN_MIN_PX {
                let (drow, irow) = (&mut depth[row..=end], &mut ids[row..=end]);
                // Long rows: only the covered span. Most of a large or thin triangle's box is
                // outside it (Sponza's: 85% of box pixels), and the span is exact (the pixels whose
                // three edge values are ≥ 0), so the same pixels are tested.
                let Some((lo, hi)) = covered_span([e0, e1, e2], step, len - 1) else { return };
                for k in lo..=hi {
                    let z = (z0 + dzdx * k as f32 + zy).min(1.0);
                    let (d, o) = (&mut drow[k], &mut irow[k]);
                    let win = z > *d;
                    *d = if win { z } else { *d };
                    *o = if win { id } else { *o };
                }
                return;
            }
            // Short rows: a fixed count of pixels (4 or 8) from the row's first, so no loop exit to
            // mispredict (rows of one triangle have one length, so the choice is predicted). The
            // pixels past the row are never covered; where 8 pixels would pass the image's right
            // edge, the row goes pixel by pixel.
            if len <= 4 && xa + 4 <= w {
                fixed_row::<4>(&mut depth[row..row + 4], &mut ids[row..row + 4], [e0, e1, e2], step, [z0, dzdx, zy], id);
                return;
            }
            if xa + 8 <= w {
                fixed_row::<8>(&mut depth[row..row + 8], &mut ids[row..row + 8], [e0, e1, e2], step, [z0, dzdx, zy], id);
                return;
            }
            row_test(&mut depth[row..=end], &mut ids[row..=end], [e0, e1, e2], step, [z0, dzdx, zy], id);
        },
    );
}

/// The depth test of a row's pixels `d`, `o` (edge values `e` at the first, changing by `step`
/// per pixel; depth `z0 + dzdx·k + zy` at pixel k): covered pixels where the depth is Greater
/// take it and `id`.
#[inline(always)]
fn row_test(d: &mut [f32], o: &mut [u32], [mut e0, mut e1, mut e2]: [i64; 3], step: [i64; 3], [z0, dzdx, zy]: [f32; 3], id: u32) {
    for (k, (d, o)) in d.iter_mut().zip(o).enumerate() {
        let z = (z0 + dzdx * k as f32 + zy).min(1.0);
        let win = ((e0 | e1 | e2) >= 0) & (z > *d);
        *d = if win { z } else { *d };
        *o = if win { id } else { *o };
        e0 += step[0];
        e1 += step[1];
        e2 += step[2];
    }
}

/// [`row_test`] of a row of at most `N` pixels, done for exactly `N` pixels from the row's first
/// (`d`, `o`), a count known at compile time. The pixels past the row lie outside the
/// triangle's box of covered pixel centres, so their edge values are never all ≥ 0: they keep
/// their values.
#[inline(always)]
fn fixed_row<const N: usize>(d: &mut [f32], o: &mut [u32], e: [i64; 3], step: [i64; 3], z: [f32; 3], id: u32) {
    let (d, o): (&mut [f32; N], &mut [u32; N]) = (d.try_into().expect("N depths"), o.try_into().expect("N ids"));
    row_test(d, o, e, step, z, id);
}

/// Rows of at least this many pixels are walked over their covered span only; shorter ones test
/// every pixel (cheaper than the span's divisions).
const SPAN_MIN_PX: usize = 9;

/// The pixels `k ∈ 0..=last` of a row where every edge value `e[i] + step[i]·k` is ≥ 0, as an
/// inclusive range, or `None` when there are none. Exact integer arithmetic.
#[inline]
fn covered_span(e: [i64; 3], step: [i64; 3], last: usize) -> Option<(usize, usize)> {
    let (mut lo, mut hi) = (0i64, last as i64);
    for i in 0..3 {
        let (e, s) = (e[i], step[i]);
        if s > 0 {
            // e + s·k ≥ 0 ⟺ k ≥ ⌈−e / s⌉.
            if e < 0 {
                lo = lo.max((-e + s - 1) / s);
            }
        } else if s < 0 {
            // e + s·k ≥ 0 ⟺ k ≤ ⌊e / −s⌋.
            if e < 0 {
                return None;
            }
            hi = hi.min(e / -s);
        } else if e < 0 {
            return None;
        }
    }
    (lo <= hi).then_some((lo as usize, hi as usize))
}

fn raster_into(prepared: &PreparedScene, camera: &Camera, rt_layer: Option<&RtLayer>, g: &mut GBuffer, clear: bool) {
    raster_meshes_into(prepared, camera, rt_layer, g, clear, None);
}

/// [`rasterize`] of the meshes whose `include[mesh]` is true only (all when `None`): a
/// reflection probe's face leaves its own object out.
pub fn rasterize_meshes(prepared: &PreparedScene, camera: &Camera, width: u32, height: u32, include: &[bool]) -> GBuffer {
    let mut g = GBuffer::new(width, height);
    raster_meshes_into(prepared, camera, None, &mut g, false, Some(include));
    g
}

/// Depth only (a shadow map): the reversed-Z depth of the nearest triangle of the meshes whose
/// `include[mesh]` is true, seen through `view_proj` on a `size`² map (0 where none is). Same
/// setup, clipping, fill rule and depth planes as the G-buffer raster.
pub fn rasterize_depth(prepared: &PreparedScene, view_proj: Mat4, size: u32, include: &[bool]) -> Vec<f32> {
    let mut out = vec![0.0f32; size as usize * size as usize];
    if size == 0 {
        return out;
    }
    let vpt = viewport(view_proj, size, size);
    let mut scratch = SCRATCH.with(|s| std::mem::take(&mut *s.borrow_mut()));
    if setup_pass(prepared, &vpt, Some(include), &mut scratch) {
        let chunks = &*scratch.chunks;
        let w = size as usize;
        out.par_chunks_mut(w * BAND_ROWS as usize).enumerate().with_max_len(1).for_each_init(BandScratch::default, |s, (band, rows)| {
            let y_lo = band as u32 * BAND_ROWS;
            let y_hi = y_lo + (rows.len() / w) as u32;
            s.ids.clear();
            s.ids.resize(rows.len(), VIS_NONE);
            for (ci, chunk) in chunks.iter().enumerate() {
                let first = (ci as u32) << CHUNK_SHIFT;
                for &local in chunk.bin(band) {
                    depth_test(&chunk.raster[local as usize], first + local, y_lo, y_hi, w, rows, &mut s.ids);
                }
            }
        });
    }
    SCRATCH.with(|s| *s.borrow_mut() = scratch);
    out
}

fn viewport(vp: Mat4, width: u32, height: u32) -> Viewport {
    Viewport { vp, width, height, gx: 1.0 + 2.0 * GUARD_PX / width as f32, gy: 1.0 + 2.0 * GUARD_PX / height as f32 }
}

/// Passes 1 and 2 into `scratch`: vertices, then setup and binning of the triangles of the
/// included meshes (all when `None`). False when the scene has too many triangles.
fn setup_pass(prepared: &PreparedScene, vpt: &Viewport, include: Option<&[bool]>, scratch: &mut Scratch) -> bool {
    let Scratch { verts, mesh_base, chunks } = scratch;

    // Pass 1: vertices, once per vertex, in parallel over fixed slices.
    mesh_base.clear();
    mesh_base.push(0);
    for m in &prepared.meshes {
        mesh_base.push(mesh_base[mesh_base.len() - 1] + m.positions.len());
    }
    verts.resize(mesh_base[mesh_base.len() - 1], PVert::default());
    let mut slices = Vec::with_capacity(prepared.meshes.len());
    let mut rest = verts.as_mut_slice();
    for m in &prepared.meshes {
        let (mine, tail) = rest.split_at_mut(m.positions.len());
        slices.push(mine);
        rest = tail;
    }
    slices.into_par_iter().zip(&prepared.meshes).enumerate().for_each(|(mi, (out, m))| {
        if include.is_some_and(|inc| !inc.get(mi).copied().unwrap_or(false)) {
            return;
        }
        out.par_chunks_mut(VERTEX_CHUNK).zip(m.positions.par_chunks(VERTEX_CHUNK)).for_each(|(o, p)| {
            for (o, p) in o.iter_mut().zip(p) {
                *o = vpt.vertex(*p);
            }
        });
    });

    // Pass 2: setup and binning, in fixed chunks of the scene's triangle order.
    let bands = vpt.height.div_ceil(BAND_ROWS) as usize;
    let n_chunks = prepared.triangles.len().div_ceil(SETUP_CHUNK);
    if n_chunks >= (VIS_RT >> CHUNK_SHIFT) as usize {
        tracing::error!(triangles = prepared.triangles.len(), "too many triangles for the rasteriser's visibility ids");
        return false;
    }
    chunks.truncate(n_chunks);
    chunks.resize_with(n_chunks, Chunk::default);
    let (verts, mesh_base) = (&*verts, &*mesh_base);
    chunks.par_iter_mut().enumerate().with_max_len(1).for_each(|(k, chunk)| {
        setup_chunk(chunk, k * SETUP_CHUNK, prepared, verts, mesh_base, vpt, bands, include);
    });
    true
}

fn raster_meshes_into(
    prepared: &PreparedScene,
    camera: &Camera,
    rt_layer: Option<&RtLayer>,
    g: &mut GBuffer,
    clear: bool,
    include: Option<&[bool]>,
) {
    let (width, height) = (g.width, g.height);
    let n = g.len();
    if width == 0 || height == 0 || n != width as usize * height as usize {
        return;
    }
    let rt_layer = rt_layer.filter(|l| layer_fits(l, width, height));
    let vpt = viewport(camera.view_projection(width as f32 / height as f32), width, height);

    // Per-frame scratch (vertices, setup chunks) kept by the calling thread between frames, so
    // a frame allocates (and page-faults) nothing but what it outputs.
    let mut scratch = SCRATCH.with(|s| std::mem::take(&mut *s.borrow_mut()));
    if !setup_pass(prepared, &vpt, include, &mut scratch) {
        SCRATCH.with(|s| *s.borrow_mut() = scratch);
        return;
    }
    let chunks = &*scratch.chunks;

    // Pass 3: bands (visibility, then shading of the winners).
    let rays = PrimaryRays::new(camera, width, height);
    let w = width as usize;
    let band_len = w * BAND_ROWS as usize;
    let rows = g.bands_mut(band_len);
    let ctx = BandContext { prepared, chunks, rt_layer, rays: &rays, width, height, clear, level0: include.is_some() };
    rows.into_par_iter()
        .enumerate()
        .with_max_len(1)
        .for_each_init(BandScratch::default, |scratch, (band, mut out)| ctx.band(band, &mut out, scratch));
    SCRATCH.with(|s| *s.borrow_mut() = scratch);
}

/// Vertices per task of the vertex pass.
const VERTEX_CHUNK: usize = 4096;

/// Per-frame buffers reused between frames (see [`SCRATCH`]).
#[derive(Default)]
struct Scratch {
    /// Every mesh's vertices, mesh after mesh (`mesh_base[m]..mesh_base[m + 1]` = mesh m).
    verts: Vec<PVert>,
    mesh_base: Vec<usize>,
    chunks: Vec<Chunk>,
}

thread_local! {
    /// The calling thread's raster scratch (taken out for a frame, put back after it).
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

struct BandContext<'a, 's> {
    prepared: &'a PreparedScene<'s>,
    chunks: &'a [Chunk],
    rt_layer: Option<&'a RtLayer>,
    rays: &'a PrimaryRays,
    width: u32,
    height: u32,
    clear: bool,
    level0: bool,
}

impl BandContext<'_, '_> {
    fn band(&self, band: usize, out: &mut BandRows, scratch: &mut BandScratch) {
        let BandScratch { depth, ids } = scratch;
        let w = self.width as usize;
        let y_lo = band as u32 * BAND_ROWS;
        let y_hi = (y_lo + BAND_ROWS).min(self.height);
        let len = (y_hi - y_lo) as usize * w;
        let base = y_lo as usize * w;
        depth.clear();
        ids.clear();
        match self.rt_layer {
            Some(l) => {
                depth.extend_from_slice(&l.depth[base..base + len]);
                ids.extend(depth.iter().map(|&d| if d > 0.0 { VIS_RT } else { VIS_NONE }));
                // Depth 0 is the clear value; negative or NaN layer depths never win.
                depth.iter_mut().for_each(|d| *d = if *d > 0.0 { *d } else { 0.0 });
            }
            None => {
                depth.resize(len, 0.0);
                ids.resize(len, VIS_NONE);
            }
        }

        // Visibility: scene order, strict Greater → the earlier triangle keeps ties.
        for (ci, chunk) in self.chunks.iter().enumerate() {
            let first = (ci as u32) << CHUNK_SHIFT;
            for &local in chunk.bin(band) {
                let t = &chunk.raster[local as usize];
                depth_test(t, first + local, y_lo, y_hi, w, depth, ids);
            }
        }

        // Shading of the winners, row by row in runs of one winner: its planes, corner
        // attributes and material are gathered once per run.
        let rows = (y_hi - y_lo) as usize;
        for row in 0..rows {
            let y = y_lo + row as u32;
            let rb = row * w;
            let mut x = 0usize;
            while x < w {
                let i = rb + x;
                match ids[i] {
                    VIS_NONE => {
                        if self.clear {
                            out.clear(i);
                        }
                        x += 1;
                    }
                    VIS_RT => {
                        let color = self.rt_layer.map_or(Vec3::ZERO, |l| l.color[base + i]);
                        out.write(i, RT_SCENE_OBJECT, depth[i], &rt_surface_with(self.rays, x as u32, y, depth[i], color));
                        if self.clear {
                            out.mask[i] = 0.0;
                        }
                        x += 1;
                    }
                    id => {
                        let end = ids[i + 1..rb + w].iter().position(|&o| o != id).map_or(w, |k| x + 1 + k);
                        let st = &self.chunks[(id >> CHUNK_SHIFT) as usize].shade[(id & ((1 << CHUNK_SHIFT) - 1)) as usize];
                        let ts = self.prepared.triangle_surface(st.triangle);
                        let object = self.prepared.meshes[st.triangle.mesh as usize].object;
                        let px = Pixels { out: &mut *out, row_base: rb, depth, object, clear: self.clear, level0: self.level0 };
                        shade_run(st, &ts, x as u32, end as u32, y, px);
                        x = end;
                    }
                }
            }
        }
    }
}

/// A band worker's buffers, reused from band to band.
#[derive(Default)]
struct BandScratch {
    /// The band's visibility buffer: depth and winner id per pixel.
    depth: Vec<f32>,
    ids: Vec<u32>,
}

/// Clamps perspective-correct barycentrics to the triangle (covered pixels lie inside the
/// snapped triangle; this removes the tiny overshoot of snapping); `None` → the centroid.
/// (Negative components become +0, others, −0 included, stay: a select, not `f32::max`, whose
/// choice between ±0 is unspecified, so that [`clamp_bary4`] can match it lane for lane.)
#[inline]
fn clamp_bary(b: Option<Vec3>) -> Vec3 {
    b.map_or(Vec3::splat(1.0 / 3.0), |b| {
        let b = Vec3::select(b.cmplt(Vec3::ZERO), Vec3::ZERO, b);
        let s = b.x + b.y + b.z;
        if s > 0.0 { b / s } else { Vec3::splat(1.0 / 3.0) }
    })
}

/// [`clamp_bary`] of four lanes ([`ShadeTri::bary4`]'s barycentrics and valid lanes).
#[inline]
fn clamp_bary4((b, valid): (V3, BVec4A)) -> V3 {
    let b = b.map(|v| Vec4::select(v.cmplt(Vec4::ZERO), Vec4::ZERO, v));
    let s = b[0] + b[1] + b[2];
    let ok = valid & s.cmpgt(Vec4::ZERO);
    b.map(|v| Vec4::select(ok, v / s, Vec4::splat(1.0 / 3.0)))
}

/// Where [`shade_run`] writes: one row of a band's G-buffer rows.
struct Pixels<'a, 'b> {
    out: &'a mut BandRows<'b>,
    /// Index of the row's first pixel in the band.
    row_base: usize,
    depth: &'a [f32],
    object: u32,
    clear: bool,
    /// Sample textures at level 0 (footprint 0) instead of by screen footprint.
    level0: bool,
}

impl Pixels<'_, '_> {
    #[inline(always)]
    fn emit(&mut self, x: u32, s: &Surface) {
        let j = self.row_base + x as usize;
        self.out.write(j, self.object, self.depth[j], s);
        if self.clear {
            self.out.mask[j] = 0.0;
        }
    }

    /// [`Self::emit`] of pixels `x..x + 4` (the lanes of `s`).
    #[inline(always)]
    fn emit4(&mut self, x: u32, s: &Plain4) {
        let j = self.row_base + x as usize;
        self.out.write4(j, self.object, &self.depth[j..j + 4], s);
        if self.clear {
            self.out.mask[j..j + 4].fill(0.0);
        }
    }
}

/// The surfaces of the winning triangle at pixels `x0..x1` of row `y` (one run of one winner),
/// written to `px`; every pixel exactly as [`shade`] gives it.
#[inline]
fn shade_run(st: &ShadeTri, ts: &TriangleSurface<'_>, x0: u32, x1: u32, y: u32, mut px_out: Pixels<'_, '_>) {
    let py = y as f32 + 0.5;
    // The centres of pixels x..x + 4, as `shade` computes one.
    let centres = |x: u32| Vec4::new(x as f32 + 0.5, (x + 1) as f32 + 0.5, (x + 2) as f32 + 0.5, (x + 3) as f32 + 0.5);
    if px_out.level0 && ts.is_textured() {
        // Textures at level 0, as a secondary ray's hit samples them (the fallbacks' layers).
        for x in x0..x1 {
            px_out.emit(x, &ts.at(clamp_bary(st.bary(x as f32 + 0.5, py)), 0.0));
        }
        return;
    }
    match ts.uvs() {
        // Pixel centres x + 0.5 are exact in f32 below 2²², so the planes one pixel right of
        // pixel x (`px + 1`) are those of pixel x + 1 bit for bit: computed once, used twice.
        Some(uvs) if ts.uses_footprint() && x1 < 1 << 22 => {
            // Barycentrics and footprints four pixels at a time, then the surfaces one at a time.
            let mut x0 = x0;
            while x0 + 4 <= x1 {
                let here = st.bary4(centres(x0), py);
                let (right, down) = (st.bary4(centres(x0 + 1), py), st.bary4(centres(x0), py + 1.0));
                let b = clamp_bary4(here);
                let footprints = footprint4(uvs, b, right, down);
                for (k, footprint) in footprints.into_iter().enumerate() {
                    px_out.emit(x0 + k as u32, &ts.at(hybrid_core::lanes::lane(b, k), footprint));
                }
                x0 += 4;
            }
            let mut here = st.bary(x0 as f32 + 0.5, py);
            for x in x0..x1 {
                let px = x as f32 + 0.5;
                let right = st.bary((x + 1) as f32 + 0.5, py);
                let down = st.bary(px, py + 1.0);
                let b = clamp_bary(here);
                px_out.emit(x, &ts.at(b, footprint(uvs, b, right, down)));
                here = right;
            }
        }
        // No texture: four pixels at a time, then one at a time (the same surfaces).
        _ if !ts.is_textured() => {
            let mut x0 = x0;
            while x0 + 4 <= x1 {
                px_out.emit4(x0, &ts.plain4(clamp_bary4(st.bary4(centres(x0), py))));
                x0 += 4;
            }
            for x in x0..x1 {
                px_out.emit(x, &shade(st, ts, x, y));
            }
        }
        _ => {
            for x in x0..x1 {
                px_out.emit(x, &shade(st, ts, x, y));
            }
        }
    }
}

/// UV change per pixel (the larger of the steps one pixel right and one down) at clamped
/// barycentrics `b`, given the raw barycentrics of those two neighbours; 0 when unknown.
#[inline]
fn footprint([u0, u1, u2]: [glam::Vec2; 3], b: Vec3, right: Option<Vec3>, down: Option<Vec3>) -> f32 {
    let uv = |b: Vec3| u0 * b.x + u1 * b.y + u2 * b.z;
    let at = uv(b);
    // Screen derivatives of the UV: the same planes one pixel right and one pixel down.
    let dx = right.map(|b| uv(b).distance(at));
    let dy = down.map(|b| uv(b).distance(at));
    let f = match (dx, dy) {
        (Some(a), Some(b)) => a.max(b),
        (Some(a), None) | (None, Some(a)) => a,
        (None, None) => 0.0,
    };
    if f.is_finite() { f } else { 0.0 }
}

/// [`footprint`] at four pixels: clamped barycentrics `b` as lanes, and the raw barycentrics
/// (with their valid lanes, [`ShadeTri::bary4`]) one pixel right and one down.
#[inline]
fn footprint4([u0, u1, u2]: [glam::Vec2; 3], b: V3, right: (V3, BVec4A), down: (V3, BVec4A)) -> [f32; 4] {
    let uv = |b: V3| [0, 1].map(|k| Vec4::splat(u0[k]) * b[0] + Vec4::splat(u1[k]) * b[1] + Vec4::splat(u2[k]) * b[2]);
    let at = uv(b);
    // `Vec2::distance`: √(d.x² + d.y²) of the difference.
    let distance = |n: V3| {
        let q = uv(n);
        let d = [q[0] - at[0], q[1] - at[1]];
        (d[0] * d[0] + d[1] * d[1]).sqrt()
    };
    let (dx, dy) = (distance(right.0), distance(down.0));
    let (vx, vy) = (right.1.bitmask(), down.1.bitmask());
    [0, 1, 2, 3].map(|k| {
        let f = match (vx >> k & 1 != 0, vy >> k & 1 != 0) {
            (true, true) => dx[k].max(dy[k]),
            (true, false) => dx[k],
            (false, true) => dy[k],
            (false, false) => 0.0,
        };
        if f.is_finite() { f } else { 0.0 }
    })
}

/// The surface of the winning triangle at pixel (x, y).
#[inline]
fn shade(st: &ShadeTri, ts: &TriangleSurface<'_>, x: u32, y: u32) -> Surface {
    let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
    let b = clamp_bary(st.bary(px, py));
    let footprint = match ts.uvs() {
        Some(uvs) if ts.uses_footprint() => footprint(uvs, b, st.bary(px + 1.0, py), st.bary(px, py + 1.0)),
        _ => 0.0,
    };
    ts.at(b, footprint)
}

#[cfg(test)]
mod tests {
    use super::*;
    use hybrid_core::test_rng::Rng;

    /// The tests' oracle of coverage: calls `hit(x, y, covered)` for every pixel centre of the
    /// bounding box of `t` in rows `rows`, `covered` by the top-left rule.
    fn for_each_covered(t: &RasterTri, rows: std::ops::Range<u32>, mut hit: impl FnMut(u32, u32, bool)) {
        walk_rows(t, rows, |y, [mut e0, mut e1, mut e2], step| {
            for x in t.x0..=t.x1 {
                hit(x, y, (e0 | e1 | e2) >= 0);
                e0 += step[0];
                e1 += step[1];
                e2 += step[2];
            }
        });
    }

    fn vpt(w: u32, h: u32) -> Viewport {
        Viewport { vp: Mat4::IDENTITY, width: w, height: h, gx: 1.0 + 2.0 * GUARD_PX / w as f32, gy: 1.0 + 2.0 * GUARD_PX / h as f32 }
    }

    /// Coverage counts of fixed-point triangles on a w × h grid.
    fn count(tris: &[[[i32; 2]; 3]], w: u32, h: u32) -> Vec<u32> {
        let v = vpt(w, h);
        let mut c = vec![0u32; (w * h) as usize];
        for t in tris {
            if let Some(rt) = coverage(*t, &v) {
                for_each_covered(&rt, 0..h, |x, y, covered| c[(y * w + x) as usize] += u32::from(covered));
            }
        }
        c
    }

    /// A subpixel coordinate for the fuzz-style tests: half the time exactly on a pixel centre or
    /// pixel corner, to hit the tie cases.
    fn coord(rng: &mut Rng, max_px: i32) -> i32 {
        let px = (rng.next_u64() % max_px as u64) as i32;
        match rng.next_u64() % 4 {
            0 => px * SUB as i32 + HALF as i32,
            1 => px * SUB as i32,
            _ => px * SUB as i32 + (rng.next_u64() % SUB as u64) as i32,
        }
    }

    /// Is the pixel centre strictly inside or on the boundary of the convex polygon?
    fn inside_convex(poly: &[[i32; 2]], x: u32, y: u32) -> (bool, bool) {
        let (px, py) = (x as i64 * SUB + HALF, y as i64 * SUB + HALF);
        let n = poly.len();
        let mut sign = 0i64;
        let mut on_edge = false;
        for k in 0..n {
            let [ax, ay] = poly[k].map(i64::from);
            let [bx, by] = poly[(k + 1) % n].map(i64::from);
            let e = (bx - ax) * (py - ay) - (by - ay) * (px - ax);
            if e == 0 {
                on_edge = true;
                continue;
            }
            if sign == 0 {
                sign = e.signum();
            } else if e.signum() != sign {
                return (false, false);
            }
        }
        (true, on_edge)
    }

    #[test]
    fn covered_span_is_exactly_the_pixels_with_every_edge_non_negative() {
        let mut rng = Rng(0x5eed_1234);
        let mut nonempty = 0;
        for k in 0..20_000 {
            let last = (rng.f() * 300.0) as usize;
            let pick = |rng: &mut Rng, scale: f32| ((rng.f() - 0.5) * scale) as i64;
            // Steps of either sign and zero; values around the row's crossings, and exact hits.
            let step = [0, 1, 2].map(|i| if (k + i) % 9 == 0 { 0 } else { pick(&mut rng, 4.0e5) });
            let e = [0, 1, 2].map(|i| {
                let v = pick(&mut rng, 6.0e7);
                if (k + i) % 5 == 0 && step[i] != 0 { -step[i] * (rng.f() * last as f32) as i64 } else { v }
            });
            let brute: Vec<usize> = (0..=last).filter(|&x| (0..3).all(|i| e[i] + step[i] * x as i64 >= 0)).collect();
            let want = brute.first().map(|&a| (a, *brute.last().unwrap()));
            assert_eq!(covered_span(e, step, last), want, "e {e:?} step {step:?} last {last}");
            // Convex: the covered pixels are contiguous.
            if let Some((a, b)) = want {
                assert_eq!(brute.len(), b - a + 1);
                nonempty += 1;
            }
        }
        assert!(nonempty > 2000, "only {nonempty} rows had covered pixels");
    }

    #[test]
    fn shared_edge_pixels_are_drawn_exactly_once() {
        let (w, h) = (40u32, 30u32);
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let mut checked = 0;
        for _ in 0..400 {
            let q: Vec<[i32; 2]> = (0..4).map(|_| [coord(&mut rng, w as i32), coord(&mut rng, h as i32)]).collect();
            // Keep convex quads in consistent order (both diagonals split it into two triangles).
            let e = |a: [i32; 2], b: [i32; 2], c: [i32; 2]| area2([a, b, c]).signum();
            let s = e(q[0], q[1], q[2]);
            if s == 0 || e(q[1], q[2], q[3]) != s || e(q[2], q[3], q[0]) != s || e(q[3], q[0], q[1]) != s {
                continue;
            }
            // Split along the diagonal 0–2; the second triangle in reverse winding too.
            let tris = [[q[0], q[1], q[2]], [q[2], q[0], q[3]]];
            let c = count(&tris, w, h);
            for y in 0..h {
                for x in 0..w {
                    let (inside, on_edge) = inside_convex(&q, x, y);
                    let n = c[(y * w + x) as usize];
                    assert!(n <= 1, "pixel ({x}, {y}) drawn {n} times for quad {q:?}");
                    if inside && !on_edge {
                        assert_eq!(n, 1, "interior pixel ({x}, {y}) missing for quad {q:?}");
                    }
                    if !inside {
                        assert_eq!(n, 0, "outside pixel ({x}, {y}) drawn for quad {q:?}");
                    }
                }
            }
            checked += 1;
        }
        assert!(checked > 50, "too few convex quads generated: {checked}");
    }

    /// Small triangles (rows of 1–12 pixels, the fixed-count rows and the ones past them), up to
    /// the image's right edge, over a visibility buffer that already holds random depths and
    /// ids: every pixel ends as the plain per-pixel test leaves it.
    #[test]
    fn short_rows_match_the_per_pixel_depth_test() {
        let (w, h) = (37u32, 21u32);
        let v = vpt(w, h);
        let mut rng = Rng(0x0005_40c7_2055);
        let (mut won, mut lost) = (0, 0);
        for n in 0..3000u32 {
            let size = 1 + (rng.next_u64() % 12) as i32;
            let (ax, ay) = ((rng.next_u64() % w as u64) as i32 - 2, (rng.next_u64() % h as u64) as i32 - 2);
            let tri = [0, 1, 2].map(|_| {
                let d = |rng: &mut Rng| (rng.next_u64() % (size as u64 * SUB as u64)) as i32;
                [ax * SUB as i32 + d(&mut rng), ay * SUB as i32 + d(&mut rng)]
            });
            let Some(mut rt) = coverage(tri, &v) else { continue };
            rt.z0 = rng.f();
            rt.dzdx = (rng.f() - 0.5) * 0.1;
            rt.dzdy = (rng.f() - 0.5) * 0.1;
            for y_lo in (0..h).step_by(BAND_ROWS as usize) {
                let y_hi = (y_lo + BAND_ROWS).min(h);
                let len = ((y_hi - y_lo) * w) as usize;
                let depth: Vec<f32> = (0..len).map(|_| rng.f()).collect();
                let ids: Vec<u32> = (0..len).map(|_| rng.next_u64() as u32).collect();
                let (mut want_depth, mut want_ids) = (depth.clone(), ids.clone());
                for_each_covered(&rt, y_lo..y_hi, |x, y, covered| {
                    let i = ((y - y_lo) * w + x) as usize;
                    let z = (rt.z0 + rt.dzdx * (x - rt.x0) as f32 + rt.dzdy * (y - rt.y0) as f32).min(1.0);
                    if covered && z > want_depth[i] {
                        (want_depth[i], want_ids[i]) = (z, n);
                        won += 1;
                    } else if covered {
                        lost += 1;
                    }
                });
                let (mut got_depth, mut got_ids) = (depth.clone(), ids.clone());
                depth_test(&rt, n, y_lo, y_hi, w as usize, &mut got_depth, &mut got_ids);
                assert_eq!(got_ids, want_ids, "{tri:?}, band from row {y_lo}");
                assert_eq!(
                    got_depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>(),
                    want_depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>()
                );
            }
        }
        assert!(won > 5000 && lost > 5000, "{won} covered pixels won, {lost} lost");
    }

    #[test]
    fn depth_test_covers_what_for_each_covered_covers() {
        let (w, h) = (40u32, 37u32);
        let v = vpt(w, h);
        let mut rng = Rng(0x5151_7a7a_0102_0304);
        let mut drawn = 0;
        for n in 0..300u32 {
            let tri = [0, 1, 2].map(|_| [coord(&mut rng, w as i32), coord(&mut rng, h as i32)]);
            let Some(mut rt) = coverage(tri, &v) else { continue };
            rt.z0 = 0.5;
            rt.dzdx = 0.001;
            rt.dzdy = -0.002;
            let mut want = vec![false; (w * h) as usize];
            for_each_covered(&rt, 0..h, |x, y, c| want[(y * w + x) as usize] |= c);
            // Bands of 16 rows, as the rasteriser runs them (the last one shorter).
            for y_lo in (0..h).step_by(BAND_ROWS as usize) {
                let y_hi = (y_lo + BAND_ROWS).min(h);
                let len = ((y_hi - y_lo) * w) as usize;
                let (mut depth, mut ids) = (vec![0.0f32; len], vec![VIS_NONE; len]);
                depth_test(&rt, n, y_lo, y_hi, w as usize, &mut depth, &mut ids);
                for i in 0..len {
                    let (x, y) = (i as u32 % w, y_lo + i as u32 / w);
                    let covered = want[(y * w + x) as usize];
                    assert_eq!(ids[i] == n, covered, "pixel ({x}, {y}) of {tri:?}");
                    if covered {
                        let z = (0.5 + 0.001 * (x - rt.x0) as f32 + -0.002 * (y - rt.y0) as f32).min(1.0);
                        assert_eq!(depth[i].to_bits(), z.to_bits());
                        drawn += 1;
                    }
                }
            }
        }
        assert!(drawn > 1000, "too few pixels drawn: {drawn}");
    }

    #[test]
    fn round_to_i32_matches_round() {
        let mut rng = Rng(0xdead_beef_1234_5678);
        let special =
            [0.5f32, -0.5, 1.5, -1.5, 2.5, 0.499_999_97, -0.499_999_97, 8_388_607.5, -8_388_607.5, 1e10, -1e10, 0.0, -0.0, f32::NAN];
        for x in special {
            assert_eq!(round_to_i32(x), x.round() as i32, "{x}");
        }
        for _ in 0..200_000 {
            let x = f32::from_bits(rng.next_u64() as u32);
            assert_eq!(round_to_i32(x), x.round() as i32, "{x}");
        }
    }

    #[test]
    fn axis_aligned_square_follows_top_left_rule() {
        // Square from pixel centre (2.5, 2.5) to (6.5, 6.5): centres on the top and left edges
        // are in, on the bottom and right edges out → exactly 4 × 4 pixels, x, y in 2..6.
        let p = |x: i32, y: i32| [x * SUB as i32 + HALF as i32, y * SUB as i32 + HALF as i32];
        let tris = [[p(2, 2), p(6, 2), p(6, 6)], [p(2, 2), p(6, 6), p(2, 6)]];
        let c = count(&tris, 10, 10);
        for y in 0..10u32 {
            for x in 0..10u32 {
                let want = u32::from((2..6).contains(&x) && (2..6).contains(&y));
                assert_eq!(c[(y * 10 + x) as usize], want, "({x}, {y})");
            }
        }
    }

    #[test]
    fn fan_around_shared_vertex_covers_once() {
        // A fan of triangles around a vertex on a pixel centre, closing the full circle.
        let (w, h) = (32u32, 32u32);
        for (cx, cy, n) in [(16i32, 16i32, 7usize), (15, 17, 12), (16, 16, 4)] {
            let centre = [cx * SUB as i32 + HALF as i32, cy * SUB as i32 + HALF as i32];
            let rim: Vec<[i32; 2]> = (0..n)
                .map(|k| {
                    let a = k as f32 / n as f32 * std::f32::consts::TAU + 0.3;
                    [centre[0] + (a.cos() * 10.0 * SUB as f32) as i32, centre[1] + (a.sin() * 10.0 * SUB as f32) as i32]
                })
                .collect();
            let tris: Vec<[[i32; 2]; 3]> = (0..n).map(|k| [centre, rim[k], rim[(k + 1) % n]]).collect();
            let c = count(&tris, w, h);
            assert_eq!(c[(cy as u32 * w + cx as u32) as usize], 1, "shared vertex pixel, n = {n}");
            for y in 0..h {
                for x in 0..w {
                    let (inside, on_edge) = inside_convex(&rim, x, y);
                    let k = c[(y * w + x) as usize];
                    assert!(k <= 1, "({x}, {y}) drawn {k} times");
                    if inside && !on_edge {
                        assert_eq!(k, 1, "({x}, {y}) missing");
                    }
                }
            }
        }
    }

    #[test]
    fn shade_run_matches_shade_bit_for_bit() {
        use glam::Vec2;
        use hybrid_scene::{ColorSpace, Material, Mesh, Object, ObjectSource, Scene, Texture, Transform};
        let texels = (0..64u32 * 32).map(|i| [(i * 7) as u8, (i * 13 + 5) as u8, (i * 29) as u8, (i * 3 + 100) as u8]).collect();
        let mut scene = Scene::new(Camera::default());
        scene.textures = vec![Texture::new("t", 64, 32, texels, ColorSpace::Srgb)];
        scene.materials = vec![
            Material { diffuse_map: Some(0), specular_map: Some(0), tiling: Vec2::new(3.0, 2.0), ..Material::default() },
            Material::default(),
        ];
        let mesh = |material: usize, smooth: bool| Mesh {
            positions: vec![Vec3::new(-1.0, 0.0, 0.0), Vec3::new(2.0, 0.5, -1.0), Vec3::new(0.0, 3.0, 0.5)],
            normals: if smooth { vec![Vec3::Z, Vec3::new(0.3, 0.1, 0.9), Vec3::new(-0.2, 0.4, 0.8)] } else { Vec::new() },
            uvs: vec![Vec2::new(0.1, 0.2), Vec2::new(1.7, 0.4), Vec2::new(0.6, 2.3)],
            indices: vec![[0, 1, 2]],
            material,
            ..Default::default()
        };
        // Untextured (the four-pixel path) smooth, flat and with vertex colours.
        let coloured = Mesh { colors: vec![Vec3::new(1.0, 0.2, 0.0), Vec3::new(0.0, 0.5, 1.0), Vec3::ONE], ..mesh(1, true) };
        let meshes = vec![mesh(0, true), mesh(0, false), mesh(1, true), mesh(1, false), coloured];
        scene.objects = vec![Object {
            name: "o".into(),
            source: ObjectSource::Plane,
            transform: Transform::default(),
            meshes,
            relevance: 1.0,
            cost: 1.0,
        }];
        let prepared = PreparedScene::new(&scene);
        let (w, h) = (37u32, 5u32);
        let mut rng = Rng(0x0123_4567_89ab_cdef);
        let mut f = || (rng.next_u64() % 2001) as f32 / 1000.0 - 1.0;
        for (k, &t) in prepared.triangles.iter().enumerate() {
            let ts = prepared.triangle_surface(t);
            for _ in 0..20 {
                // Planes of a plausible perspective triangle, and some with a sign change of
                // their sum inside the row (non-finite and clamped barycentrics).
                let planes = [0, 1, 2].map(|_| Vec3::new(f() + 1.2, f() * 0.05, f() * 0.05));
                let planes = if k % 2 == 0 { planes } else { planes.map(|p| p - Vec3::new(1.5, 0.0, 0.0)) };
                let st = ShadeTri { triangle: t, ref_px: [3.5, 1.5], planes };
                let (mut a, mut b) = (GBuffer::new(w, h), GBuffer::new(w, h));
                for y in 0..h {
                    let (x0, x1) = (y * 3, w - y);
                    for x in x0..x1 {
                        a.write((y * w + x) as usize, 7, 0.5, &shade(&st, &ts, x, y));
                    }
                    let depth = vec![0.5f32; (w * h) as usize];
                    let mut rows = b.bands_mut((w * h) as usize);
                    let px =
                        Pixels { out: &mut rows[0], row_base: (y * w) as usize, depth: &depth, object: 7, clear: false, level0: false };
                    shade_run(&st, &ts, x0, x1, y, px);
                }
                assert_eq!(gbuffer_bits(&a), gbuffer_bits(&b), "triangle {t:?}, planes {planes:?}");
            }
        }
    }

    /// Every bit of every target (f32 equality would let −0 = +0 and NaN ≠ NaN through).
    fn gbuffer_bits(g: &GBuffer) -> Vec<u32> {
        let v3 = |v: &[Vec3]| v.iter().flat_map(|v| v.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        let v4 = |v: &[Vec4]| v.iter().flat_map(|v| v.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        let f = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        [v3(&g.position), v3(&g.normal), v3(&g.emission), v3(&g.ambient), v4(&g.diffuse), v4(&g.specular), v3(&g.optical)]
            .concat()
            .into_iter()
            .chain(g.object_id.iter().copied())
            .chain(f(&g.mask))
            .chain(f(&g.depth))
            .collect()
    }

    #[test]
    fn four_pixel_barycentrics_match_one_pixel_bit_for_bit() {
        let mut rng = Rng(0x5eed_f0ba_7700);
        let mut f = || (rng.next_u64() % 4001) as f32 / 1000.0 - 2.0;
        let special = [0.0, -0.0, 1e-38, -1e30, f32::INFINITY, f32::NAN];
        let (mut valid, mut invalid) = (0, 0);
        for k in 0..4000 {
            let mut planes = [0, 1, 2].map(|_| Vec3::new(f(), f() * 0.1, f() * 0.1));
            if k % 5 == 0 {
                // Awkward planes: zero, huge, infinite or NaN coefficients.
                planes[k / 5 % 3][k / 15 % 3] = special[k / 45 % special.len()];
            }
            let st = ShadeTri { triangle: TriangleRef { mesh: 0, triangle: 0 }, ref_px: [f() * 50.0, f() * 50.0], planes };
            let (x, y) = ((f() * 40.0 + 80.0) as u32, f() * 30.0 + 40.0);
            let px = Vec4::new(x as f32 + 0.5, (x + 1) as f32 + 0.5, (x + 2) as f32 + 0.5, (x + 3) as f32 + 0.5);
            let (b4, ok) = st.bary4(px, y);
            let clamped = clamp_bary4((b4, ok));
            for lane in 0..4 {
                let one = st.bary(px[lane], y);
                assert_eq!(ok.bitmask() >> lane & 1 != 0, one.is_some(), "planes {planes:?} at {}", px[lane]);
                if let Some(b) = one {
                    assert_eq!(hybrid_core::lanes::lane(b4, lane).to_array().map(f32::to_bits), b.to_array().map(f32::to_bits));
                    valid += 1;
                } else {
                    invalid += 1;
                }
                let c = hybrid_core::lanes::lane(clamped, lane);
                assert_eq!(c.to_array().map(f32::to_bits), clamp_bary(one).to_array().map(f32::to_bits), "planes {planes:?}");
            }
        }
        assert!(valid > 10_000 && invalid > 100, "{valid} valid, {invalid} invalid lanes");
    }

    #[test]
    fn band_rows_write_matches_gbuffer_write() {
        let s = Surface {
            position: Vec3::new(1.0, 2.0, 3.0),
            normal: Vec3::Y,
            emission: Vec3::splat(0.1),
            ambient: Vec3::splat(0.2),
            diffuse: Vec3::new(0.3, 0.4, 0.5),
            opacity: 0.6,
            specular: Vec3::splat(0.7),
            shininess: 0.8,
            reflectivity: 0.9,
            ior: 1.4,
        };
        let mut a = GBuffer::new(3, 2);
        a.write(4, 7, 0.5, &s);
        let mut b = GBuffer::new(3, 2);
        b.mask.iter_mut().for_each(|m| *m = 1.0);
        {
            let mut rows = b.bands_mut(6);
            rows[0].write(4, 7, 0.5, &s);
            for i in [0, 1, 2, 3, 5] {
                rows[0].clear(i);
            }
            rows[0].mask[4] = 0.0;
        }
        assert_eq!(a, b);
    }

    #[test]
    fn clipping_keeps_shared_cut_points_identical() {
        // Two triangles sharing an edge that crosses the near plane: the cut point on that edge
        // must be bit-identical in both, whatever the winding.
        let v = Viewport { vp: Mat4::IDENTITY, width: 64, height: 64, gx: 100.0, gy: 100.0 };
        let a = Vec4::new(0.1, 0.2, 0.3, 1.0); // inside (z < w)
        let b = Vec4::new(-0.3, 0.1, 2.0, 0.5); // in front of near (z > w)
        let c1 = Vec4::new(0.5, -0.5, 0.2, 1.0);
        let c2 = Vec4::new(-0.5, 0.6, 0.1, 1.0);
        let mut p1 = [ClipVert { c: Vec4::ZERO }; 9];
        let mut p2 = [ClipVert { c: Vec4::ZERO }; 9];
        let n1 = clip_polygon(&mut p1, [a, b, c1], CLIP_NEAR, &v);
        let n2 = clip_polygon(&mut p2, [b, a, c2], CLIP_NEAR, &v);
        let cut = |p: &[ClipVert]| -> Vec<[u32; 4]> {
            p.iter().filter(|q| q.c != a && q.c != c1 && q.c != c2).map(|q| q.c.to_array().map(f32::to_bits)).collect()
        };
        let (k1, k2) = (cut(&p1[..n1]), cut(&p2[..n2]));
        assert_eq!(n1, 4);
        assert_eq!(n2, 4);
        assert!(k1.iter().any(|x| k2.contains(x)), "no shared cut point: {k1:?} vs {k2:?}");
        for q in &p1[..n1] {
            assert!(q.c.z <= q.c.w * (1.0 + 1e-6), "vertex in front of near after clipping: {}", q.c);
        }
    }
}
