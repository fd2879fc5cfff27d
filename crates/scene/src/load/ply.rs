//! PLY meshes and point clouds (ASCII and binary) via ply-rs-bw, with our own element structs
//! (`PropertyAccess`) read one element at a time straight into the output arrays: no
//! intermediate `Vec` of elements, no per-property `HashMap`.

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek};
use std::path::Path;

use glam::{Vec2, Vec3};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{BeginList, ElementDef, Encoding, Header, PropertyAccess, PropertyAccessResult, PropertyType, ScalarType};

use super::{capped_capacity, check_finite, check_indices};
use crate::texture::srgb_to_linear;
use crate::{Material, Mesh, SceneError};

/// One vertex as read from the file; which fields are meaningful is known from the header.
#[derive(Default)]
struct Vertex {
    p: [f32; 3],
    n: [f32; 3],
    uv: [f32; 2],
    /// Colour in 0..1 (integer channels are normalised by their type's maximum).
    c: [f32; 3],
}

/// Which vertex field a property fills (0–2 position, 3–5 normal, 6–7 UV, 8–10 colour).
fn slot_of(name: &str) -> Option<usize> {
    Some(match name {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        "nx" => 3,
        "ny" => 4,
        "nz" => 5,
        "u" | "s" | "texture_u" | "texture_s" => 6,
        "v" | "t" | "texture_v" | "texture_t" => 7,
        "red" | "diffuse_red" | "r" => 8,
        "green" | "diffuse_green" | "g" => 9,
        "blue" | "diffuse_blue" | "b" => 10,
        _ => return None,
    })
}

impl Vertex {
    #[inline]
    fn set_slot(&mut self, slot: usize, v: f32) {
        match slot {
            0..=2 => self.p[slot] = v,
            3..=5 => self.n[slot - 3] = v,
            6 | 7 => self.uv[slot - 6] = v,
            8..=10 => self.c[slot - 8] = v,
            _ => {}
        }
    }

    #[inline]
    fn set(&mut self, name: &str, v: f32) -> PropertyAccessResult {
        match name {
            "x" => self.p[0] = v,
            "y" => self.p[1] = v,
            "z" => self.p[2] = v,
            "nx" => self.n[0] = v,
            "ny" => self.n[1] = v,
            "nz" => self.n[2] = v,
            "u" | "s" | "texture_u" | "texture_s" => self.uv[0] = v,
            "v" | "t" | "texture_v" | "texture_t" => self.uv[1] = v,
            "red" | "diffuse_red" | "r" => self.c[0] = v,
            "green" | "diffuse_green" | "g" => self.c[1] = v,
            "blue" | "diffuse_blue" | "b" => self.c[2] = v,
            _ => return PropertyAccessResult::Ignored,
        }
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Self::default()
    }
    fn set_float(&mut self, name: &str, v: f32) -> PropertyAccessResult {
        self.set(name, v)
    }
    fn set_double(&mut self, name: &str, v: f64) -> PropertyAccessResult {
        self.set(name, v as f32)
    }
    // Integer channels: colours are normalised to 0..1; integer coordinates are kept as numbers.
    fn set_uchar(&mut self, name: &str, v: u8) -> PropertyAccessResult {
        self.set_int_value(name, v as f32, 255.0)
    }
    fn set_char(&mut self, name: &str, v: i8) -> PropertyAccessResult {
        self.set_int_value(name, v as f32, 127.0)
    }
    fn set_ushort(&mut self, name: &str, v: u16) -> PropertyAccessResult {
        self.set_int_value(name, v as f32, 65_535.0)
    }
    fn set_short(&mut self, name: &str, v: i16) -> PropertyAccessResult {
        self.set_int_value(name, v as f32, 32_767.0)
    }
    fn set_int(&mut self, name: &str, v: i32) -> PropertyAccessResult {
        self.set_int_value(name, v as f32, i32::MAX as f32)
    }
    fn set_uint(&mut self, name: &str, v: u32) -> PropertyAccessResult {
        self.set_int_value(name, v as f32, u32::MAX as f32)
    }
}

