//! `prepare`: the scene in world space, once per scene (not per frame). Raster, trace and the
//! capsule all read this; it also evaluates a material at a point of a triangle, so the G-buffer
//! (raster) and secondary hits (trace) see exactly the same surface.

use crate::Surface;
use crate::lanes::{V3, lerp3, normalize_or3, splat3};
use glam::{Mat3, Vec2, Vec3, Vec4};
use hybrid_scene::model::normal_matrix;
use hybrid_scene::{Aabb, ColorSpace, Material, Scene, Texture};

/// One mesh of one object, transformed to world space.
#[derive(Debug, Clone)]
pub struct WorldMesh {
    /// Index of the object in `Scene::objects` (the object id written to the G-buffer).
    pub object: u32,
    pub material: usize,
    pub positions: Vec<Vec3>,
    /// World normals; empty = flat shading.
    pub normals: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    /// World tangents with bitangent sign; empty = no normal mapping possible.
    pub tangents: Vec<Vec4>,
    pub colors: Vec<Vec3>,
    pub indices: Vec<[u32; 3]>,
}

/// A triangle of the whole scene: which mesh, which triangle in it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TriangleRef {
    pub mesh: u32,
    pub triangle: u32,
}

/// The scene prepared for the CPU backend.
#[derive(Debug)]
pub struct PreparedScene<'s> {
    pub scene: &'s Scene,
    pub meshes: Vec<WorldMesh>,
    /// World bounds per object (index = object id); empty boxes for objects without geometry.
    pub object_bounds: Vec<Aabb>,
    /// Every triangle of every mesh, in mesh order (the trace stage's primitive list).
    pub triangles: Vec<TriangleRef>,
    /// Per material (index as `scene.materials`): its shadow-ray transparency class
    /// ([`material_shadow`]), found once here because it can scan whole textures, and the CPU
    /// BVH, the GPU's BVHs and the shadow-map casters all read it.
    pub material_shadow: Vec<f32>,
}

impl<'s> PreparedScene<'s> {
    pub fn new(scene: &'s Scene) -> Self {
        let mut meshes = Vec::new();
        let mut object_bounds = Vec::with_capacity(scene.objects.len());
        for (oi, obj) in scene.objects.iter().enumerate() {
            let m = obj.transform.matrix();
            let nm: Mat3 = normal_matrix(&m);
            let m3 = Mat3::from_mat4(m);
            let mut bounds = Aabb::EMPTY;
            for mesh in &obj.meshes {
                let positions: Vec<Vec3> = mesh.positions.iter().map(|p| m.transform_point3(*p)).collect();
                positions.iter().for_each(|p| bounds.grow(*p));
                let normals = mesh.normals.iter().map(|n| (nm * *n).normalize_or(Vec3::Y)).collect();
                let tangents = mesh.tangents.iter().map(|t| (m3 * t.truncate()).normalize_or(Vec3::X).extend(t.w)).collect();
                meshes.push(WorldMesh {
                    object: oi as u32,
                    material: mesh.material,
                    positions,
                    normals,
                    uvs: mesh.uvs.clone(),
                    tangents,
                    colors: mesh.colors.clone(),
                    indices: mesh.indices.clone(),
                });
            }
            object_bounds.push(bounds);
        }
        let triangles = meshes
            .iter()
            .enumerate()
            .flat_map(|(mi, m)| (0..m.indices.len() as u32).map(move |t| TriangleRef { mesh: mi as u32, triangle: t }))
            .collect();
        let material_shadow = scene.materials.iter().map(|m| material_shadow(m, &scene.textures)).collect();
        Self { scene, meshes, object_bounds, triangles, material_shadow }
    }

    /// The shadow-ray transparency class of mesh `mesh`'s material ([`material_shadow`]; 1, casts
    /// no shadow, for a material index out of range).
    #[inline]
    pub fn mesh_shadow(&self, mesh: usize) -> f32 {
        self.material_shadow.get(self.meshes[mesh].material).copied().unwrap_or(1.0)
    }

    /// The three world-space corners of a triangle.
    #[inline]
    pub fn triangle(&self, t: TriangleRef) -> [Vec3; 3] {
        let m = &self.meshes[t.mesh as usize];
        m.indices[t.triangle as usize].map(|i| m.positions[i as usize])
    }

