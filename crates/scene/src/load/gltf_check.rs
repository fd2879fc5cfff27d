//! glTF accessor validation, run before any of the gltf crate's readers: the readers trust the
//! file and reach `unreachable!`, slice panics or assertions on accessors the glTF schema allows
//! but the spec forbids (issue 22). Every accessor a triangle primitive uses is checked for its
//! component type and shape per semantic, its stride and bounds in its buffer view and buffer,
//! a sane count, and its sparse part (bounds, indices in range).

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::mesh::Semantic;
use ::gltf::{Accessor, Document};

/// Most elements one accessor may hold (2²⁸: 268 million; far above any real mesh, far below
/// what would overflow a `u32` index count or exhaust memory on an accessor without a view).
pub(super) const MAX_ACCESSOR_COUNT: usize = 1 << 28;

/// Checks every accessor used by the document's mesh primitives. `buffer_len(i)` is the loaded
/// length of buffer `i`. The error names the mesh, primitive, semantic and accessor.
pub(super) fn check_document(doc: &Document, buffer_len: &dyn Fn(usize) -> usize) -> Result<(), String> {
    for mesh in doc.meshes() {
        for prim in mesh.primitives() {
            let at = format!("mesh {} primitive {}", mesh.index(), prim.index());
            for (semantic, accessor) in prim.attributes() {
                let name = semantic.to_string();
                check_semantic(&semantic, &accessor).map_err(|e| format!("{at}: {name} accessor {}: {e}", accessor.index()))?;
                check_accessor(&accessor, buffer_len).map_err(|e| format!("{at}: {name} accessor {}: {e}", accessor.index()))?;
            }
            if let Some(idx) = prim.indices() {
                let what = |e: String| format!("{at}: index accessor {}: {e}", idx.index());
                if !matches!(idx.data_type(), DataType::U8 | DataType::U16 | DataType::U32) || idx.dimensions() != Dimensions::Scalar {
                    return Err(what(format!(
                        "indices must be SCALAR of an unsigned integer type, not {:?} {:?}",
                        idx.dimensions(),
                        idx.data_type()
                    )));
                }
                if idx.sparse().is_some() {
                    return Err(what("sparse index accessors are not supported".into()));
                }
                check_accessor(&idx, buffer_len).map_err(what)?;
            }
        }
    }
    Ok(())
}

/// Component type and shape allowed by the glTF 2.0 spec for the attributes this loader reads.
fn check_semantic(semantic: &Semantic, a: &Accessor<'_>) -> Result<(), String> {
    use DataType::*;
    use Dimensions::*;
    let (t, d, norm) = (a.data_type(), a.dimensions(), a.normalized());
    let ok = match semantic {
        Semantic::Positions | Semantic::Normals => t == F32 && d == Vec3,
        Semantic::Tangents => t == F32 && d == Vec4,
        Semantic::TexCoords(_) => d == Vec2 && (t == F32 || (norm && matches!(t, U8 | U16))),
        Semantic::Colors(_) => matches!(d, Vec3 | Vec4) && (t == F32 || (norm && matches!(t, U8 | U16))),
        // Not read by this loader.
        _ => true,
    };
    if ok { Ok(()) } else { Err(format!("{d:?} of {t:?}{} is not allowed for this attribute", if norm { " (normalized)" } else { "" })) }
}

/// Bytes from `offset` for `count` elements of `elem` bytes, `stride` apart, within `len`.
fn span_fits(offset: usize, count: usize, elem: usize, stride: usize, len: usize) -> bool {
    if count == 0 {
        return offset <= len;
    }
    (count - 1).checked_mul(stride).and_then(|s| s.checked_add(elem)).and_then(|s| s.checked_add(offset)).is_some_and(|end| end <= len)
}

/// A buffer view's bytes within its (loaded) buffer.
fn check_view(v: &::gltf::buffer::View<'_>, buffer_len: &dyn Fn(usize) -> usize) -> Result<(), String> {
    let len = buffer_len(v.buffer().index());
    if !span_fits(v.offset(), 1, v.length(), 0, len) {
        return Err(format!(
            "buffer view {} (offset {}, length {}) runs past the end of buffer {} ({len} bytes)",
            v.index(),
            v.offset(),
            v.length(),
            v.buffer().index()
        ));
    }
    Ok(())
}

