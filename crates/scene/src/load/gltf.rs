//! glTF 2.0 (`.gltf` + `.bin`, `.glb`) via the gltf crate. The default scene's node tree is
//! walked with node transforms applied; cycles are rejected (the crate does not check them),
//! as are out-of-range indices and non-finite positions.

use std::collections::HashMap;
use std::path::Path;

use ::gltf::mesh::Mode;
use glam::{Mat3, Mat4, Vec2, Vec3, Vec4};

use super::{check_finite, check_indices};
use crate::{ColorSpace, Material, Mesh, SceneError, Texture, TextureId, normal_matrix};

/// Deepest node nesting accepted (real files nest a handful of levels).
const MAX_DEPTH: usize = 256;
/// Most node visits accepted (shared subtrees are instanced once per parent).
const MAX_NODE_VISITS: usize = 1 << 20;

/// How an image is used: decides its colour space and whether its alpha is kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Use {
    /// sRGB colour whose alpha is opacity (BLEND / MASK materials).
    Color,
    /// sRGB colour of an opaque material: alpha forced to 1.
    ColorOpaque,
    /// Linear data (normal maps).
    Data,
}

struct Ctx<'a> {
    path: &'a Path,
    doc: &'a ::gltf::Document,
    buffers: &'a [::gltf::buffer::Data],
    images: &'a [::gltf::image::Data],
    textures: &'a mut Vec<Texture>,
    texture_ids: HashMap<(usize, Use), TextureId>,
    /// Material index in the file → index in the scene's list.
    material_base: usize,
    default_material: Option<usize>,
    materials_len: usize,
    visits: usize,
    meshes: Vec<Mesh>,
}

pub(super) fn load(path: &Path, materials: &mut Vec<Material>, textures: &mut Vec<Texture>) -> Result<Vec<Mesh>, SceneError> {
    let (doc, buffers, images) = import(path)?;
    // Validate before any of the gltf crate's readers run (they panic on forbidden accessors).
    let len = |i: usize| buffers.get(i).map_or(0, |d| d.0.len());
    super::gltf_check::check_document(&doc, &len).map_err(|e| SceneError::new(path, e))?;
    let bytes = |i: usize| buffers.get(i).map_or(&[][..], |d| &d.0[..]);
    super::gltf_check::check_sparse_indices(&doc, &bytes).map_err(|e| SceneError::new(path, e))?;
    let scene = doc.default_scene().or_else(|| doc.scenes().next()).ok_or_else(|| SceneError::new(path, "glTF file has no scene"))?;
    let material_base = materials.len();
    let mut ctx = Ctx {
        path,
        doc: &doc,
        buffers: &buffers,
        images: &images,
        textures,
        texture_ids: HashMap::new(),
        material_base,
        default_material: None,
        materials_len: material_base + doc.materials().len(),
        visits: 0,
        meshes: Vec::new(),
    };
    for m in doc.materials() {
        let converted = ctx.material(&m)?;
        materials.push(converted);
    }
    let mut on_path = vec![false; doc.nodes().len()];
    for node in scene.nodes() {
        ctx.node(&node, Mat4::IDENTITY, 0, &mut on_path)?;
    }
    if let Some(d) = ctx.default_material {
        debug_assert_eq!(d, materials.len());
        materials.push(Material::default());
    } else if doc.materials().len() == 0 {
        materials.push(Material::default());
    }
    let mut meshes = ctx.meshes;
    for mesh in &mut meshes {
        if mesh.tangents.is_empty() && materials[mesh.material].normal_map.is_some() {
            mesh.compute_tangents();
        }
    }
    Ok(meshes)
}

/// The GLB header's version and total length, checked before gltf reads the container: gltf
/// 1.4.1 subtracts the 12-byte header from the declared length unchecked (found by fuzzing: a
/// length below 12 wraps in release builds and panics with overflow checks on).
fn check_glb_header(bytes: &[u8]) -> Result<(), String> {
    const HEADER: usize = 12;
    let word = |at: usize| bytes.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let (Some(version), Some(length)) = (word(4), word(8)) else {
        return Err(format!("the file is {} bytes, shorter than the {HEADER}-byte GLB header", bytes.len()));
    };
    if version != 2 {
        return Err(format!("GLB version {version} (only version 2 is supported)"));
    }
    let length = length as usize;
    if length < HEADER + 8 {
        return Err(format!("the header declares {length} bytes, too short for the header and a JSON chunk ({} bytes)", HEADER + 8));
    }
    if length > bytes.len() {
        return Err(format!("the header declares {length} bytes, the file has {}", bytes.len()));
    }
    Ok(())
}

