//! Wavefront OBJ + MTL via tobj. Polygons are triangulated here (fan for convex faces, ear
//! clipping for concave ones) rather than by tobj, whose fan is wrong for concave faces.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::image::looks_like_normal_map;
use super::{check_finite, check_indices};
use crate::texture::srgb_to_linear;
use crate::{ColorSpace, Material, Mesh, SceneError, Texture, TextureId};

/// Stand-in for an empty material name (`newmtl` / `usemtl` with nothing after it), which tobj
/// rejects; the material keeps an empty name after loading.
const EMPTY_NAME: &str = "\u{1}unnamed";

pub(super) fn load(path: &Path, materials: &mut Vec<Material>, textures: &mut Vec<Texture>) -> Result<Vec<Mesh>, SceneError> {
    let opts = tobj::LoadOptions { single_index: true, triangulate: false, ignore_points: true, ignore_lines: true };
    let bytes = super::read_capped(path, "OBJ file", super::MAX_MODEL_BYTES)?;
    let text = decode_text(path, bytes)?;
    let text = preprocess(path, &text)?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mtl_warning = std::cell::RefCell::new(None);
    let loader = |name: &Path| -> tobj::MTLLoadResult {
        let mtl_path = resolve(dir, &name.to_string_lossy().replace('\\', "/"));
        let loaded = super::read_capped(&mtl_path, "material library", super::MAX_MTL_BYTES)
            .map_err(|e| format!("cannot read material library {}: {}", mtl_path.display(), e.message))
            .and_then(|b| decode_text(&mtl_path, b).map_err(|e| e.to_string()))
            .map(|t| preprocess_mtl(&t))
            .and_then(|t| {
                tobj::load_mtl_buf(&mut t.as_bytes()).map_err(|e| format!("material library {} is not usable: {e}", mtl_path.display()))
            });
        match loaded {
            Ok(m) => Ok(m),
            Err(msg) => {
                *mtl_warning.borrow_mut() = Some(msg);
                Ok((Vec::new(), Default::default()))
            }
        }
    };
    // tobj is not known to panic on what `preprocess` lets through; a panic would still be a
    // bug in it, so it is turned into an error naming the file rather than taking the caller down.
    let loaded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| tobj::load_obj_buf(&mut text.as_bytes(), &opts, loader)));
    let (models, mtl) = match loaded {
        Ok(r) => r.map_err(|e| SceneError::new(path, format!("cannot load OBJ: {e}")))?,
        Err(_) => return Err(SceneError::new(path, "the OBJ parser (tobj) failed on this file")),
    };
    drop(text);
    if let Some(w) = mtl_warning.into_inner() {
        tracing::warn!("{}: {w}; using the default material", path.display());
    }
    let mut mtl = mtl.unwrap_or_default();
    for m in &mut mtl {
        if m.name == EMPTY_NAME {
            m.name.clear();
        }
    }

    let mut meshes = Vec::new();
    let mut needs_default = false;
    for model in &models {
        let m = &model.mesh;
        let n = m.positions.len() / 3;
        let mut mesh = Mesh { positions: Vec::with_capacity(n), ..Mesh::default() };
        for (i, p) in m.positions.chunks_exact(3).enumerate() {
            let p = Vec3::new(p[0], p[1], p[2]);
            check_finite("vertex", i, p).map_err(|e| SceneError::new(path, format!("object `{}`: {e}", model.name)))?;
            mesh.positions.push(p);
        }
        if m.normals.len() == 3 * n {
            mesh.normals = m.normals.chunks_exact(3).map(|c| sanitize_normal(Vec3::new(c[0], c[1], c[2]))).collect();
        }
        if m.texcoords.len() == 2 * n {
            // OBJ puts v = 0 at the bottom of the image; our textures have (0, 0) top-left.
            mesh.uvs = m.texcoords.chunks_exact(2).map(|c| sanitize_uv(Vec2::new(c[0], 1.0 - c[1]))).collect();
        }
        if m.vertex_color.len() == 3 * n {
            mesh.colors = m
                .vertex_color
                .chunks_exact(3)
                .map(|c| Vec3::from_array([c[0], c[1], c[2]].map(|v| srgb_to_linear(v.clamp(0.0, 1.0)))))
                .collect();
        }
        mesh.indices = triangulate(&mesh.positions, &m.indices, &m.face_arities)
            .map_err(|e| SceneError::new(path, format!("object `{}`: {e}", model.name)))?;
        check_indices(&mesh.indices, n).map_err(|e| SceneError::new(path, format!("object `{}`: {e}", model.name)))?;
        if mesh.indices.is_empty() {
            continue;
        }
        mesh.material = match m.material_id {
            Some(id) if id < mtl.len() => id,
            _ => {
                needs_default = true;
                usize::MAX
            }
        };
        meshes.push(mesh);
    }
    if meshes.is_empty() {
        return Err(SceneError::new(path, "OBJ file has no faces (nothing to draw)"));
    }

    // Textures: collect every referenced file, decode them in parallel, then assign ids in order.
    let base_mat = materials.len();
    let mut requests: Vec<(PathBuf, ColorSpace)> = Vec::new();
    let mut parsed = Vec::with_capacity(mtl.len());
    for m in &mtl {
        let maps = MtlMaps::of(m, dir);
        for (p, cs) in maps.requests() {
            if !requests.contains(&(p.clone(), cs)) {
                requests.push((p, cs));
            }
        }
        parsed.push(maps);
    }
    let decoded: Vec<Option<Texture>> = requests
        .par_iter()
        .map(|(p, cs)| match super::image::load(p, *cs) {
            Ok(t) => Some(t),
            Err(e) => {
                tracing::warn!("{}: texture skipped: {e}", path.display());
                None
            }
        })
        .collect();
    let mut ids: HashMap<(PathBuf, bool), TextureId> = HashMap::new();
    for ((p, cs), t) in requests.into_iter().zip(decoded) {
        if let Some(t) = t {
            if cs == ColorSpace::Linear && !looks_like_normal_map(&t.levels[0].texels) {
                tracing::warn!("{}: bump map {} is not a tangent-space normal map; ignored", path.display(), p.display());
                continue;
            }
            ids.insert((p, cs == ColorSpace::Linear), textures.len());
            textures.push(t);
        }
    }
    for (m, maps) in mtl.iter().zip(&parsed) {
        materials.push(convert_material(m, maps, &ids));
    }
    let default_id = materials.len();
    if needs_default || mtl.is_empty() {
        materials.push(Material::default());
    }
    for mesh in &mut meshes {
        mesh.material = if mesh.material == usize::MAX { default_id } else { base_mat + mesh.material };
        if mesh.normals.is_empty() || mesh.uvs.is_empty() {
            continue;
        }
        if materials[mesh.material].normal_map.is_some() {
            mesh.compute_tangents();
        }
    }
    Ok(meshes)
}