    pub fn material(&self, t: TriangleRef) -> &Material {
        &self.scene.materials[self.meshes[t.mesh as usize].material]
    }

    /// The surface at barycentric coordinates `bary` (weights of the three corners, summing to 1)
    /// of triangle `t`. `uv_footprint` is the UV change per pixel for mip selection (0 = finest).
    /// Same as `self.triangle_surface(t).at(bary, uv_footprint)`.
    pub fn surface_at(&self, t: TriangleRef, bary: Vec3, uv_footprint: f32) -> Surface {
        self.triangle_surface(t).at(bary, uv_footprint)
    }

    /// Everything [`Self::surface_at`] needs of triangle `t` gathered once (corner attributes,
    /// material, the geometric normal of flat triangles), for evaluating many points of one
    /// triangle (the raster's pixels of one winner).
    #[inline]
    pub fn triangle_surface(&self, t: TriangleRef) -> TriangleSurface<'_> {
        let mesh = &self.meshes[t.mesh as usize];
        let [i0, i1, i2] = mesh.indices[t.triangle as usize].map(|i| i as usize);
        let corners = |v: &[Vec3]| if v.is_empty() { None } else { Some([v[i0], v[i1], v[i2]]) };
        let material = &self.scene.materials[mesh.material];
        let positions = [mesh.positions[i0], mesh.positions[i1], mesh.positions[i2]];
        let normals = corners(&mesh.normals);
        // Smooth triangles need the geometric normal only where the interpolated one cannot be
        // normalised ([`TriangleSurface::at`] computes it there).
        let geometric = if normals.is_none() { geometric_normal(positions) } else { Vec3::Y };
        let tangents = if material.normal_map.is_some() && !mesh.tangents.is_empty() {
            Some([mesh.tangents[i0], mesh.tangents[i1], mesh.tangents[i2]])
        } else {
            None
        };
        TriangleSurface {
            material,
            textures: &self.scene.textures,
            positions,
            normals,
            geometric,
            uvs: if mesh.uvs.is_empty() { None } else { Some([mesh.uvs[i0], mesh.uvs[i1], mesh.uvs[i2]]) },
            colors: corners(&mesh.colors),
            tangents,
            textured: material.emission_map.is_some()
                || material.ambient_map.is_some()
                || material.diffuse_map.is_some()
                || material.specular_map.is_some()
                || material.normal_map.is_some()
                || material.optical_map.is_some(),
        }
    }
}

/// The unit geometric normal of a triangle (Y when degenerate).
#[inline]
fn geometric_normal(p: [Vec3; 3]) -> Vec3 {
    (p[1] - p[0]).cross(p[2] - p[0]).normalize_or(Vec3::Y)
}

/// One triangle's corner attributes and material, ready to evaluate surfaces at many points
/// ([`PreparedScene::triangle_surface`]).
#[derive(Debug, Clone, Copy)]
pub struct TriangleSurface<'a> {
    material: &'a Material,
    textures: &'a [Texture],
    positions: [Vec3; 3],
    normals: Option<[Vec3; 3]>,
    /// The geometric normal, for flat triangles only (`normals` is `None`).
    geometric: Vec3,
    uvs: Option<[Vec2; 3]>,
    colors: Option<[Vec3; 3]>,
    /// Only where the material has a normal map and the mesh tangents.
    tangents: Option<[Vec4; 3]>,
    textured: bool,
}