/// `gltf::import` with a JSON pre-pass: scenes without `nodes` (optional in the glTF schema,
/// required by gltf-json) get an empty list, and extension objects of the wrong JSON type are
/// rejected (gltf ignores extensions it was not built for, whatever their content).
fn import(path: &Path) -> Result<(::gltf::Document, Vec<::gltf::buffer::Data>, Vec<::gltf::image::Data>), SceneError> {
    let fail = |what: &str, e: &dyn std::fmt::Display| SceneError::new(path, format!("{what}: {e}"));
    let bytes = super::read_capped(path, "glTF file", super::MAX_MODEL_BYTES)?;
    let (json, blob) = if bytes.starts_with(b"glTF") {
        check_glb_header(&bytes).map_err(|m| fail("invalid GLB container", &m))?;
        let glb = ::gltf::Glb::from_slice(&bytes).map_err(|e| fail("invalid GLB container", &e))?;
        (glb.json.into_owned(), glb.bin.map(|b| b.into_owned()))
    } else {
        (bytes, None)
    };
    let mut value: ::gltf::json::Value = ::gltf::json::deserialize::from_slice(&json).map_err(|e| fail("invalid glTF JSON", &e))?;
    drop(json);
    if let Some(scenes) = value.get_mut("scenes").and_then(|s| s.as_array_mut()) {
        for scene in scenes.iter_mut().filter_map(|s| s.as_object_mut()) {
            scene.entry("nodes").or_insert_with(|| ::gltf::json::Value::Array(Vec::new()));
        }
    }
    check_extensions(&value, "").map_err(|m| SceneError::new(path, m))?;
    check_primitive_accessors(&value).map_err(|m| SceneError::new(path, m))?;
    check_uris(&value).map_err(|m| SceneError::new(path, m))?;
    let json = ::gltf::json::serialize::to_vec(&value).map_err(|e| fail("invalid glTF JSON", &e))?;
    // The checks above cover the panics fuzzing found in gltf 1.4.1; a panic left in it is still
    // its bug, turned into an error naming the file rather than taking the caller down.
    let parsed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> Result<_, SceneError> {
        let gltf = ::gltf::Gltf::from_slice(&json).map_err(|e| fail("invalid glTF", &e))?;
        let base = path.parent();
        check_external_files(path, &gltf.document)?;
        let buffers = ::gltf::import_buffers(&gltf.document, base, blob).map_err(|e| fail("cannot load glTF buffers", &e))?;
        let images = ::gltf::import_images(&gltf.document, base, &buffers).map_err(|e| fail("cannot load glTF images", &e))?;
        Ok((gltf.document, buffers, images))
    }));
    parsed.unwrap_or_else(|_| Err(SceneError::new(path, "the glTF parser (gltf) failed on this file")))
}

/// Every accessor a mesh primitive names (attributes, morph targets, indices) must exist:
/// gltf-json's validation reads the POSITION accessor by its index before checking the index (an
/// index-out-of-bounds panic in gltf 1.4.1, found by fuzzing: fuzz/README.md).
fn check_primitive_accessors(v: &::gltf::json::Value) -> Result<(), String> {
    let n = v.get("accessors").and_then(|a| a.as_array()).map_or(0, |a| a.len());
    let meshes = v.get("meshes").and_then(|m| m.as_array());
    for (mi, mesh) in meshes.into_iter().flatten().enumerate() {
        for (pi, prim) in mesh.get("primitives").and_then(|p| p.as_array()).into_iter().flatten().enumerate() {
            let mut refs: Vec<(String, &::gltf::json::Value)> = Vec::new();
            if let Some(attrs) = prim.get("attributes").and_then(|a| a.as_object()) {
                refs.extend(attrs.iter().map(|(k, r)| (format!("attribute {k}"), r)));
            }
            if let Some(r) = prim.get("indices") {
                refs.push(("indices".into(), r));
            }
            for t in prim.get("targets").and_then(|t| t.as_array()).into_iter().flatten().filter_map(|t| t.as_object()) {
                refs.extend(t.iter().map(|(k, r)| (format!("morph target {k}"), r)));
            }
            for (what, r) in refs {
                if r.as_u64().is_none_or(|i| i >= n as u64) {
                    return Err(format!("mesh {mi} primitive {pi}: {what} refers to accessor {r}, and the file has {n} accessors"));
                }
            }
        }
    }
    Ok(())
}