/// OBJ/MTL text: UTF-8 (invalid bytes replaced); UTF-16 files are rejected with a clear message.
fn decode_text(path: &Path, bytes: Vec<u8>) -> Result<String, SceneError> {
    if bytes.starts_with(&[0xFE, 0xFF]) || bytes.starts_with(&[0xFF, 0xFE]) {
        return Err(SceneError::new(path, "file is UTF-16 encoded; OBJ and MTL files must be UTF-8 (or ASCII) text"));
    }
    Ok(match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
    })
}

/// Fixes what tobj cannot read and rejects what it silently accepts:
/// - `l` (polyline) statements are dropped: lines are not drawn (tobj reads `l a b c d` as a quad);
/// - an `f` without vertices, or with an index 0 or beyond the file's count of its kind (vertex,
///   texture or normal), is an error;
/// - `usemtl` with an empty name selects the material with an empty name;
/// - exponents written `3.1+e2` / `3.1-e2` are read as `3.1e+2` / `3.1e-2`.
fn preprocess(path: &Path, text: &str) -> Result<String, SceneError> {
    let mut out = String::with_capacity(text.len() + 1);
    // How many positions, texture coordinates and normals the file declares: a face index beyond
    // them cannot be valid, and tobj computes `index * 2` / `index * 3` unchecked (a huge one
    // overflowed: found by fuzzing, fuzz/README.md).
    let mut counts = [0u64; 3];
    for line in text.lines() {
        match line.split_whitespace().next() {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            _ => {}
        }
    }
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let start = offset;
        offset += line.len();
        let body = line.trim_end_matches(['\n', '\r']);
        let mut words = body.split_whitespace();
        match words.next() {
            Some("l") => {}
            Some("f") if words.next().is_none() => {
                return Err(SceneError::at(path, text, start..start + body.len(), "face (`f`) without vertices"));
            }
            Some("f") if let Some(problem) = face_index_problem(body, counts) => {
                return Err(SceneError::at(path, text, start..start + body.len(), problem));
            }
            Some("usemtl") if words.next().is_none() => {
                out.push_str("usemtl ");
                out.push_str(EMPTY_NAME);
            }
            Some("v" | "vn" | "vt") if body.contains("+e") || body.contains("-e") || body.contains("+E") || body.contains("-E") => {
                let fixed: Vec<String> = body
                    .split_whitespace()
                    .map(|w| w.replace("+e", "e+").replace("-e", "e-").replace("+E", "E+").replace("-E", "E-"))
                    .collect();
                out.push_str(&fixed.join(" "));
            }
            _ => out.push_str(body),
        }
        out.push('\n');
    }
    Ok(out)
}