impl Vertex {
    #[inline]
    fn set_int_value(&mut self, name: &str, v: f32, max: f32) -> PropertyAccessResult {
        if is_color(name) { self.set(name, v / max) } else { self.set(name, v) }
    }
}

fn is_color(name: &str) -> bool {
    matches!(name, "red" | "green" | "blue" | "diffuse_red" | "diffuse_green" | "diffuse_blue" | "r" | "g" | "b")
}

/// One face: its vertex-index list (signed lists are kept apart so negatives can be reported).
#[derive(Default)]
struct Face {
    signed: Vec<i32>,
    unsigned: Vec<u32>,
}

fn is_index_list(name: &str) -> bool {
    name == "vertex_indices" || name == "vertex_index"
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Self::default()
    }
    fn begin_list_int(&mut self, name: &str, _len: usize) -> BeginList<'_, i32> {
        if is_index_list(name) { BeginList::Fill(&mut self.signed) } else { BeginList::UseSetter }
    }
    fn begin_list_uint(&mut self, name: &str, _len: usize) -> BeginList<'_, u32> {
        if is_index_list(name) { BeginList::Fill(&mut self.unsigned) } else { BeginList::UseSetter }
    }
    fn set_list_uchar(&mut self, name: &str, v: Vec<u8>) -> PropertyAccessResult {
        self.set_list(name, v.into_iter().map(i32::from).collect())
    }
    fn set_list_char(&mut self, name: &str, v: Vec<i8>) -> PropertyAccessResult {
        self.set_list(name, v.into_iter().map(i32::from).collect())
    }
    fn set_list_ushort(&mut self, name: &str, v: Vec<u16>) -> PropertyAccessResult {
        self.set_list(name, v.into_iter().map(i32::from).collect())
    }
    fn set_list_short(&mut self, name: &str, v: Vec<i16>) -> PropertyAccessResult {
        self.set_list(name, v.into_iter().map(i32::from).collect())
    }
    fn set_list_float(&mut self, name: &str, _v: Vec<f32>) -> PropertyAccessResult {
        if is_index_list(name) { PropertyAccessResult::UnsupportedType } else { PropertyAccessResult::Ignored }
    }
    fn set_list_double(&mut self, name: &str, _v: Vec<f64>) -> PropertyAccessResult {
        self.set_list_float(name, Vec::new())
    }
}

impl Face {
    fn set_list(&mut self, name: &str, v: Vec<i32>) -> PropertyAccessResult {
        if is_index_list(name) {
            self.signed = v;
            PropertyAccessResult::Set
        } else {
            PropertyAccessResult::Ignored
        }
    }
}

/// Elements we do not use: read and dropped.
struct Skip;

impl PropertyAccess for Skip {
    fn new() -> Self {
        Skip
    }
}