/// Buffer and image URIs that are not `data:` URIs must percent-decode to UTF-8: gltf 1.4.1
/// unwraps `urlencoding::decode` of them (a panic, found by fuzzing); this is the same call.
fn check_uris(v: &::gltf::json::Value) -> Result<(), String> {
    for (kind, list) in [("buffer", "buffers"), ("image", "images")] {
        for (i, item) in v.get(list).and_then(|l| l.as_array()).into_iter().flatten().enumerate() {
            if let Some(uri) = item.get("uri").and_then(|u| u.as_str())
                && !uri.starts_with("data:")
                && urlencoding::decode(uri).is_err()
            {
                return Err(format!("{kind} {i}: its URI is not valid percent-encoded UTF-8"));
            }
        }
    }
    Ok(())
}

/// External buffers and images (relative URIs, not `data:`) must be regular files within the
/// read caps before the gltf crate reads them whole.
fn check_external_files(path: &Path, doc: &::gltf::Document) -> Result<(), SceneError> {
    let base = path.parent().unwrap_or(Path::new("."));
    let external = |uri: &str| (!uri.starts_with("data:")).then(|| base.join(uri));
    for b in doc.buffers() {
        if let ::gltf::buffer::Source::Uri(uri) = b.source()
            && let Some(file) = external(uri)
            && file.exists()
        {
            super::check_file(&file, "glTF buffer", super::MAX_MODEL_BYTES)
                .map_err(|e| SceneError::new(path, format!("buffer {}: {}: {}", b.index(), file.display(), e.message)))?;
        }
    }
    for im in doc.images() {
        if let ::gltf::image::Source::Uri { uri, .. } = im.source()
            && let Some(file) = external(uri)
            && file.exists()
        {
            super::check_file(&file, "texture file", super::MAX_TEXTURE_FILE_BYTES)
                .map_err(|e| SceneError::new(path, format!("image {}: {}: {}", im.index(), file.display(), e.message)))?;
        }
    }
    Ok(())
}

/// Every member of every `extensions` object must itself be a JSON object.
fn check_extensions(v: &::gltf::json::Value, at: &str) -> Result<(), String> {
    use ::gltf::json::Value;
    match v {
        Value::Object(map) => {
            for (k, child) in map {
                let here = format!("{at}/{k}");
                if k == "extensions" {
                    let Value::Object(exts) = child else { return Err(format!("{here} is not a JSON object")) };
                    for (name, ext) in exts {
                        if !ext.is_object() {
                            return Err(format!("extension {name} at {here} is not a JSON object"));
                        }
                    }
                }
                check_extensions(child, &here)?;
            }
            Ok(())
        }
        Value::Array(items) => items.iter().enumerate().try_for_each(|(i, c)| check_extensions(c, &format!("{at}/{i}"))),
        _ => Ok(()),
    }
}

