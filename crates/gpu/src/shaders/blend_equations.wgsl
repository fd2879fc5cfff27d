// blend_equations.wgsl — eq. 4–6 of the blend (paper listing 10), the WGSL twin of
// hybrid_core::blend::{combine, blend_pixel}. Prepended to blend.wgsl and to fallback.wgsl (the
// see-through layer's texels are combined with their own reflection and refraction).

// Eq. 5/6 averaged: CM = OM·M + (1 − OM)(OR·R + (1 − OR)·C); CR = OR·R + (1 − OR)(OM·M + (1 − OM)·C).
fn combine(c: vec3<f32>, m: vec3<f32>, r: vec3<f32>, reflectivity: f32, transparency: f32) -> vec3<f32> {
    let om = reflectivity;
    let tr = transparency;
    let cm = om * m + (1.0 - om) * (tr * r + (1.0 - tr) * c);
    let cr = tr * r + (1.0 - tr) * (om * m + (1.0 - om) * c);
    return (cm + cr) * 0.5;
}

// Listing 10: `heurVal < 0.0001` means "not traced" (hybrid_core::blend::MASK_EPSILON): the
// lighting alone; else eq. 4, then eq. 5/6. `opt` is (reflectivity, IOR, opacity).
fn blend_pixel(l: vec3<f32>, s: vec3<f32>, m: vec3<f32>, r: vec3<f32>, opt: vec3<f32>, mask_value: f32) -> vec3<f32> {
    if mask_value < MASK_EPSILON {
        return l;
    }
    // Eq. 4: C = L − (1 − S).
    let c = l - (vec3<f32>(1.0) - s);
    return combine(c, m, r, opt.x, 1.0 - opt.z);
}