impl TriangleSurface<'_> {
    /// Whether the triangle has UVs and its material any texture map (else the UV footprint
    /// passed to [`Self::at`] is unused).
    #[inline]
    pub fn uses_footprint(&self) -> bool {
        self.textured && self.uvs.is_some()
    }

    /// The corner UVs (`None` for meshes without UVs).
    #[inline]
    pub fn uvs(&self) -> Option<[Vec2; 3]> {
        self.uvs
    }

    /// The surface at barycentric coordinates `bary` with UV footprint `uv_footprint`; see
    /// [`PreparedScene::surface_at`].
    #[inline(always)]
    pub fn at(&self, bary: Vec3, uv_footprint: f32) -> Surface {
        let lerp3 = |v: [Vec3; 3]| v[0] * bary.x + v[1] * bary.y + v[2] * bary.z;
        let position = lerp3(self.positions);
        let mut normal = match self.normals {
            None => self.geometric,
            // `normalize_or(geometric_normal(..))`, the fallback only computed when taken.
            Some(n) => {
                let n = lerp3(n);
                let rcp = n.length_recip();
                if rcp.is_finite() && rcp > 0.0 { n * rcp } else { geometric_normal(self.positions) }
            }
        };
        let color = self.colors.map_or(Vec3::ONE, lerp3);
        if !self.textured {
            return self.untextured(position, normal, color);
        }
        let uv = self.uvs.map_or(Vec2::ZERO, |u| u[0] * bary.x + u[1] * bary.y + u[2] * bary.z);
        let mat = self.material;
        let uv = mat.offset + uv * mat.tiling;
        let tex = self.textures;
        let footprint = uv_footprint * mat.tiling.abs().max_element();
        // Absent maps sample as 1 (inline); present ones through one out-of-line call each.
        let sample = |id: Option<usize>| -> Vec4 {
            match id {
                Some(id) => sample_map(&tex[id], uv, footprint),
                None => Vec4::ONE,
            }
        };
        if let (Some(nm), Some(tg)) = (mat.normal_map, self.tangents) {
            let t4 = tg[0] * bary.x + tg[1] * bary.y + tg[2] * bary.z;
            let tangent = (t4.truncate() - normal * normal.dot(t4.truncate())).normalize_or_zero();
            if tangent != Vec3::ZERO {
                let sign = if tg[0].w < 0.0 { -1.0 } else { 1.0 };
                let bitangent = normal.cross(tangent) * sign;
                let n_ts = sample_texture(&tex[nm], uv, footprint).truncate() * 2.0 - Vec3::ONE;
                normal = (tangent * n_ts.x + bitangent * n_ts.y + normal * n_ts.z).normalize_or(normal);
            }
        }
        let d = sample(mat.diffuse_map);
        let s = sample(mat.specular_map);
        let o = sample(mat.optical_map);
        // Loaders give the ambient colour the diffuse map when a material names no ambient map
        // (OBJ without `map_Ka`, glTF): the same sample, taken once.
        let a = if mat.ambient_map == mat.diffuse_map { d } else { sample(mat.ambient_map) };
        Surface {
            position,
            normal,
            emission: mat.emission * sample(mat.emission_map).truncate(),
            ambient: mat.ambient * a.truncate(),
            diffuse: mat.diffuse * d.truncate() * color,
            // Opacity: material × diffuse-map alpha × optical-map B (Table 1).
            opacity: (mat.opacity * d.w * o.z).clamp(0.0, 1.0),
            specular: mat.specular * s.truncate(),
            shininess: (mat.shininess * s.w).clamp(0.0, 1.0),
            reflectivity: (mat.reflectivity * o.x).clamp(0.0, 1.0),
            ior: mat.ior * o.y,
        }
    }

    /// Whether the material has any texture map (else [`Self::plain4`] applies).
    #[inline]
    pub fn is_textured(&self) -> bool {
        self.textured
    }

    /// [`Self::at`] at four points of a triangle without texture maps (barycentrics as lanes),
    /// lane by lane bit for bit: the position, normal and diffuse colour of each lane, and the
    /// fields all four share.
    #[inline(always)]
    pub fn plain4(&self, bary: V3) -> Plain4 {
        debug_assert!(!self.textured);
        let position = lerp3(self.positions, bary);
        let normal = match self.normals {
            None => splat3(self.geometric),
            Some(n) => normalize_or3(lerp3(n, bary), splat3(geometric_normal(self.positions))),
        };
        let color = self.colors.map_or(splat3(Vec3::ONE), |c| lerp3(c, bary));
        let d = self.material.diffuse;
        let diffuse = [Vec4::splat(d.x) * color[0], Vec4::splat(d.y) * color[1], Vec4::splat(d.z) * color[2]];
        Plain4 { position, normal, diffuse, constant: self.untextured(Vec3::ZERO, Vec3::ZERO, Vec3::ONE) }
    }

    /// The surface of a triangle without texture maps: every sample would be 1 (multiplying by
    /// it is exact), so none is taken.
    #[inline(always)]
    fn untextured(&self, position: Vec3, normal: Vec3, color: Vec3) -> Surface {
        let mat = self.material;
        Surface {
            position,
            normal,
            emission: mat.emission,
            ambient: mat.ambient,
            diffuse: mat.diffuse * color,
            opacity: mat.opacity.clamp(0.0, 1.0),
            specular: mat.specular,
            shininess: mat.shininess.clamp(0.0, 1.0),
            reflectivity: mat.reflectivity.clamp(0.0, 1.0),
            ior: mat.ior,
        }
    }
}