impl Ctx<'_> {
    fn err(&self, msg: impl Into<String>) -> SceneError {
        SceneError::new(self.path, msg)
    }

    fn node(&mut self, node: &::gltf::Node<'_>, parent: Mat4, depth: usize, on_path: &mut [bool]) -> Result<(), SceneError> {
        let i = node.index();
        if on_path.get(i).copied().unwrap_or(true) {
            return Err(self.err(format!("node {i} is its own ancestor (the node hierarchy has a cycle)")));
        }
        if depth >= MAX_DEPTH {
            return Err(self.err(format!("node hierarchy is deeper than {MAX_DEPTH} levels")));
        }
        self.visits += 1;
        if self.visits > MAX_NODE_VISITS {
            return Err(self.err(format!("node hierarchy expands to more than {MAX_NODE_VISITS} node instances")));
        }
        on_path[i] = true;
        let local = Mat4::from_cols_array_2d(&node.transform().matrix());
        let world = parent * local;
        if !world.is_finite() {
            return Err(self.err(format!("node {i} has a non-finite transform")));
        }
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                let what = format!("mesh {} ({}) primitive {}", mesh.index(), mesh.name().unwrap_or("unnamed"), prim.index());
                if let Some(m) = self.primitive(&prim, &world, &what)? {
                    self.meshes.push(m);
                }
            }
        }
        for child in node.children() {
            self.node(&child, world, depth + 1, on_path)?;
        }
        on_path[i] = false;
        Ok(())
    }

    fn primitive(&mut self, prim: &::gltf::Primitive<'_>, world: &Mat4, what: &str) -> Result<Option<Mesh>, SceneError> {
        let mode = prim.mode();
        if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
            tracing::debug!("{}: {what}: {mode:?} primitive skipped (only triangles are drawn)", self.path.display());
            return Ok(None);
        }
        let buffers = self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let Some(pos) = reader.read_positions() else {
            return Err(self.err(format!("{what} has no POSITION attribute")));
        };
        let mut mesh = Mesh::default();
        for (i, p) in pos.enumerate() {
            let p = Vec3::from(p);
            check_finite("vertex", i, p).map_err(|e| self.err(format!("{what}: {e}")))?;
            mesh.positions.push(p);
        }
        let n = mesh.positions.len();
        let len_err = |attr: &str, got: usize| self.err(format!("{what}: {attr} has {got} entries but POSITION has {n}"));
        if let Some(it) = reader.read_normals() {
            mesh.normals = it.map(Vec3::from).collect();
            if mesh.normals.len() != n {
                return Err(len_err("NORMAL", mesh.normals.len()));
            }
        }
        if let Some(it) = reader.read_tex_coords(0) {
            mesh.uvs = it.into_f32().map(Vec2::from).map(|v| if v.is_finite() { v } else { Vec2::ZERO }).collect();
            if mesh.uvs.len() != n {
                return Err(len_err("TEXCOORD_0", mesh.uvs.len()));
            }
        }
        if let Some(it) = reader.read_tangents() {
            mesh.tangents = it.map(Vec4::from).collect();
            if mesh.tangents.len() != n {
                return Err(len_err("TANGENT", mesh.tangents.len()));
            }
        }
        if let Some(it) = reader.read_colors(0) {
            // glTF vertex colours are linear already.
            mesh.colors =
                it.into_rgb_f32().map(|c| Vec3::from(c).max(Vec3::ZERO)).map(|c| if c.is_finite() { c } else { Vec3::ONE }).collect();
            if mesh.colors.len() != n {
                return Err(len_err("COLOR_0", mesh.colors.len()));
            }
        }
        let flat: Vec<u32> = match reader.read_indices() {
            Some(it) => it.into_u32().collect(),
            None => (0..n as u32).collect(),
        };
        mesh.indices = match mode {
            Mode::TriangleStrip => (2..flat.len())
                .map(|k| if k % 2 == 0 { [flat[k - 2], flat[k - 1], flat[k]] } else { [flat[k - 1], flat[k - 2], flat[k]] })
                .collect(),
            Mode::TriangleFan => (2..flat.len()).map(|k| [flat[0], flat[k - 1], flat[k]]).collect(),
            _ => flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        };
        check_indices(&mesh.indices, n).map_err(|e| self.err(format!("{what}: {e}")))?;
        if mesh.indices.is_empty() {
            return Ok(None);
        }

        // Node transform: positions by the matrix, normals by its inverse transpose, tangents by
        // its 3×3 part; a mirroring transform flips the winding and the bitangent sign.
        if *world != Mat4::IDENTITY {
            let nm: Mat3 = normal_matrix(world);
            let m3 = Mat3::from_mat4(*world);
            let mirror = m3.determinant() < 0.0;
            for p in &mut mesh.positions {
                *p = world.transform_point3(*p);
            }
            for v in &mut mesh.normals {
                *v = nm * *v;
            }
            for t in &mut mesh.tangents {
                let xyz = (m3 * t.truncate()).normalize_or_zero();
                *t = xyz.extend(if mirror { -t.w } else { t.w });
            }
            // A finite matrix can still overflow a finite position to infinity.
            if let Some((i, p)) = mesh.positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
                return Err(self.err(format!("{what}: vertex {i} is not finite after the node transform ({}, {}, {})", p.x, p.y, p.z)));
            }
            if mirror {
                for tri in &mut mesh.indices {
                    tri.swap(1, 2);
                }
            }
        }
        for v in &mut mesh.normals {
            *v = if v.is_finite() { v.normalize_or_zero() } else { Vec3::ZERO };
        }
        if mesh.tangents.iter().any(|t| !t.is_finite()) {
            mesh.tangents.clear();
        }
        mesh.material = match prim.material().index() {
            Some(i) => self.material_base + i,
            None => *self.default_material.get_or_insert(self.materials_len),
        };
        Ok(Some(mesh))
    }

    fn texture(&mut self, tex: ::gltf::Texture<'_>, usage: Use) -> Result<TextureId, SceneError> {
        let image = tex.source().index();
        if let Some(&id) = self.texture_ids.get(&(image, usage)) {
            return Ok(id);
        }
        let data = self.images.get(image).ok_or_else(|| self.err(format!("texture {} uses missing image {image}", tex.index())))?;
        let texels = to_rgba8(data)
            .ok_or_else(|| self.err(format!("image {image} has {} bytes for {}×{} pixels", data.pixels.len(), data.width, data.height)))?;
        let texels = if usage == Use::ColorOpaque { texels.into_iter().map(|t| [t[0], t[1], t[2], 255]).collect() } else { texels };
        let cs = if usage == Use::Data { ColorSpace::Linear } else { ColorSpace::Srgb };
        let src = self.doc.images().nth(image);
        let name = src
            .and_then(|s| {
                s.name().map(str::to_owned).or_else(|| match s.source() {
                    ::gltf::image::Source::Uri { uri, .. } => Some(uri.to_owned()),
                    ::gltf::image::Source::View { .. } => None,
                })
            })
            .unwrap_or_else(|| format!("image {image}"));
        let id = self.textures.len();
        self.textures.push(Texture::new(name, data.width, data.height, texels, cs));
        self.texture_ids.insert((image, usage), id);
        Ok(id)
    }

    /// Table 1 material from a metallic-roughness material (see docs/loaders.md).
    fn material(&mut self, m: &::gltf::Material<'_>) -> Result<Material, SceneError> {
        let pbr = m.pbr_metallic_roughness();
        let base = Vec4::from(pbr.base_color_factor());
        let base = if base.is_finite() { base.clamp(Vec4::ZERO, Vec4::ONE) } else { Vec4::ONE };
        let metallic = finite_or(pbr.metallic_factor(), 1.0).clamp(0.0, 1.0);
        let roughness = finite_or(pbr.roughness_factor(), 1.0).clamp(0.0, 1.0);
        let blend = m.alpha_mode() != ::gltf::material::AlphaMode::Opaque;
        let color_use = if blend { Use::Color } else { Use::ColorOpaque };
        let diffuse_map = pbr.base_color_texture().map(|t| self.texture(t.texture(), color_use)).transpose()?;
        let emission_map = m.emissive_texture().map(|t| self.texture(t.texture(), Use::ColorOpaque)).transpose()?;
        let normal_map = m.normal_texture().map(|t| self.texture(t.texture(), Use::Data)).transpose()?;
        let transmission = m.transmission().map_or(0.0, |t| finite_or(t.transmission_factor(), 0.0).clamp(0.0, 1.0));
        let alpha = if blend { base.w } else { 1.0 };
        let diffuse = base.truncate();
        let emission = Vec3::from(m.emissive_factor());
        Ok(Material {
            name: m.name().map_or_else(|| format!("material {}", m.index().unwrap_or(0)), str::to_owned),
            emission: if emission.is_finite() { emission.max(Vec3::ZERO) } else { Vec3::ZERO },
            emission_map,
            ambient: diffuse,
            ambient_map: diffuse_map,
            diffuse,
            diffuse_map,
            specular: Vec3::splat(0.04).lerp(diffuse, metallic),
            shininess: 1.0 - roughness,
            specular_map: None,
            normal_map,
            reflectivity: metallic * (1.0 - roughness) * (1.0 - roughness),
            ior: m.ior().filter(|i| i.is_finite() && *i >= 1.0).unwrap_or(1.5),
            opacity: (alpha * (1.0 - transmission)).clamp(0.0, 1.0),
            optical_map: None,
            tiling: Vec2::ONE,
            offset: Vec2::ZERO,
            casts_shadows: true,
        })
    }
}