/// What is wrong with the indices of the face statement `body`, if anything: an index 0, or one
/// beyond the file's `counts` of positions, texture coordinates and normals (negative indices
/// count back, so their magnitude is checked).
fn face_index_problem(body: &str, counts: [u64; 3]) -> Option<String> {
    let indices: Vec<(i64, u64)> = body
        .split_whitespace()
        .skip(1)
        .flat_map(|w| w.split('/').zip(counts).filter_map(|(i, n)| i.parse::<i64>().ok().map(|i| (i, n))))
        .collect();
    if indices.iter().any(|&(i, _)| i == 0) {
        return Some("face (`f`) with index 0 (OBJ vertex, texture and normal indices start at 1; negative ones count back)".into());
    }
    indices.iter().any(|&(i, n)| i.unsigned_abs() > n).then(|| {
        format!(
            "face (`f`) with an index out of range (the file has {} positions, {} texture coordinates, {} normals)",
            counts[0], counts[1], counts[2]
        )
    })
}

/// Makes MTL text safe for tobj: `newmtl` with an empty name gets [`EMPTY_NAME`] (tobj rejects
/// empty names), and colour statements (`Ka`, `Kd`, `Ks`, `Ke`, `Tf`) with fewer than three
/// numbers are completed as the MTL spec says (`Ks r` = `Ks r r r`), because tobj 4.0.5 panics on
/// them; a colour statement without any number is dropped.
fn preprocess_mtl(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 64);
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("newmtl") if words.next().is_none() => {
                out.push_str("newmtl ");
                out.push_str(EMPTY_NAME);
            }
            Some(k @ ("Ka" | "Kd" | "Ks" | "Ke" | "Tf")) => {
                let nums: Vec<&str> = words.collect();
                match nums.len() {
                    0 => {}
                    1 | 2 => out.push_str(&format!("{k} {} {} {}", nums[0], nums.get(1).unwrap_or(&nums[0]), nums[0])),
                    _ => out.push_str(line),
                }
            }
            _ => out.push_str(line),
        }
        out.push('\n');
    }
    out
}

fn sanitize_normal(n: Vec3) -> Vec3 {
    if n.is_finite() { n.normalize_or_zero() } else { Vec3::ZERO }
}

fn sanitize_uv(uv: Vec2) -> Vec2 {
    if uv.is_finite() { uv } else { Vec2::ZERO }
}

/// Texture maps of one MTL material, with the options of `map_Kd` that set tiling and offset.
struct MtlMaps {
    diffuse: Option<PathBuf>,
    ambient: Option<PathBuf>,
    specular: Option<PathBuf>,
    emission: Option<PathBuf>,
    bump: Option<PathBuf>,
    tiling: Option<Vec2>,
    offset: Option<Vec2>,
}

