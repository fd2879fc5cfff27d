//! The frame's buffers (design §2, paper Table 2), as plain row-major arrays (row 0 at the top).
//! The CPU backend writes them directly; the GPU backend reads its textures back into them for
//! dumps and tests, so both are compared buffer by buffer.

use glam::{Vec3, Vec4};

use crate::lanes::aos;
use crate::prepare::Plain4;

/// Object id of pixels no object covers (sky).
pub const NO_OBJECT: u32 = u32::MAX;

/// What the G-buffer holds for one covered pixel: everything the lighting, trace and blend
/// stages need about the visible surface (no primary rays needed).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Surface {
    /// World position.
    pub position: Vec3,
    /// World shading normal (normal-mapped, unit length) as the mesh orients it. Lighting flips it
    /// towards the viewer; refraction uses its side to tell entering from leaving.
    pub normal: Vec3,
    pub emission: Vec3,
    pub ambient: Vec3,
    /// Linear diffuse colour (material × texture × vertex colour).
    pub diffuse: Vec3,
    /// 1 = opaque, 0 = fully transparent.
    pub opacity: f32,
    pub specular: Vec3,
    /// 0..1 (exponent 1..255, see `hybrid_scene::specular_exponent`).
    pub shininess: f32,
    pub reflectivity: f32,
    pub ior: f32,
}

/// The G-buffer of design §2: one entry per pixel in every target.
#[derive(Debug, Clone, PartialEq)]
pub struct GBuffer {
    pub width: u32,
    pub height: u32,
    pub position: Vec<Vec3>,
    /// Zero vector where nothing is drawn (listing 8a tests for it).
    pub normal: Vec<Vec3>,
    pub emission: Vec<Vec3>,
    pub ambient: Vec<Vec3>,
    /// RGB diffuse, A opacity.
    pub diffuse: Vec<Vec4>,
    /// RGB specular, A shininess (0..1).
    pub specular: Vec<Vec4>,
    /// Reflectivity, IOR, opacity.
    pub optical: Vec<Vec3>,
    /// Which object covers the pixel; [`NO_OBJECT`] for none.
    pub object_id: Vec<u32>,
    /// Heuristic mask: > 0 = ray trace this pixel.
    pub mask: Vec<f32>,
    /// Reversed-Z depth: near 1, far 0, 0 where nothing is drawn.
    pub depth: Vec<f32>,
}

impl GBuffer {
    /// A cleared G-buffer: no object anywhere, depth 0 (the far plane), mask 0.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            position: vec![Vec3::ZERO; n],
            normal: vec![Vec3::ZERO; n],
            emission: vec![Vec3::ZERO; n],
            ambient: vec![Vec3::ZERO; n],
            diffuse: vec![Vec4::ZERO; n],
            specular: vec![Vec4::ZERO; n],
            optical: vec![Vec3::ZERO; n],
            object_id: vec![NO_OBJECT; n],
            mask: vec![0.0; n],
            depth: vec![0.0; n],
        }
    }

    pub fn len(&self) -> usize {
        self.object_id.len()
    }
    pub fn is_empty(&self) -> bool {
        self.object_id.is_empty()
    }

    /// The surface at pixel `i`, or `None` where no object is drawn.
    #[inline]
    pub fn surface(&self, i: usize) -> Option<Surface> {
        if self.object_id[i] == NO_OBJECT {
            return None;
        }
        let (d, s, o) = (self.diffuse[i], self.specular[i], self.optical[i]);
        Some(Surface {
            position: self.position[i],
            normal: self.normal[i],
            emission: self.emission[i],
            ambient: self.ambient[i],
            diffuse: d.truncate(),
            opacity: d.w,
            specular: s.truncate(),
            shininess: s.w,
            reflectivity: o.x,
            ior: o.y,
        })
    }

    /// Writes `surface` (covered by `object_id` at reversed-Z `depth`) into pixel `i`.
    #[inline]
    pub fn write(&mut self, i: usize, object_id: u32, depth: f32, s: &Surface) {
        self.position[i] = s.position;
        self.normal[i] = s.normal;
        self.emission[i] = s.emission;
        self.ambient[i] = s.ambient;
        self.diffuse[i] = s.diffuse.extend(s.opacity);
        self.specular[i] = s.specular.extend(s.shininess);
        self.optical[i] = Vec3::new(s.reflectivity, s.ior, s.opacity);
        self.object_id[i] = object_id;
        self.depth[i] = depth;
    }
}

