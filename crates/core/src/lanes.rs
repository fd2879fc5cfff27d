//! Four lanes at a time (structure of arrays): `Vec3` arithmetic on four points at once, each
//! lane doing exactly the scalar operations, in the same order, that glam's `Vec3` does. The
//! CPU backend's four-pixel paths (deferred lighting, the G-buffer fill) are built on these and
//! tested bit for bit against their one-pixel forms.

use glam::{Vec3, Vec4};

/// Three components of four lanes: `[x, y, z]`, lane `i` of each is point `i`.
pub type V3 = [Vec4; 3];

/// Four points as lanes.
#[inline]
pub fn soa(v: [Vec3; 4]) -> V3 {
    [0, 1, 2].map(|k| Vec4::new(v[0][k], v[1][k], v[2][k], v[3][k]))
}

/// The four points of lanes.
#[inline]
pub fn aos(v: V3) -> [Vec3; 4] {
    let [x, y, z] = v.map(|a| a.to_array());
    [0, 1, 2, 3].map(|i| Vec3::new(x[i], y[i], z[i]))
}

/// Lane `i` as a point.
#[inline]
pub fn lane(v: V3, i: usize) -> Vec3 {
    Vec3::new(v[0][i], v[1][i], v[2][i])
}

/// One point in every lane.
#[inline]
pub fn splat3(v: Vec3) -> V3 {
    [Vec4::splat(v.x), Vec4::splat(v.y), Vec4::splat(v.z)]
}

/// `Vec3::dot` lane by lane: `(x·x′ + y·y′) + z·z′`.
#[inline]
pub fn dot3(a: V3, b: V3) -> Vec4 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `v[0] * b.x + v[1] * b.y + v[2] * b.z` (barycentric interpolation of three corners) lane by
/// lane, with the weights `b` as lanes.
#[inline]
pub fn lerp3(v: [Vec3; 3], b: V3) -> V3 {
    [0, 1, 2].map(|k| Vec4::splat(v[0][k]) * b[0] + Vec4::splat(v[1][k]) * b[1] + Vec4::splat(v[2][k]) * b[2])
}

/// `Vec3::normalize_or(fallback)` lane by lane: `v · (1 / √(v · v))` where that reciprocal is
/// finite and positive.
#[inline]
pub fn normalize_or3(v: V3, fallback: V3) -> V3 {
    let rcp = Vec4::ONE / dot3(v, v).sqrt();
    let ok = rcp.is_finite_mask() & rcp.cmpgt(Vec4::ZERO);
    [0, 1, 2].map(|k| Vec4::select(ok, v[k] * rcp, fallback[k]))
}

/// `Vec3::normalize_or_zero` lane by lane.
#[inline]
pub fn normalize_or_zero3(v: V3) -> V3 {
    normalize_or3(v, [Vec4::ZERO; 3])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bits(v: Vec3) -> [u32; 3] {
        v.to_array().map(f32::to_bits)
    }

    /// Awkward values: signed zeros, tiny and huge magnitudes, infinities, NaN.
    const VALUES: [f32; 10] = [0.0, -0.0, 1.0, -2.5, 1e-30, -3e-39, 7e30, f32::INFINITY, f32::NEG_INFINITY, f32::NAN];

    fn point(i: usize) -> Vec3 {
        Vec3::new(VALUES[i % 10], VALUES[(i / 10) % 10], VALUES[(i * 7 + 3) % 10])
    }

    #[test]
    fn lanes_match_glam_vec3_bit_for_bit() {
        let corners = [Vec3::new(0.3, -1.7, 2.0), Vec3::new(-0.0, 1e-20, 5.5), Vec3::new(1e20, 0.1, -0.2)];
        for base in (0..1000).step_by(4) {
            let p = [0, 1, 2, 3].map(|k| point(base + k));
            let q = [0, 1, 2, 3].map(|k| point(base * 3 + k + 1));
            let (sp, sq) = (soa(p), soa(q));
            assert_eq!(aos(sp).map(bits), p.map(bits));
            let dots = dot3(sp, sq).to_array();
            let normal = aos(normalize_or3(sp, sq));
            let zero = aos(normalize_or_zero3(sp));
            let interpolated = aos(lerp3(corners, sp));
            for k in 0..4 {
                assert_eq!(lane(sp, k).to_array().map(f32::to_bits), bits(p[k]));
                assert_eq!(dots[k].to_bits(), p[k].dot(q[k]).to_bits(), "dot {:?} {:?}", p[k], q[k]);
                assert_eq!(bits(normal[k]), bits(p[k].normalize_or(q[k])), "normalize_or {:?} {:?}", p[k], q[k]);
                assert_eq!(bits(zero[k]), bits(p[k].normalize_or_zero()), "normalize_or_zero {:?}", p[k]);
                let b = p[k];
                let expect = corners[0] * b.x + corners[1] * b.y + corners[2] * b.z;
                assert_eq!(bits(interpolated[k]), bits(expect), "lerp at {b:?}");
            }
        }
    }
}