impl MtlMaps {
    fn of(m: &tobj::Material, dir: &Path) -> Self {
        let map = |s: Option<&String>| s.map(|s| parse_map(s, dir));
        let diffuse = map(m.diffuse_texture.as_ref());
        let bump = map(m.normal_texture.as_ref().or(m.unknown_param.get("norm")).or(m.unknown_param.get("map_bump")));
        Self {
            tiling: diffuse.as_ref().and_then(|d| d.scale),
            offset: diffuse.as_ref().and_then(|d| d.offset),
            diffuse: diffuse.map(|d| d.file),
            ambient: map(m.ambient_texture.as_ref()).map(|d| d.file),
            specular: map(m.specular_texture.as_ref()).map(|d| d.file),
            emission: map(m.unknown_param.get("map_Ke")).map(|d| d.file),
            bump: bump.map(|d| d.file),
        }
    }

    fn requests(&self) -> Vec<(PathBuf, ColorSpace)> {
        let mut r = Vec::new();
        for p in [&self.diffuse, &self.ambient, &self.specular, &self.emission].into_iter().flatten() {
            r.push((p.clone(), ColorSpace::Srgb));
        }
        if let Some(b) = &self.bump {
            r.push((b.clone(), ColorSpace::Linear));
        }
        r
    }
}

struct MapSpec {
    file: PathBuf,
    scale: Option<Vec2>,
    offset: Option<Vec2>,
}

/// Parses a texture statement's argument: options (`-s u v w`, `-o u v w`, `-bm 1`, ...) and
/// the file name (which may contain spaces), resolved relative to the MTL's folder.
fn parse_map(s: &str, dir: &Path) -> MapSpec {
    let tokens: Vec<&str> = s.split_whitespace().collect();
    let (mut scale, mut offset) = (None, None);
    let mut i = 0;
    while i < tokens.len() && tokens[i].starts_with('-') && tokens[i].len() > 1 && tokens[i].parse::<f32>().is_err() {
        let opt = tokens[i];
        i += 1;
        let mut nums = Vec::new();
        let max = match opt {
            "-o" | "-s" | "-t" => 3,
            "-mm" => 2,
            _ => 1,
        };
        while nums.len() < max && i < tokens.len() && (tokens[i].parse::<f32>().is_ok() || max == 1 && nums.is_empty()) {
            nums.push(tokens[i].parse::<f32>().unwrap_or(0.0));
            i += 1;
            if i == tokens.len() {
                break;
            }
        }
        let v2 = |d: f32| Vec2::new(nums.first().copied().unwrap_or(d), nums.get(1).copied().unwrap_or(d));
        match opt {
            "-s" => scale = Some(v2(1.0)),
            "-o" => offset = Some(v2(0.0)),
            _ => {}
        }
    }
    let name = tokens[i.min(tokens.len())..].join(" ").replace('\\', "/");
    MapSpec { file: resolve(dir, &name), scale, offset }
}

/// `dir/name`, or a case-insensitive match of the last component if the exact one is missing.
fn resolve(dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(name);
    if p.exists() {
        return p;
    }
    let (Some(parent), Some(file)) = (p.parent(), p.file_name()) else { return p };
    let want = file.to_string_lossy().to_lowercase();
    if let Ok(entries) = std::fs::read_dir(parent) {
        for e in entries.flatten() {
            if e.file_name().to_string_lossy().to_lowercase() == want {
                return e.path();
            }
        }
    }
    p
}