/// Four surfaces of a triangle without texture maps ([`TriangleSurface::plain4`]): what
/// varies, as lanes, and what does not.
#[derive(Clone, Copy)]
pub struct Plain4 {
    pub position: V3,
    pub normal: V3,
    pub diffuse: V3,
    /// Emission, ambient, opacity, specular, shininess, reflectivity and IOR of all four (its
    /// position, normal and diffuse colour are not the lanes': read those above).
    pub constant: Surface,
}

/// Trilinear texture sample for a UV footprint (UV units per pixel): exactly (bit for bit)
/// `t.sample(uv, t.lod_for_footprint(footprint))`, without the per-call overheads of the generic
/// path (library `floor` calls, the lazily built sRGB table, bounds checks per texel).
#[inline]
pub fn sample_texture(t: &Texture, uv: Vec2, footprint: f32) -> Vec4 {
    let (Some(base), Some(last)) = (t.levels.first(), t.levels.len().checked_sub(1)) else {
        return t.sample(uv, t.lod_for_footprint(footprint));
    };
    // `Texture::lod_for_footprint`, same expression.
    let texels = footprint * base.width.max(base.height) as f32;
    let lod = if texels <= 1.0 { 0.0 } else { texels.log2() };
    let max = last as f32;
    let lod = if lod.is_finite() { lod.clamp(0.0, max) } else { 0.0 };
    // lod ≥ 0 (or −0): its floor is its truncation.
    let l0 = lod as u32 as f32;
    let f = lod - l0;
    if !uv.x.is_finite() || !uv.y.is_finite() {
        let a = bilinear(t, uv, l0 as usize);
        return if f <= 1e-4 { a } else { a.lerp(bilinear(t, uv, l0 as usize + 1), f) };
    }
    // The UV's wrapped fraction is the same for both levels: computed once.
    let frac = Vec2::new(uv.x - floor(uv.x), uv.y - floor(uv.y));
    let decode = Decode::of(t);
    let a = bilinear_frac(t, uv, frac, l0 as usize, decode);
    if f <= 1e-4 { a } else { a.lerp(bilinear_frac(t, uv, frac, l0 as usize + 1, decode), f) }
}

/// [`sample_texture`], never inlined (keeps [`TriangleSurface::at`]'s map lookups small).
#[inline(never)]
fn sample_map(t: &Texture, uv: Vec2, footprint: f32) -> Vec4 {
    sample_texture(t, uv, footprint)
}

/// `x.floor()`, bit for bit (signed zeros included), without a library call or a saturating
/// integer cast on targets lacking SSE4.1: x86-64's baseline (SSE2) has no rounding instruction,
/// so `f32::floor` is a call into the compiler's software floor even inside the AVX paths
/// (texture sampling here, the fallbacks' bilinear lookups).
#[inline(always)]
pub(crate) fn floor(x: f32) -> f32 {
    const BIG: f32 = 8_388_608.0; // 2²³: every float at or above it is an integer
    let a = x.abs();
    if a < BIG {
        // Round |x| to an integer (adding and removing 2²³), give it x's sign, and step down
        // where that rounded up.
        // (r − 0 = r for either zero, so the step is branch-free.)
        let r = ((a + BIG) - BIG).copysign(x);
        r - if r > x { 1.0 } else { 0.0 }
    } else {
        // Integral, infinite or NaN: floor is the identity.
        x
    }
}

/// 256-entry tables: sRGB → linear (the same values `Texture::texel` uses) and `i / 255` (the
/// linear decode, the same division done once per value instead of per texel).
fn decode_tables() -> &'static ([f32; 256], [f32; 256]) {
    static LUT: std::sync::OnceLock<([f32; 256], [f32; 256])> = std::sync::OnceLock::new();
    LUT.get_or_init(|| {
        (std::array::from_fn(|i| hybrid_scene::texture::srgb_to_linear(i as f32 / 255.0)), std::array::from_fn(|i| i as f32 / 255.0))
    })
}