fn scalar_size(t: &ScalarType) -> usize {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

/// A binary scalar at the start of `b` as f32, with its type's maximum for integer types
/// (used to normalise integer colours). `b` is at least the scalar's size (checked by the caller's
/// record layout).
#[inline]
fn scalar(b: &[u8], t: &ScalarType, little: bool) -> (f32, Option<f32>) {
    macro_rules! get {
        ($ty:ty, $n:expr) => {{
            let mut a = [0u8; $n];
            a.copy_from_slice(&b[..$n]);
            if little { <$ty>::from_le_bytes(a) } else { <$ty>::from_be_bytes(a) }
        }};
    }
    match t {
        ScalarType::Char => (get!(i8, 1) as f32, Some(127.0)),
        ScalarType::UChar => (b[0] as f32, Some(255.0)),
        ScalarType::Short => (get!(i16, 2) as f32, Some(32_767.0)),
        ScalarType::UShort => (get!(u16, 2) as f32, Some(65_535.0)),
        ScalarType::Int => (get!(i32, 4) as f32, Some(i32::MAX as f32)),
        ScalarType::UInt => (get!(u32, 4) as f32, Some(u32::MAX as f32)),
        ScalarType::Float => (get!(f32, 4), None),
        ScalarType::Double => (get!(f64, 8) as f32, None),
    }
}

/// A binary integer scalar (None for float types).
fn int_scalar(b: &[u8], t: &ScalarType, little: bool) -> Option<i64> {
    let (v, max) = scalar(b, t, little);
    match t {
        // f32 is not exact above 2^24: decode 32-bit integers directly.
        ScalarType::Int => Some(i64::from(if little {
            i32::from_le_bytes([b[0], b[1], b[2], b[3]])
        } else {
            i32::from_be_bytes([b[0], b[1], b[2], b[3]])
        })),
        ScalarType::UInt => Some(i64::from(if little {
            u32::from_le_bytes([b[0], b[1], b[2], b[3]])
        } else {
            u32::from_be_bytes([b[0], b[1], b[2], b[3]])
        })),
        _ => max.map(|_| v as i64),
    }
}

/// Smallest number of bytes one element can take in the file.
fn min_element_bytes(def: &ElementDef, encoding: Encoding) -> usize {
    def.properties
        .values()
        .map(|p| match (&p.data_type, encoding) {
            (_, Encoding::Ascii) => 2,
            (PropertyType::Scalar(t), _) => scalar_size(t),
            (PropertyType::List(count, _), _) => scalar_size(count),
        })
        .sum::<usize>()
        .max(1)
}

/// An open PLY file positioned after its header.
struct PlyFile<'a> {
    path: &'a Path,
    reader: Reader<BufReader<File>>,
    header: Header,
    len: u64,
    line: String,
}

impl<'a> PlyFile<'a> {
    fn open(path: &'a Path) -> Result<Self, SceneError> {
        super::check_file(path, "PLY file", super::MAX_MODEL_BYTES)?;
        let file = File::open(path).map_err(|e| SceneError::new(path, format!("cannot open PLY file: {e}")))?;
        let len = file.metadata().map(|m| m.len()).unwrap_or(0);
        if len == 0 {
            return Err(SceneError::new(path, "PLY file is empty"));
        }
        let mut reader = Reader::new(BufReader::with_capacity(1 << 16, file));
        let header =
            Parser::<Skip>::new().read_header(&mut reader).map_err(|e| SceneError::new(path, format!("invalid PLY header: {e}")))?;
        Ok(Self { path, reader, header, len, line: String::new() })
    }

    fn bytes_left(&mut self) -> u64 {
        let pos = self.reader.get_mut().stream_position().unwrap_or(0);
        self.len.saturating_sub(pos)
    }

    fn err(&self, msg: impl Into<String>) -> SceneError {
        SceneError::new(self.path, msg)
    }

    /// Reads element `i` of `def` as `E`.
    fn read<E: PropertyAccess>(&mut self, parser: &Parser<E>, def: &ElementDef, i: usize) -> Result<E, SceneError> {
        let what = |e: &dyn std::fmt::Display| format!("cannot read {} {i} of {}: {e}", def.name, def.count);
        match self.header.encoding {
            Encoding::BinaryLittleEndian => parser.read_little_endian_element(self.reader.get_mut(), def).map_err(|e| self.err(what(&e))),
            Encoding::BinaryBigEndian => parser.read_big_endian_element(self.reader.get_mut(), def).map_err(|e| self.err(what(&e))),
            Encoding::Ascii => {
                loop {
                    self.line.clear();
                    let n = self.reader.get_mut().read_line(&mut self.line).map_err(|e| self.err(what(&e)))?;
                    if n == 0 {
                        return Err(self.err(format!("file ends early: {} {i} of {} is missing", def.name, def.count)));
                    }
                    if !self.line.trim().is_empty() {
                        break;
                    }
                }
                parser.read_ascii_element(&self.line, def).map_err(|e| self.err(what(&e)))
            }
        }
    }