/// Table 1 material from an MTL material (see docs/loaders.md for the mapping).
fn convert_material(m: &tobj::Material, maps: &MtlMaps, ids: &HashMap<(PathBuf, bool), TextureId>) -> Material {
    let id = |p: &Option<PathBuf>, cs: ColorSpace| p.as_ref().and_then(|p| ids.get(&(p.clone(), cs == ColorSpace::Linear)).copied());
    let d = Material::default();
    let finite3 = |v: Option<[f32; 3]>| v.map(Vec3::from).filter(|v| v.is_finite());
    let diffuse = finite3(m.diffuse).unwrap_or(d.diffuse).max(Vec3::ZERO);
    let specular = finite3(m.specular).unwrap_or(Vec3::ZERO).max(Vec3::ZERO);
    let ka = finite3(m.ambient).filter(|a| *a != Vec3::ZERO);
    let diffuse_map = id(&maps.diffuse, ColorSpace::Srgb);
    let (ambient, ambient_map) = match ka {
        Some(a) => (a.max(Vec3::ZERO), id(&maps.ambient, ColorSpace::Srgb)),
        None => (diffuse, id(&maps.ambient, ColorSpace::Srgb).or(diffuse_map)),
    };
    let opacity = m
        .dissolve
        .or_else(|| m.unknown_param.get("Tr").and_then(|t| t.trim().parse::<f32>().ok()).map(|t| 1.0 - t))
        .filter(|o| o.is_finite())
        .unwrap_or(1.0)
        .clamp(0.0, 1.0);
    let illum = m.illumination_model.unwrap_or(2);
    let reflectivity = if matches!(illum, 3 | 5 | 7) { specular.max_element().clamp(0.0, 1.0) } else { 0.0 };
    let refractive = matches!(illum, 4 | 6 | 7 | 9);
    let ni = m.optical_density.filter(|n| n.is_finite() && *n > 0.0);
    // Dissolve without a refracting illumination model: see-through without bending (IOR 1).
    let ior = if opacity < 1.0 && !refractive { 1.0 } else { ni.unwrap_or(d.ior) };
    Material {
        name: m.name.clone(),
        emission: finite3(m.emissive).unwrap_or(Vec3::ZERO).max(Vec3::ZERO),
        emission_map: id(&maps.emission, ColorSpace::Srgb),
        ambient,
        ambient_map,
        diffuse,
        diffuse_map,
        specular,
        shininess: m.shininess.filter(|s| s.is_finite()).map_or(0.0, |ns| ((ns - 1.0) / 254.0).clamp(0.0, 1.0)),
        specular_map: id(&maps.specular, ColorSpace::Srgb),
        normal_map: id(&maps.bump, ColorSpace::Linear),
        reflectivity,
        ior,
        opacity,
        optical_map: None,
        tiling: maps.tiling.filter(|t| t.is_finite()).unwrap_or(Vec2::ONE),
        offset: maps.offset.filter(|t| t.is_finite()).unwrap_or(Vec2::ZERO),
        casts_shadows: true,
    }
}

/// Polygons with more vertices than this are fan-triangulated (ear clipping is quadratic).
const MAX_EAR_CLIP: usize = 512;

/// Triangles of faces given as `indices` grouped by `arities` (empty = all triangles).
fn triangulate(positions: &[Vec3], indices: &[u32], arities: &[u32]) -> Result<Vec<[u32; 3]>, String> {
    if arities.is_empty() {
        if !indices.len().is_multiple_of(3) {
            return Err(format!("{} indices do not form whole triangles", indices.len()));
        }
        return Ok(indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect());
    }
    let mut out = Vec::with_capacity(indices.len());
    let mut start = 0usize;
    for (f, &a) in arities.iter().enumerate() {
        let a = a as usize;
        let face = indices.get(start..start + a).ok_or_else(|| format!("face {f} runs past the end of the index list"))?;
        start += a;
        if a < 3 {
            continue;
        }
        if a == 3 {
            out.push([face[0], face[1], face[2]]);
            continue;
        }
        let pts: Option<Vec<Vec3>> = face.iter().map(|&i| positions.get(i as usize).copied()).collect();
        let Some(pts) = pts else {
            return Err(format!("face {f} uses a vertex index past the {} vertices", positions.len()));
        };
        let before = out.len();
        if a > MAX_EAR_CLIP || is_convex(&pts) || !ear_clip(&pts, face, &mut out) {
            out.truncate(before);
            for k in 1..a - 1 {
                out.push([face[0], face[k], face[k + 1]]);
            }
        }
    }
    Ok(out)
}

/// Newell normal of a polygon.
fn polygon_normal(p: &[Vec3]) -> Vec3 {
    let mut n = Vec3::ZERO;
    for i in 0..p.len() {
        let (a, b) = (p[i], p[(i + 1) % p.len()]);
        n += Vec3::new((a.y - b.y) * (a.z + b.z), (a.z - b.z) * (a.x + b.x), (a.x - b.x) * (a.y + b.y));
    }
    n
}