/// `Texture::sample_bilinear`, same arithmetic in the same order.
#[inline]
fn bilinear(t: &Texture, uv: Vec2, level: usize) -> Vec4 {
    let level = level.min(t.levels.len() - 1);
    if !uv.x.is_finite() || !uv.y.is_finite() {
        return t.texel(level, 0, 0);
    }
    bilinear_frac(t, uv, Vec2::new(uv.x - floor(uv.x), uv.y - floor(uv.y)), level, Decode::of(t))
}

/// How a texture's bytes become values: its colour space and the decode tables, looked up once
/// per sample rather than per texel.
#[derive(Clone, Copy)]
struct Decode {
    srgb: bool,
    tables: &'static ([f32; 256], [f32; 256]),
}

impl Decode {
    #[inline]
    fn of(t: &Texture) -> Self {
        Self { srgb: t.color_space == ColorSpace::Srgb, tables: decode_tables() }
    }

    #[inline(always)]
    fn texel(self, p: [u8; 4]) -> Vec4 {
        let (lut, unorm) = self.tables;
        let a = unorm[p[3] as usize];
        if self.srgb {
            Vec4::new(lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize], a)
        } else {
            Vec4::new(unorm[p[0] as usize], unorm[p[1] as usize], unorm[p[2] as usize], a)
        }
    }
}

/// [`bilinear`] for a finite `uv` whose wrapped fraction `frac` (`uv − floor(uv)`) is given.
#[inline(always)]
fn bilinear_frac(t: &Texture, uv: Vec2, frac: Vec2, level: usize, decode: Decode) -> Vec4 {
    let level = level.min(t.levels.len() - 1);
    let l = &t.levels[level];
    let x = frac.x * l.width as f32 - 0.5;
    let y = frac.y * l.height as f32 - 0.5;
    // With a finite UV the fraction is in [0, 1], so x ∈ [−0.5, width − 0.5] (y likewise): its
    // floor is its truncation, one less below 0 (x is never −0 here). The same integers as
    // `floor`, so the same weights.
    let (xi, yi) = (x as i32 - i32::from(x < 0.0), y as i32 - i32::from(y < 0.0));
    let (fx, fy) = (x - xi as f32, y - yi as f32);
    // x0 ∈ [−1, width − 1]: the texture's repeat wrap reduces to these two cases (a texel
    // outside the level after all falls back to the reference sampler below).
    let wrap0 = |i: i32, n: u32| if i < 0 { n - 1 } else { i as u32 };
    let wrap1 = |i: i32, n: u32| if i + 1 >= n as i32 { 0 } else { (i + 1) as u32 };
    let (ix0, iy0) = (wrap0(xi, l.width), wrap0(yi, l.height));
    let (ix1, iy1) = (wrap1(xi, l.width), wrap1(yi, l.height));
    let (r0, r1) = (iy0 as usize * l.width as usize, iy1 as usize * l.width as usize);
    let (Some(&t00), Some(&t10), Some(&t01), Some(&t11)) = (
        l.texels.get(r0 + ix0 as usize),
        l.texels.get(r0 + ix1 as usize),
        l.texels.get(r1 + ix0 as usize),
        l.texels.get(r1 + ix1 as usize),
    ) else {
        return t.sample_bilinear(uv, level);
    };
    let a = decode.texel(t00).lerp(decode.texel(t10), fx);
    let b = decode.texel(t01).lerp(decode.texel(t11), fx);
    a.lerp(b, fy)
}

/// Shadow transparency of a slot whose opacity varies over a texture: evaluated with
/// `surface_at` at the hit.
pub const SHADOW_EVALUATE: f32 = -1.0;