    /// Reads every vertex of `def` and hands it to `visit`. Binary vertex elements made only of
    /// scalars (the common case, and every large file) are decoded straight from fixed record
    /// offsets in chunks; anything else goes through ply-rs-bw element by element.
    fn for_each_vertex(&mut self, def: &ElementDef, mut visit: impl FnMut(usize, &Vertex) -> Result<(), String>) -> Result<(), SceneError> {
        let little = match self.header.encoding {
            Encoding::BinaryLittleEndian => Some(true),
            Encoding::BinaryBigEndian => Some(false),
            Encoding::Ascii => None,
        };
        let scalars: Option<Vec<ScalarType>> = def
            .properties
            .values()
            .map(|p| match &p.data_type {
                PropertyType::Scalar(t) => Some(t.clone()),
                PropertyType::List(..) => None,
            })
            .collect();
        let (Some(little), Some(types)) = (little, scalars) else {
            let parser = Parser::<Vertex>::new();
            for i in 0..def.count {
                let v = self.read(&parser, def, i)?;
                visit(i, &v).map_err(|m| self.err(m))?;
            }
            return Ok(());
        };
        // (offset, type, slot) of every property we use; `stride` is the record size.
        let mut fields = Vec::new();
        let mut stride = 0;
        for (name, t) in def.properties.keys().zip(&types) {
            if let Some(slot) = slot_of(name) {
                fields.push((stride, t.clone(), slot, is_color(name)));
            }
            stride += scalar_size(t);
        }
        const CHUNK: usize = 1 << 14;
        let mut buf = vec![0u8; stride * CHUNK.min(def.count)];
        let mut i = 0;
        while i < def.count {
            let n = CHUNK.min(def.count - i);
            let bytes = &mut buf[..n * stride];
            if let Err(e) = self.reader.get_mut().read_exact(bytes) {
                return Err(self.err(if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    format!("file ends early: the vertices from {i} on (of {}) are missing or cut off", def.count)
                } else {
                    format!("cannot read vertex {i} of {}: {e}", def.count)
                }));
            }
            for (k, rec) in bytes.chunks_exact(stride).enumerate() {
                let mut v = Vertex::default();
                for (off, t, slot, color) in &fields {
                    let (value, max) = scalar(&rec[*off..], t, little);
                    v.set_slot(*slot, if *color { max.map_or(value, |m| value / m) } else { value });
                }
                visit(i + k, &v).map_err(|m| self.err(m))?;
            }
            i += n;
        }
        Ok(())
    }

    /// Reads every face of `def` and hands its vertex indices to `visit`. Binary files are read
    /// directly (one reused index buffer, no allocation per face); ASCII through ply-rs-bw.
    fn for_each_face(
        &mut self,
        def: &ElementDef,
        parser: &Parser<Face>,
        mut visit: impl FnMut(usize, &[u32]) -> Result<(), String>,
    ) -> Result<(), SceneError> {
        let little = match self.header.encoding {
            Encoding::BinaryLittleEndian => true,
            Encoding::BinaryBigEndian => false,
            Encoding::Ascii => {
                let mut idx = Vec::new();
                for i in 0..def.count {
                    let face = self.read(parser, def, i)?;
                    idx.clear();
                    if face.unsigned.is_empty() {
                        for &s in &face.signed {
                            idx.push(u32::try_from(s).map_err(|_| self.err(format!("face {i} has a negative vertex index {s}")))?);
                        }
                    } else {
                        idx.extend_from_slice(&face.unsigned);
                    }
                    visit(i, &idx).map_err(|m| self.err(m))?;
                }
                return Ok(());
            }
        };
        let props: Vec<(bool, PropertyType)> = def.properties.iter().map(|(k, p)| (is_index_list(k), p.data_type.clone())).collect();
        let mut idx: Vec<u32> = Vec::new();
        let mut item = [0u8; 8];
        for i in 0..def.count {
            idx.clear();
            for (is_indices, t) in &props {
                let eof = |e: std::io::Error| {
                    if e.kind() == std::io::ErrorKind::UnexpectedEof {
                        format!("file ends early: face {i} of {} is cut off", def.count)
                    } else {
                        format!("cannot read face {i} of {}: {e}", def.count)
                    }
                };
                let r = self.reader.get_mut();
                match t {
                    PropertyType::Scalar(st) => r.read_exact(&mut item[..scalar_size(st)]).map_err(|e| self.err(eof(e)))?,
                    PropertyType::List(ct, it) => {
                        let cs = scalar_size(ct);
                        r.read_exact(&mut item[..cs]).map_err(|e| self.err(eof(e)))?;
                        let (count, _) = scalar(&item[..cs], ct, little);
                        if !(0.0..=16_777_216.0).contains(&count) {
                            return Err(self.err(format!("face {i} has a list of {count} entries")));
                        }
                        let size = scalar_size(it);
                        for _ in 0..count as usize {
                            let r = self.reader.get_mut();
                            r.read_exact(&mut item[..size]).map_err(|e| self.err(eof(e)))?;
                            if *is_indices {
                                let v = int_scalar(&item[..size], it, little)
                                    .ok_or_else(|| self.err(format!("face {i}: vertex indices of type {it:?} are not integers")))?;
                                let v = u32::try_from(v).map_err(|_| self.err(format!("face {i} has a negative vertex index {v}")))?;
                                idx.push(v);
                            }
                        }
                    }
                }
            }
            visit(i, &idx).map_err(|m| self.err(m))?;
        }
        Ok(())
    }

    /// Nothing may follow the last element: in ASCII files nothing but blank lines, in binary
    /// files no byte. More data means the header under-counts an element (e.g. a vertex line then
    /// read as a face, or a binary body cut from a larger file).
    fn check_no_trailing_data(&mut self, last: &str) -> Result<(), SceneError> {
        if self.header.encoding != Encoding::Ascii {
            let extra = self.bytes_left();
            if extra > 0 {
                return Err(self.err(format!(
                    "{extra} byte(s) of data after the last {last}: the header's element counts are smaller than the binary body"
                )));
            }
            return Ok(());
        }
        let mut extra = 0usize;
        loop {
            self.line.clear();
            let n = self.reader.get_mut().read_line(&mut self.line).map_err(|e| self.err(format!("cannot read: {e}")))?;
            if n == 0 {
                break;
            }
            if !self.line.trim().is_empty() {
                extra += 1;
            }
        }
        if extra > 0 {
            return Err(self.err(format!(
                "{extra} line(s) of data after the last {last}: the header's element counts are smaller than the body (a vertex line read as a face?)"
            )));
        }
        Ok(())
    }

    fn skip(&mut self, def: &ElementDef) -> Result<(), SceneError> {
        let parser = Parser::<Skip>::new();
        for i in 0..def.count {
            self.read(&parser, def, i)?;
        }
        Ok(())
    }
}

