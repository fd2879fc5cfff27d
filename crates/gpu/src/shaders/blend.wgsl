// Stage 4 (paper listing 10, eq. 4–6; design §3): lighting, shadow, reflection and refraction
// combined under the mask and the optical properties, then sRGB-encoded to 8 bits. The WGSL twin
// of hybrid_core::blend::{blend_pixel, encode_srgb}.

@group(0) @binding(0) var lighting: texture_2d<f32>;
@group(0) @binding(1) var shadow: texture_2d<f32>;
@group(0) @binding(2) var reflection: texture_2d<f32>;
@group(0) @binding(3) var refraction: texture_2d<f32>;
// Reflectivity (OM), IOR, opacity (OR = 1 − opacity).
@group(0) @binding(4) var optical: texture_2d<f32>;
@group(0) @binding(5) var mask: texture_2d<f32>;
@group(0) @binding(6) var final_image: texture_storage_2d<rgba8unorm, write>;

// combine and blend_pixel (eq. 4–6) are in blend_equations.wgsl, prepended.

fn srgb_encode(x: f32) -> f32 {
    let c = clamp(x, 0.0, 1.0);
    if c <= 0.0031308 {
        return c * 12.92;
    }
    return 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

// encode_srgb's byte: non-finite → 0, then trunc(srgb · 255 + 0.5). The shader rounds itself and
// stores byte / 255, which the Rgba8Unorm conversion maps back to exactly that byte.
fn encode_channel(v: f32) -> f32 {
    // NaN and ±inf by their exponent bits (comparisons with NaN may be optimised away).
    let finite = (bitcast<u32>(v) & 0x7f800000u) != 0x7f800000u;
    let s = srgb_encode(select(0.0, v, finite));
    return floor(s * 255.0 + 0.5) / 255.0;
}

@compute @workgroup_size(8, 8, 1)
fn blend(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(final_image);
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    let p = gid.xy;
    let c = blend_pixel(
        textureLoad(lighting, p, 0).xyz,
        textureLoad(shadow, p, 0).xyz,
        textureLoad(reflection, p, 0).xyz,
        textureLoad(refraction, p, 0).xyz,
        textureLoad(optical, p, 0).xyz,
        textureLoad(mask, p, 0).x,
    );
    textureStore(final_image, p, vec4<f32>(encode_channel(c.x), encode_channel(c.y), encode_channel(c.z), 1.0));
}

// With the raster fallbacks (issue 18; hybrid_core::blend::blend_pixel_with_fallback): a polygon
// pixel the trace stage left out (mask < MASK_EPSILON) takes the fallback terms through the same
// equations with mask 1. Only the pipeline of this entry point binds group 1.
@group(1) @binding(0) var object_id: texture_2d<u32>;
@group(1) @binding(1) var shadow_fallback: texture_2d<f32>;
@group(1) @binding(2) var reflection_fallback: texture_2d<f32>;
@group(1) @binding(3) var refraction_fallback: texture_2d<f32>;

@compute @workgroup_size(8, 8, 1)
fn blend_fallback(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(final_image);
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    let p = gid.xy;
    let id = textureLoad(object_id, p, 0).x;
    let mask_value = textureLoad(mask, p, 0).x;
    var c: vec3<f32>;
    if mask_value < MASK_EPSILON && id != NO_OBJECT && id != RT_SCENE_OBJECT {
        c = blend_pixel(
            textureLoad(lighting, p, 0).xyz,
            textureLoad(shadow_fallback, p, 0).xyz,
            textureLoad(reflection_fallback, p, 0).xyz,
            textureLoad(refraction_fallback, p, 0).xyz,
            textureLoad(optical, p, 0).xyz,
            1.0,
        );
    } else {
        c = blend_pixel(
            textureLoad(lighting, p, 0).xyz,
            textureLoad(shadow, p, 0).xyz,
            textureLoad(reflection, p, 0).xyz,
            textureLoad(refraction, p, 0).xyz,
            textureLoad(optical, p, 0).xyz,
            mask_value,
        );
    }
    textureStore(final_image, p, vec4<f32>(encode_channel(c.x), encode_channel(c.y), encode_channel(c.z), 1.0));
}