fn check_accessor(a: &Accessor<'_>, buffer_len: &dyn Fn(usize) -> usize) -> Result<(), String> {
    let (count, elem) = (a.count(), a.size());
    if count > MAX_ACCESSOR_COUNT {
        return Err(format!("count {count} is above the limit of {MAX_ACCESSOR_COUNT}"));
    }
    // The spec's minimum; gltf 1.4.1's readers compute `count - 1` (an overflow, found by fuzzing).
    if count == 0 {
        return Err("count 0 (glTF accessors hold at least 1 element)".into());
    }
    if let Some(v) = a.view() {
        check_view(&v, buffer_len)?;
        let stride = v.stride().unwrap_or(elem);
        if stride < elem {
            return Err(format!("buffer view {} has byteStride {stride}, smaller than the {elem}-byte element", v.index()));
        }
        if !span_fits(a.offset(), count, elem, stride, v.length()) {
            return Err(format!(
                "{count} elements of {elem} bytes (stride {stride}) from offset {} run past the end of buffer view {} ({} bytes)",
                a.offset(),
                v.index(),
                v.length()
            ));
        }
    }
    if let Some(s) = a.sparse() {
        let n = s.count();
        if n == 0 {
            return Err("sparse count 0 (glTF sparse accessors hold at least 1 element)".into());
        }
        if n > count {
            return Err(format!("sparse count {n} is above the accessor's count {count}"));
        }
        let ind = s.indices();
        let iv = ind.view();
        check_view(&iv, buffer_len)?;
        let isize = match ind.index_type() {
            ::gltf::accessor::sparse::IndexType::U8 => 1,
            ::gltf::accessor::sparse::IndexType::U16 => 2,
            ::gltf::accessor::sparse::IndexType::U32 => 4,
        };
        if !span_fits(ind.offset(), n, isize, isize, iv.length()) {
            return Err(format!("sparse indices run past the end of buffer view {}", iv.index()));
        }
        let vals = s.values();
        let vv = vals.view();
        check_view(&vv, buffer_len)?;
        if !span_fits(vals.offset(), n, elem, elem, vv.length()) {
            return Err(format!("sparse values run past the end of buffer view {}", vv.index()));
        }
        // The index values themselves are checked by `check_sparse_indices`, with the bytes.
    }
    Ok(())
}

/// Every sparse index of every accessor the primitives use is below the accessor's count.
/// Run after [`check_document`] (which proved the index bytes are in bounds).
pub(super) fn check_sparse_indices<'b>(doc: &Document, buffer: &dyn Fn(usize) -> &'b [u8]) -> Result<(), String> {
    for mesh in doc.meshes() {
        for prim in mesh.primitives() {
            for (semantic, a) in prim.attributes() {
                let Some(s) = a.sparse() else { continue };
                let ind = s.indices();
                let v = ind.view();
                let bytes = buffer(v.buffer().index());
                let start = v.offset() + ind.offset();
                let size = match ind.index_type() {
                    ::gltf::accessor::sparse::IndexType::U8 => 1,
                    ::gltf::accessor::sparse::IndexType::U16 => 2,
                    ::gltf::accessor::sparse::IndexType::U32 => 4,
                };
                for k in 0..s.count() {
                    let b = bytes.get(start + k * size..start + (k + 1) * size).ok_or("sparse index past its buffer")?;
                    let i = b.iter().rev().fold(0usize, |acc, &x| (acc << 8) | x as usize);
                    if i >= a.count() {
                        return Err(format!(
                            "mesh {} primitive {}: {} accessor {}: sparse index {k} is {i}, but the accessor has {} elements",
                            mesh.index(),
                            prim.index(),
                            semantic.to_string(),
                            a.index(),
                            a.count()
                        ));
                    }
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_are_checked_without_overflow() {
        assert!(span_fits(0, 3, 12, 12, 36));
        assert!(!span_fits(0, 4, 12, 12, 36));
        assert!(span_fits(4, 3, 12, 16, 48));
        assert!(!span_fits(usize::MAX, 2, 12, 12, 36));
        assert!(!span_fits(0, usize::MAX, 12, 12, 36));
        assert!(span_fits(36, 0, 12, 12, 36));
    }
}