/// Shadow-ray transparency of a material: 1 when it casts no shadows, its constant
/// `1 − opacity` when no texture can change it (no maps, or maps whose relevant channel is the
/// same in every texel of level 0, the level shadow rays sample), else [`SHADOW_EVALUATE`]. The GPU
/// backend's BVH uses the same classes.
pub fn material_shadow(m: &Material, textures: &[Texture]) -> f32 {
    if !m.casts_shadows || m.opacity <= 0.0 {
        return 1.0;
    }
    if !m.opacity.is_finite() {
        return SHADOW_EVALUATE;
    }
    // The value of texture channel `c` if it is the same everywhere on level 0.
    let constant = |id: Option<usize>, c: usize| -> Option<f32> {
        let Some(id) = id else { return Some(1.0) };
        let t = textures.get(id)?;
        let texels = &t.levels.first()?.texels;
        let v = texels.first()?[c];
        texels.iter().all(|x| x[c] == v).then(|| t.texel(0, 0, 0)[c])
    };
    match (constant(m.diffuse_map, 3), constant(m.optical_map, 2)) {
        (Some(a), Some(b)) => 1.0 - (m.opacity * a * b).clamp(0.0, 1.0),
        _ => SHADOW_EVALUATE,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::Rng;

    #[test]
    fn untextured_shortcut_matches_the_general_path_bit_for_bit() {
        let mut scene = hybrid_scene::demo_scene();
        // Vary the materials' constants (out-of-range values too: the clamps must agree).
        for (k, m) in scene.materials.iter_mut().enumerate() {
            m.emission = Vec3::new(0.1, 0.0, -0.0) * k as f32;
            m.opacity = 1.5 - 0.4 * k as f32;
            m.shininess = -0.2 + 0.3 * k as f32;
            m.reflectivity = 0.7 * k as f32 - 0.5;
            m.offset = Vec2::new(0.25, -0.5);
        }
        let prepared = PreparedScene::new(&scene);
        let mut rng = Rng(7);
        let mut checked = 0;
        for &t in prepared.triangles.iter().step_by(7) {
            let fast = prepared.triangle_surface(t);
            if fast.textured {
                continue;
            }
            let general = TriangleSurface { textured: true, ..fast };
            for _ in 0..4 {
                let b = Vec3::new(rng.f(), rng.f(), rng.f());
                let b = b / (b.x + b.y + b.z);
                let (x, y) = (fast.at(b, 0.01), general.at(b, 0.01));
                let bits = |s: Surface| {
                    [s.position, s.normal, s.emission, s.ambient, s.diffuse, s.specular]
                        .map(|v| v.to_array().map(f32::to_bits))
                        .concat()
                        .into_iter()
                        .chain([s.opacity, s.shininess, s.reflectivity, s.ior].map(f32::to_bits))
                        .collect::<Vec<u32>>()
                };
                assert_eq!(bits(x), bits(y), "triangle {t:?} at {b}");
                checked += 1;
            }
        }
        assert!(checked > 100, "only {checked} points checked");
    }

    #[test]
    fn four_lane_plain_surfaces_match_at_bit_for_bit() {
        let mut scene = hybrid_scene::demo_scene();
        for (k, m) in scene.materials.iter_mut().enumerate() {
            m.opacity = 1.5 - 0.4 * k as f32;
            m.shininess = -0.2 + 0.3 * k as f32;
        }
        let prepared = PreparedScene::new(&scene);
        let mut rng = Rng(11);
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        let mut checked = 0;
        for &t in prepared.triangles.iter().step_by(5) {
            let plain = prepared.triangle_surface(t);
            if plain.textured {
                continue;
            }
            // As it is; with vertex colours; with normals that cancel at (½, ½, 0) (the
            // geometric-normal fallback); flat.
            let n = plain.normals.unwrap_or([Vec3::Y; 3])[0];
            let variants = [
                plain,
                TriangleSurface { colors: Some([Vec3::new(1.0, 0.2, -0.0), Vec3::new(0.0, 0.5, 1.0), Vec3::ONE]), ..plain },
                TriangleSurface { normals: Some([n, -n, Vec3::ZERO]), ..plain },
                TriangleSurface { normals: None, geometric: geometric_normal(plain.positions), ..plain },
            ];
            for ts in variants {
                let mut b = [0, 1, 2, 3].map(|_| {
                    let b = Vec3::new(rng.f(), rng.f(), rng.f());
                    b / (b.x + b.y + b.z)
                });
                b[1] = Vec3::new(0.5, 0.5, 0.0);
                let four = ts.plain4(crate::lanes::soa(b));
                for (k, &b) in b.iter().enumerate() {
                    let one = ts.at(b, 0.0);
                    let c = &four.constant;
                    let lane = |v| crate::lanes::lane(v, k);
                    assert_eq!(bits(lane(four.position)), bits(one.position), "{t:?} at {b}");
                    assert_eq!(bits(lane(four.normal)), bits(one.normal), "{t:?} at {b}");
                    assert_eq!(bits(lane(four.diffuse)), bits(one.diffuse), "{t:?} at {b}");
                    assert_eq!([c.emission, c.ambient, c.specular].map(bits), [one.emission, one.ambient, one.specular].map(bits));
                    let scalars = |s: &Surface| [s.opacity, s.shininess, s.reflectivity, s.ior].map(f32::to_bits);
                    assert_eq!(scalars(c), scalars(&one));
                    checked += 1;
                }
            }
        }
        assert!(checked > 400, "only {checked} points checked");
    }

    #[test]
    fn fast_sampler_matches_texture_sample_bit_for_bit() {
        let texels: Vec<[u8; 4]> =
            (0..37u32 * 20).map(|i| [(i * 7) as u8, (i * 13 + 5) as u8, (i * 29) as u8, (i * 3 + 100) as u8]).collect();
        let mut rng = Rng(0x1234_5678_9abc_def1);
        for cs in [ColorSpace::Srgb, ColorSpace::Linear] {
            let t = Texture::new("t", 37, 20, texels.clone(), cs);
            let special = [0.0, -0.0, 1.0, -1.0, 0.5, -1e-9, 1e-9, 0.999_999_9, 3.0e7, -3.0e7, f32::NAN, f32::INFINITY];
            for k in 0..20_000 {
                let (u, v) = if k < special.len() * special.len() {
                    (special[k % special.len()], special[k / special.len()])
                } else {
                    ((rng.f() - 0.5) * 40.0, (rng.f() - 0.5) * 7.0)
                };
                let footprint = match k % 4 {
                    0 => 0.0,
                    1 => rng.f() * 0.05,
                    2 => rng.f() * 2.0,
                    _ => rng.f() * 1e-3,
                };
                let uv = Vec2::new(u, v);
                let want = t.sample(uv, t.lod_for_footprint(footprint));
                let got = sample_texture(&t, uv, footprint);
                assert_eq!(want.to_array().map(f32::to_bits), got.to_array().map(f32::to_bits), "uv {uv} footprint {footprint} {cs:?}");
            }
        }
        for x in [-2.5f32, -3.5, 2.5, 3.5, -1.0, -0.5, -0.7, -0.0, 0.0, 0.3, 1.0, 2.7, 8_388_607.5, -8_388_607.5, 4_194_303.7, 1e10, -1e10]
        {
            assert_eq!(floor(x).to_bits(), x.floor().to_bits(), "floor {x}");
        }
        let mut rng = Rng(99);
        for _ in 0..100_000 {
            let x = (rng.f() - 0.5) * 2f32.powi((rng.f() * 30.0) as i32 - 5);
            assert_eq!(floor(x).to_bits(), x.floor().to_bits(), "floor {x}");
        }
    }

    #[test]
    fn shadow_class_of_materials() {
        let tex = |alphas: [u8; 4]| Texture::new("t", 2, 2, alphas.map(|a| [200, 100, 50, a]).to_vec(), hybrid_scene::ColorSpace::Srgb);
        let textures = vec![tex([255; 4]), tex([255, 255, 0, 255]), tex([128; 4])];
        let m = |opacity: f32, diffuse_map: Option<usize>| Material { opacity, diffuse_map, ..Default::default() };
        assert_eq!(material_shadow(&m(1.0, None), &textures), 0.0);
        assert_eq!(material_shadow(&m(0.25, None), &textures), 0.75);
        assert_eq!(material_shadow(&m(1.0, Some(0)), &textures), 0.0);
        assert_eq!(material_shadow(&m(1.0, Some(1)), &textures), SHADOW_EVALUATE);
        assert!((material_shadow(&m(1.0, Some(2)), &textures) - (1.0 - 128.0 / 255.0)).abs() < 1e-6);
        assert_eq!(material_shadow(&m(0.0, Some(1)), &textures), 1.0);
        assert_eq!(material_shadow(&Material { casts_shadows: false, ..m(1.0, None) }, &textures), 1.0);
        // A missing texture is evaluated at the hit (where `surface_at` decides).
        assert_eq!(material_shadow(&m(1.0, Some(9)), &textures), SHADOW_EVALUATE);
        let optical = Material { optical_map: Some(1), ..m(1.0, None) };
        // Texture 1's blue channel is constant (50): opacity = 50/255 in sRGB → linear.
        let tr = material_shadow(&optical, &textures);
        assert!((tr - (1.0 - textures[1].texel(0, 0, 0).z)).abs() < 1e-6 && tr > 0.5, "{tr}");
    }
}