/// Which vertex attributes the header declares.
struct Layout {
    normals: bool,
    uvs: bool,
    colors: bool,
}

fn layout(def: &ElementDef) -> Layout {
    let has = |names: &[&str]| names.iter().any(|n| def.properties.contains_key(*n));
    let all = |names: &[&[&str]]| names.iter().all(|alts| has(alts));
    Layout {
        normals: all(&[&["nx"], &["ny"], &["nz"]]),
        uvs: all(&[&["u", "s", "texture_u", "texture_s"], &["v", "t", "texture_v", "texture_t"]]),
        colors: all(&[&["red", "diffuse_red", "r"], &["green", "diffuse_green", "g"], &["blue", "diffuse_blue", "b"]]),
    }
}

fn vertex_def<'h>(f: &PlyFile<'_>, header: &'h Header) -> Result<&'h ElementDef, SceneError> {
    let def = header.elements.get("vertex").ok_or_else(|| f.err("PLY file has no `vertex` element"))?;
    for c in ["x", "y", "z"] {
        if !def.properties.contains_key(c) {
            return Err(f.err(format!("PLY vertex element has no `{c}` property")));
        }
    }
    for (name, p) in &def.properties {
        if slot_of(name).is_some() && matches!(p.data_type, PropertyType::List(..)) {
            return Err(f.err(format!("PLY vertex property `{name}` is declared as a list; vertex attributes must be scalars")));
        }
    }
    Ok(def)
}