/// Stage outputs after the G-buffer: the P-buffer (lighting), the trace stage's three buffers
/// (paper Fig. 5) and the final image.
/// `Default` is the empty 0×0 set (for a frame loop to fill).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FrameBuffers {
    pub width: u32,
    pub height: u32,
    /// Deferred Blinn–Phong result (linear). Sky pixels hold the skybox colour.
    pub lighting: Vec<Vec3>,
    /// 1 minus the light blocked from each shadow-casting light (listing 8a), linear.
    pub shadow: Vec<Vec3>,
    pub reflection: Vec<Vec3>,
    pub refraction: Vec<Vec3>,
    /// The raster fallbacks' terms (issue 18), the same quantities as `shadow`, `reflection` and
    /// `refraction` from shadow maps and probes: written for every covered polygon pixel the
    /// trace stage left out (1, 0, 0 elsewhere); empty when the frame has no fallbacks
    /// (`--fallback none`, `rt-only`).
    pub shadow_fallback: Vec<Vec3>,
    pub reflection_fallback: Vec<Vec3>,
    pub refraction_fallback: Vec<Vec3>,
    /// Final image, sRGB-encoded 8-bit RGBA (alpha 255).
    pub final_srgb: Vec<[u8; 4]>,
}

impl FrameBuffers {
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            lighting: vec![Vec3::ZERO; n],
            shadow: vec![Vec3::ONE; n],
            reflection: vec![Vec3::ZERO; n],
            refraction: vec![Vec3::ZERO; n],
            shadow_fallback: Vec::new(),
            reflection_fallback: Vec::new(),
            refraction_fallback: Vec::new(),
            final_srgb: vec![[0, 0, 0, 255]; n],
        }
    }
}

/// Object id written where the RT-scene (the point-cloud capsule, paper 2) is the visible
/// surface after the depth merge.
pub const RT_SCENE_OBJECT: u32 = u32::MAX - 1;

/// Whether an object id names a scene object (a polygon), not the sky or the RT-scene.
#[inline]
pub fn is_polygon(object_id: u32) -> bool {
    object_id != NO_OBJECT && object_id != RT_SCENE_OBJECT
}

/// The capsule's frame after unpacking (paper 2, block U): linear colour and reversed-Z depth
/// per pixel; `depth == 0.0` where the capsule drew nothing (alpha ≤ 0.1 was discarded).
#[derive(Debug, Clone, PartialEq)]
pub struct RtLayer {
    pub width: u32,
    pub height: u32,
    pub color: Vec<Vec3>,
    pub depth: Vec<f32>,
}

impl RtLayer {
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self { width, height, color: vec![Vec3::ZERO; n], depth: vec![0.0; n] }
    }
}

/// One band's rows of every G-buffer target (the band's slices of the frame's vectors).
pub struct BandRows<'a> {
    pub position: &'a mut [Vec3],
    pub normal: &'a mut [Vec3],
    pub emission: &'a mut [Vec3],
    pub ambient: &'a mut [Vec3],
    pub diffuse: &'a mut [Vec4],
    pub specular: &'a mut [Vec4],
    pub optical: &'a mut [Vec3],
    pub object_id: &'a mut [u32],
    pub mask: &'a mut [f32],
    pub depth: &'a mut [f32],
}