fn is_convex(p: &[Vec3]) -> bool {
    let n = polygon_normal(p);
    (0..p.len()).all(|i| {
        let (a, b, c) = (p[i], p[(i + 1) % p.len()], p[(i + 2) % p.len()]);
        (b - a).cross(c - b).dot(n) >= 0.0
    })
}

/// Ear clipping in the polygon's plane; appends `p.len() - 2` triangles, or returns false when
/// the polygon is degenerate (the caller then uses a fan).
fn ear_clip(p: &[Vec3], face: &[u32], out: &mut Vec<[u32; 3]>) -> bool {
    let n = polygon_normal(p);
    if n.length_squared() == 0.0 || !n.is_finite() {
        return false;
    }
    let cross2 = |a: Vec3, b: Vec3, c: Vec3| (b - a).cross(c - a).dot(n);
    let mut rest: Vec<usize> = (0..p.len()).collect();
    // An ear: a convex corner (strictly, or degenerate in the second pass) with no other vertex
    // inside. Vertices shared with the corner (a polygon with a hole joined by a bridge visits
    // some vertices twice) do not count as inside.
    let is_ear = |rest: &[usize], i: usize, strict: bool| {
        let m = rest.len();
        let (ia, ib, ic) = (rest[(i + m - 1) % m], rest[i], rest[(i + 1) % m]);
        let (a, b, c) = (p[ia], p[ib], p[ic]);
        let turn = cross2(a, b, c);
        if turn < 0.0 || (strict && turn == 0.0) {
            return false;
        }
        rest.iter().all(|&j| {
            let q = p[j];
            if face[j] == face[ia] || face[j] == face[ib] || face[j] == face[ic] || q == a || q == b || q == c {
                return true;
            }
            !(cross2(a, b, q) >= 0.0 && cross2(b, c, q) >= 0.0 && cross2(c, a, q) >= 0.0)
        })
    };
    while rest.len() > 3 {
        let m = rest.len();
        let ear = (0..m).find(|&i| is_ear(&rest, i, true)).or_else(|| (0..m).find(|&i| is_ear(&rest, i, false)));
        let Some(i) = ear else { return false };
        out.push([face[rest[(i + m - 1) % m]], face[rest[i]], face[rest[(i + 1) % m]]]);
        rest.remove(i);
    }
    out.push([face[rest[0]], face[rest[1]], face[rest[2]]]);
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_mtl_and_texture_are_warnings_with_the_default_material() {
        let dir = tempfile::tempdir().unwrap();
        let obj = dir.path().join("quad.OBJ");
        std::fs::write(
            &obj,
            "mtllib nowhere.mtl\nusemtl stone\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n",
        )
        .unwrap();
        let (mut mats, mut texs) = (vec![Material::default()], Vec::new());
        let meshes = super::super::load_model(&obj, &mut mats, &mut texs).unwrap();
        assert_eq!(meshes.len(), 1);
        assert_eq!(meshes[0].indices.len(), 2);
        assert_eq!(meshes[0].material, 1);
        assert_eq!(mats.len(), 2);
        assert_eq!(meshes[0].uvs[2], Vec2::new(1.0, 0.0)); // v flipped

        let mtl = dir.path().join("m.mtl");
        std::fs::write(&mtl, "newmtl stone\nKd 0.5 0.5 0.5\nKs 0.25\nmap_Kd missing.png\n").unwrap();
        std::fs::write(&obj, "mtllib m.mtl\nusemtl stone\nv 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n").unwrap();
        let (mut mats, mut texs) = (Vec::new(), Vec::new());
        let meshes = super::super::load_model(&obj, &mut mats, &mut texs).unwrap();
        assert_eq!(mats.len(), 1, "no default needed");
        assert_eq!(mats[meshes[0].material].name, "stone");
        assert_eq!(mats[0].specular, Vec3::splat(0.25)); // `Ks 0.25` completed, not a tobj panic
        assert_eq!(mats[0].diffuse_map, None);
        assert!(texs.is_empty());
    }

    #[test]
    fn face_indices_beyond_the_files_counts_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let obj = dir.path().join("t.obj");
        let load = |text: &str| {
            std::fs::write(&obj, text).unwrap();
            super::super::load_model(&obj, &mut Vec::new(), &mut Vec::new())
        };
        assert!(load("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 -1/-1\n").is_ok());
        for bad in ["f 1 2 4", "f 1/2 2/1 3/1", "f 1//9 2 3", "f -4 2 3", "f 1/18446744073709551 2/1 3/1"] {
            let e = load(&format!("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n{bad}\n")).unwrap_err().to_string();
            assert!(e.contains("index out of range") && e.contains("t.obj"), "{bad}: {e}");
        }
        // Found by fuzzing: a texture index that overflowed tobj's `index * 2` (a panic with
        // overflow checks, a wrong texture coordinate without).
        let crash = include_str!("../../tests/fuzz-regressions/obj/tobj-texcoord-index-overflow.obj");
        let e = load(crash).unwrap_err().to_string();
        assert!(e.contains("index out of range"), "{e}");
    }

    #[test]
    fn map_options_set_tiling_and_offset() {
        let m = parse_map("-bm 0.5 -s 2 3 1 -o 0.25 0.5 textures\\my file.png", Path::new("/x"));
        assert_eq!(m.file, PathBuf::from("/x/textures/my file.png"));
        assert_eq!(m.scale, Some(Vec2::new(2.0, 3.0)));
        assert_eq!(m.offset, Some(Vec2::new(0.25, 0.5)));
        assert_eq!(parse_map("a.jpg", Path::new("/y")).file, PathBuf::from("/y/a.jpg"));
    }

    #[test]
    fn concave_polygon_is_ear_clipped_inside_its_outline() {
        // An L-shape: a fan from vertex 0 would create a triangle outside the polygon.
        let pts: Vec<Vec3> =
            [[0., 0.], [2., 0.], [2., 1.], [1., 1.], [1., 2.], [0., 2.]].iter().map(|p| Vec3::new(p[0], p[1], 0.0)).collect();
        let face: Vec<u32> = (0..6).map(|i| (i + 2) % 6).collect(); // start at the reflex-adjacent corner
        let tris = triangulate(&pts, &face, &[6]).unwrap();
        assert_eq!(tris.len(), 4);
        let area: f32 =
            tris.iter().map(|t| (pts[t[1] as usize] - pts[t[0] as usize]).cross(pts[t[2] as usize] - pts[t[0] as usize]).z * 0.5).sum();
        assert!((area - 3.0).abs() < 1e-5, "area {area}");
        assert!(tris.iter().all(|t| (pts[t[1] as usize] - pts[t[0] as usize]).cross(pts[t[2] as usize] - pts[t[0] as usize]).z > 0.0));
    }

    #[test]
    fn mtl_mapping_follows_table_1() {
        let mut m =
            tobj::Material { name: "glass".into(), diffuse: Some([0.5, 0.6, 0.7]), specular: Some([0.2, 0.9, 0.1]), ..Default::default() };
        m.shininess = Some(128.0);
        m.dissolve = Some(0.25);
        m.optical_density = Some(1.33);
        m.illumination_model = Some(7);
        let maps = MtlMaps::of(&m, Path::new("."));
        let out = convert_material(&m, &maps, &HashMap::new());
        assert_eq!(out.ambient, Vec3::new(0.5, 0.6, 0.7)); // Ka absent → Kd
        assert!((out.shininess - 127.0 / 254.0).abs() < 1e-6);
        assert!((out.reflectivity - 0.9).abs() < 1e-6);
        assert_eq!((out.opacity, out.ior), (0.25, 1.33));
        m.illumination_model = Some(2);
        m.unknown_param.insert("Tr".into(), "0.5".into());
        m.dissolve = None;
        let out = convert_material(&m, &maps, &HashMap::new());
        assert_eq!((out.opacity, out.ior, out.reflectivity), (0.5, 1.0, 0.0));
    }
}