fn finite_or(v: f32, d: f32) -> f32 {
    if v.is_finite() { v } else { d }
}

/// Decoded glTF image → RGBA8 (16-bit channels keep their high byte; float channels are clamped).
fn to_rgba8(d: &::gltf::image::Data) -> Option<Vec<[u8; 4]>> {
    use ::gltf::image::Format as F;
    let n = (d.width as usize).checked_mul(d.height as usize)?;
    if n == 0 {
        return None;
    }
    let (channels, bytes) = match d.format {
        F::R8 => (1, 1),
        F::R8G8 => (2, 1),
        F::R8G8B8 => (3, 1),
        F::R8G8B8A8 => (4, 1),
        F::R16 => (1, 2),
        F::R16G16 => (2, 2),
        F::R16G16B16 => (3, 2),
        F::R16G16B16A16 => (4, 2),
        F::R32G32B32FLOAT => (3, 4),
        F::R32G32B32A32FLOAT => (4, 4),
    };
    let stride = channels * bytes;
    if d.pixels.len() != n.checked_mul(stride)? {
        return None;
    }
    let chan = |px: &[u8], c: usize| -> u8 {
        let b = &px[c * bytes..(c + 1) * bytes];
        match bytes {
            1 => b[0],
            2 => u16::from_le_bytes([b[0], b[1]]).to_be_bytes()[0],
            _ => (f32::from_le_bytes([b[0], b[1], b[2], b[3]]).clamp(0.0, 1.0) * 255.0 + 0.5) as u8,
        }
    };
    Some(
        d.pixels
            .chunks_exact(stride)
            .map(|px| match channels {
                1 => {
                    let v = chan(px, 0);
                    [v, v, v, 255]
                }
                2 => {
                    let v = chan(px, 0);
                    [v, v, v, chan(px, 1)]
                }
                3 => [chan(px, 0), chan(px, 1), chan(px, 2), 255],
                _ => [chan(px, 0), chan(px, 1), chan(px, 2), chan(px, 3)],
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uris_must_percent_decode_to_utf8() {
        let doc = |uri: &str| {
            ::gltf::json::serialize::to_value(::std::collections::BTreeMap::from([(
                "buffers",
                vec![::std::collections::BTreeMap::from([("uri", uri)])],
            )]))
            .unwrap()
        };
        for good in ["a%20b.bin", "100%.bin", "%C3%A9.png", "data:application/octet-stream;base64,%FF"] {
            assert!(check_uris(&doc(good)).is_ok(), "{good}");
        }
        let e = check_uris(&doc("%FF.bin")).unwrap_err();
        assert!(e.contains("buffer 0") && e.contains("UTF-8"), "{e}");
    }

    #[test]
    fn image_formats_become_rgba8() {
        let d = |format, pixels: Vec<u8>| ::gltf::image::Data { pixels, format, width: 1, height: 1 };
        use ::gltf::image::Format as F;
        assert_eq!(to_rgba8(&d(F::R8G8B8, vec![1, 2, 3])), Some(vec![[1, 2, 3, 255]]));
        assert_eq!(to_rgba8(&d(F::R8G8, vec![9, 7])), Some(vec![[9, 9, 9, 7]]));
        assert_eq!(to_rgba8(&d(F::R16, vec![0x34, 0x12])), Some(vec![[0x12, 0x12, 0x12, 255]]));
        assert_eq!(to_rgba8(&d(F::R8G8B8A8, vec![1, 2, 3])), None);
    }
}