impl BandRows<'_> {
    /// Pixels in the band.
    pub fn len(&self) -> usize {
        self.depth.len()
    }

    pub fn is_empty(&self) -> bool {
        self.depth.is_empty()
    }

    pub fn set_mask(&mut self, i: usize, mask: f32) {
        self.mask[i] = mask;
    }

    /// Exactly what [`GBuffer::write`] does, for a band's slices (a test checks they agree).
    #[inline(always)]
    pub fn write(&mut self, i: usize, object_id: u32, depth: f32, s: &Surface) {
        self.position[i] = s.position;
        self.normal[i] = s.normal;
        self.emission[i] = s.emission;
        self.ambient[i] = s.ambient;
        self.diffuse[i] = s.diffuse.extend(s.opacity);
        self.specular[i] = s.specular.extend(s.shininess);
        self.optical[i] = Vec3::new(s.reflectivity, s.ior, s.opacity);
        self.object_id[i] = object_id;
        self.depth[i] = depth;
    }

    /// [`Self::write`] of the four surfaces of `s` at pixels `i..i + 4`.
    #[inline(always)]
    pub fn write4(&mut self, i: usize, object_id: u32, depth: &[f32], s: &Plain4) {
        let c = &s.constant;
        let r = i..i + 4;
        self.position[r.clone()].copy_from_slice(&aos(s.position));
        self.normal[r.clone()].copy_from_slice(&aos(s.normal));
        self.emission[r.clone()].fill(c.emission);
        self.ambient[r.clone()].fill(c.ambient);
        for (d, v) in self.diffuse[r.clone()].iter_mut().zip(aos(s.diffuse)) {
            *d = v.extend(c.opacity);
        }
        self.specular[r.clone()].fill(c.specular.extend(c.shininess));
        self.optical[r.clone()].fill(Vec3::new(c.reflectivity, c.ior, c.opacity));
        self.object_id[r.clone()].fill(object_id);
        self.depth[r].copy_from_slice(depth);
    }

    /// What [`GBuffer::new`] holds in a pixel (a test checks they agree).
    #[inline]
    pub fn clear(&mut self, i: usize) {
        self.position[i] = Vec3::ZERO;
        self.normal[i] = Vec3::ZERO;
        self.emission[i] = Vec3::ZERO;
        self.ambient[i] = Vec3::ZERO;
        self.diffuse[i] = Vec4::ZERO;
        self.specular[i] = Vec4::ZERO;
        self.optical[i] = Vec3::ZERO;
        self.object_id[i] = NO_OBJECT;
        self.mask[i] = 0.0;
        self.depth[i] = 0.0;
    }
}

impl GBuffer {
    /// The G-buffer's targets cut into runs of `band_len` pixels, one [`BandRows`] each, to be
    /// written in parallel.
    pub fn bands_mut(&mut self, band_len: usize) -> Vec<BandRows<'_>> {
        let g = self;
        let mut position = g.position.chunks_mut(band_len);
        let mut normal = g.normal.chunks_mut(band_len);
        let mut emission = g.emission.chunks_mut(band_len);
        let mut ambient = g.ambient.chunks_mut(band_len);
        let mut diffuse = g.diffuse.chunks_mut(band_len);
        let mut specular = g.specular.chunks_mut(band_len);
        let mut optical = g.optical.chunks_mut(band_len);
        let mut object_id = g.object_id.chunks_mut(band_len);
        let mut mask = g.mask.chunks_mut(band_len);
        let mut depth = g.depth.chunks_mut(band_len);
        let mut out = Vec::new();
        while let (
            Some(position),
            Some(normal),
            Some(emission),
            Some(ambient),
            Some(diffuse),
            Some(specular),
            Some(optical),
            Some(object_id),
            Some(mask),
            Some(depth),
        ) = (
            position.next(),
            normal.next(),
            emission.next(),
            ambient.next(),
            diffuse.next(),
            specular.next(),
            optical.next(),
            object_id.next(),
            mask.next(),
            depth.next(),
        ) {
            out.push(BandRows { position, normal, emission, ambient, diffuse, specular, optical, object_id, mask, depth });
        }
        out
    }
}