/// For ASCII point clouds, the vertex element without trailing list properties (a list of
/// `vertex_indices` in the vertex element, with no data on the lines: assimp issue 623). Their
/// values, if present, are the last tokens of the line and are not needed for points.
fn without_trailing_lists(def: &ElementDef, encoding: Encoding) -> ElementDef {
    let mut out = def.clone();
    if encoding == Encoding::Ascii {
        while out.properties.last().is_some_and(|(_, p)| matches!(p.data_type, PropertyType::List(..))) {
            out.properties.pop();
        }
    }
    out
}

fn to_u8(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Vertices (x, y, z and, if present, red/green/blue) of a PLY file as a point cloud.
pub(super) fn load_points(path: &Path) -> Result<(Vec<Vec3>, Vec<[u8; 3]>), SceneError> {
    let mut f = PlyFile::open(path)?;
    let header = std::mem::take(&mut f.header);
    f.header.encoding = header.encoding;
    let vdef = vertex_def(&f, &header)?;
    let lay = layout(vdef);
    let point_def = without_trailing_lists(vdef, header.encoding);
    for (name, def) in &header.elements {
        if name != "vertex" {
            f.skip(def)?;
            continue;
        }
        let cap = capped_capacity(def.count, min_element_bytes(def, header.encoding), f.bytes_left());
        let mut points = Vec::with_capacity(cap);
        let mut colors = if lay.colors { Vec::with_capacity(cap) } else { Vec::new() };
        f.for_each_vertex(&point_def, |i, v| {
            let p = Vec3::from(v.p);
            check_finite("point", i, p)?;
            points.push(p);
            if lay.colors {
                colors.push(v.c.map(to_u8));
            }
            Ok(())
        })?;
        // Everything after the vertices (faces, ...) is not needed for a point cloud; when
        // nothing should follow, nothing may.
        if header.elements.keys().last().is_some_and(|k| k == "vertex") {
            f.check_no_trailing_data("vertex")?;
        }
        return Ok((points, colors));
    }
    Err(f.err("PLY file has no `vertex` element"))
}

/// A PLY mesh with one default material appended to `materials`.
pub(super) fn load_mesh(path: &Path, materials: &mut Vec<Material>) -> Result<Vec<Mesh>, SceneError> {
    let mut f = PlyFile::open(path)?;
    let header = std::mem::take(&mut f.header);
    f.header.encoding = header.encoding;
    let vdef = vertex_def(&f, &header)?;
    let lay = layout(vdef);
    let has_faces = header.elements.get("face").is_some_and(|d| d.count > 0 && d.properties.keys().any(|k| is_index_list(k)));
    if !has_faces {
        return Err(f.err("PLY file has no faces (use it as a point cloud)"));
    }
    let mut mesh = Mesh::default();
    let fparser = Parser::<Face>::new();
    for (name, def) in &header.elements {
        let cap = capped_capacity(def.count, min_element_bytes(def, header.encoding), f.bytes_left());
        match name.as_str() {
            "vertex" => {
                mesh.positions.reserve_exact(cap);
                if lay.normals {
                    mesh.normals.reserve_exact(cap);
                }
                if lay.uvs {
                    mesh.uvs.reserve_exact(cap);
                }
                if lay.colors {
                    mesh.colors.reserve_exact(cap);
                }
                f.for_each_vertex(def, |i, v| {
                    let p = Vec3::from(v.p);
                    check_finite("vertex", i, p)?;
                    mesh.positions.push(p);
                    if lay.normals {
                        let n = Vec3::from(v.n);
                        mesh.normals.push(if n.is_finite() { n.normalize_or_zero() } else { Vec3::ZERO });
                    }
                    if lay.uvs {
                        // PLY (like OBJ) puts v = 0 at the bottom of the image; ours is the top.
                        let uv = Vec2::new(v.uv[0], 1.0 - v.uv[1]);
                        mesh.uvs.push(if uv.is_finite() { uv } else { Vec2::ZERO });
                    }
                    if lay.colors {
                        mesh.colors.push(Vec3::from(v.c.map(|c| srgb_to_linear(c.clamp(0.0, 1.0)))));
                    }
                    Ok(())
                })?;
            }
            "face" => {
                // Most faces are triangles: one triangle per face is the usual count.
                mesh.indices.reserve_exact(cap);
                f.for_each_face(def, &fparser, |_, idx| {
                    // Polygons become triangle fans; faces with fewer than 3 vertices are dropped.
                    for k in 1..idx.len().saturating_sub(1) {
                        mesh.indices.push([idx[0], idx[k], idx[k + 1]]);
                    }
                    Ok(())
                })?;
            }
            _ => f.skip(def)?,
        }
    }
    f.check_no_trailing_data(header.elements.keys().last().map_or("element", |k| k.as_str()))?;
    check_indices(&mesh.indices, mesh.positions.len()).map_err(|m| f.err(m))?;
    if mesh.indices.is_empty() {
        return Err(f.err("PLY file has no faces with 3 or more vertices (use it as a point cloud)"));
    }
    if lay.normals && mesh.normals.iter().all(|n| *n == Vec3::ZERO) {
        mesh.normals.clear();
    }
    mesh.material = materials.len();
    materials.push(Material { name: super::image::texture_name(path), ..Material::default() });
    Ok(vec![mesh])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    #[test]
    fn ascii_quad_with_uvs_colors_and_normals_is_fanned() {
        let dir = tempfile::tempdir().unwrap();
        let src = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
                   property float nx\nproperty float ny\nproperty float nz\nproperty float s\nproperty float t\n\
                   property uchar red\nproperty uchar green\nproperty uchar blue\n\
                   element face 1\nproperty list uchar uint vertex_index\nend_header\n\
                   0 0 0 0 0 2 0 0 255 0 0\n1 0 0 0 0 1 1 0 0 255 0\n1 1 0 0 0 1 1 1 0 0 255\n0 1 0 0 0 1 0 1 255 255 255\n4 0 1 2 3\n";
        let p = write(dir.path(), "quad.ply", src.as_bytes());
        let mut mats = vec![Material::default()];
        let meshes = load_mesh(&p, &mut mats).unwrap();
        assert_eq!(mats.len(), 2);
        let m = &meshes[0];
        assert_eq!(m.material, 1);
        assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.normals[0], Vec3::Z); // normalised
        assert_eq!(m.uvs[2], Vec2::new(1.0, 0.0)); // v flipped
        assert!((m.colors[0] - Vec3::X).length() < 1e-6);

        let (pts, cols) = load_points(&p).unwrap();
        assert_eq!(pts.len(), 4);
        assert_eq!(cols, vec![[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255]]);
    }

    #[test]
    fn binary_fast_path_matches_ascii() {
        let dir = tempfile::tempdir().unwrap();
        let head = |fmt: &str| {
            format!(
                "ply\nformat {fmt} 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
                 property uchar target_count\nproperty ushort red\nproperty uchar green\nproperty float blue\nend_header\n"
            )
        };
        let ascii = head("ascii") + "1 2 3 7 65535 0 0.5\n-1 0.25 8 9 0 255 1\n";
        let mut bin = head("binary_little_endian").into_bytes();
        for (p, t, r, g, b) in [([1f32, 2., 3.], 7u8, 65_535u16, 0u8, 0.5f32), ([-1., 0.25, 8.], 9, 0, 255, 1.0)] {
            p.iter().for_each(|c| bin.extend_from_slice(&c.to_le_bytes()));
            bin.push(t);
            bin.extend_from_slice(&r.to_le_bytes());
            bin.push(g);
            bin.extend_from_slice(&b.to_le_bytes());
        }
        let a = load_points(&write(dir.path(), "a.ply", ascii.as_bytes())).unwrap();
        let b = load_points(&write(dir.path(), "b.ply", &bin)).unwrap();
        assert_eq!(a, b);
        assert_eq!(b.0[1], Vec3::new(-1.0, 0.25, 8.0));
        assert_eq!(b.1, vec![[255, 0, 128], [0, 255, 255]]);
        // Cut inside the second record: a clean error.
        let e = load_points(&write(dir.path(), "cut.ply", &bin[..bin.len() - 3])).unwrap_err();
        assert!(e.message.contains("ends early"), "{e}");
        // Longer than the header says (one more byte, one more record): an error naming the file.
        for extra in [vec![0u8], bin[bin.len() - 16..].to_vec()] {
            let long = [bin.clone(), extra.clone()].concat();
            let p = write(dir.path(), "long.ply", &long);
            let e = load_points(&p).unwrap_err();
            assert!(e.to_string().contains("long.ply"), "{e}");
            assert!(e.message.contains(&format!("{} byte(s) of data after the last vertex", extra.len())), "{e}");
        }
    }

    #[test]
    fn binary_big_endian_and_bad_indices() {
        let dir = tempfile::tempdir().unwrap();
        let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\n\
                      element face 1\nproperty list uchar int vertex_indices\nend_header\n"
            .to_vec();
        for v in [0.0f64, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
            b.extend_from_slice(&v.to_be_bytes());
        }
        let good = [b.clone(), vec![3], 0i32.to_be_bytes().to_vec(), 1i32.to_be_bytes().to_vec(), 2i32.to_be_bytes().to_vec()].concat();
        let p = write(dir.path(), "be.ply", &good);
        let m = load_mesh(&p, &mut Vec::new()).unwrap();
        assert_eq!(m[0].positions[1], Vec3::X);
        assert_eq!(m[0].indices, vec![[0, 1, 2]]);
        // A face more in the body than in the header.
        let face = [vec![3], 0i32.to_be_bytes().to_vec(), 2i32.to_be_bytes().to_vec(), 1i32.to_be_bytes().to_vec()].concat();
        let p = write(dir.path(), "extra-face.ply", &[good.clone(), face].concat());
        let e = load_mesh(&p, &mut Vec::new()).unwrap_err();
        assert!(e.message.contains("13 byte(s) of data after the last face"), "{e}");

        let neg = [b.clone(), vec![3], 0i32.to_be_bytes().to_vec(), (-1i32).to_be_bytes().to_vec(), 2i32.to_be_bytes().to_vec()].concat();
        let p = write(dir.path(), "neg.ply", &neg);
        let e = load_mesh(&p, &mut Vec::new()).unwrap_err();
        assert!(e.message.contains("negative"), "{e}");

        let nan = [
            b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
                .to_vec(),
            f32::NAN.to_le_bytes().to_vec(),
            0f32.to_le_bytes().to_vec(),
            0f32.to_le_bytes().to_vec(),
        ]
        .concat();
        let p = write(dir.path(), "nan.ply", &nan);
        let e = load_points(&p).unwrap_err();
        assert!(e.message.contains("not finite"), "{e}");
    }
}
