// ---- textures (hybrid_scene::Texture / hybrid_cpu::prepare::sample_texture) ----

fn texel(tex: u32, level: u32, x: u32, y: u32) -> vec4<f32> {
    let header = tex_dir[tex];
    let l = tex_dir[header.x + level];
    let i = l.x + y * l.y + x;
    var packed: u32;
    if l.w == 0u {
        packed = texels0[i];
    } else {
        packed = texels1[i];
    }
    let t = unpack4x8unorm(packed);
    if header.z == 1u {
        return vec4<f32>(srgb_to_linear(t.x), srgb_to_linear(t.y), srgb_to_linear(t.z), t.w);
    }
    return t;
}

/// Bilinear sample of one mip level, repeat addressing; uv (0,0) = top-left.
fn sample_bilinear(tex: u32, uv: vec2<f32>, level_in: u32) -> vec4<f32> {
    let header = tex_dir[tex];
    let level = min(level_in, header.y - 1u);
    let l = tex_dir[header.x + level];
    if !is_finite(uv.x) || !is_finite(uv.y) {
        return texel(tex, level, 0u, 0u);
    }
    let w = l.y;
    let h = l.z;
    let x = (uv.x - floor(uv.x)) * f32(w) - 0.5;
    let y = (uv.y - floor(uv.y)) * f32(h) - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let xi = i32(x0);
    let yi = i32(y0);
    var ix0 = min(u32(max(xi, 0)), w - 1u);
    if xi < 0 { ix0 = w - 1u; }
    var iy0 = min(u32(max(yi, 0)), h - 1u);
    if yi < 0 { iy0 = h - 1u; }
    var ix1 = u32(max(xi + 1, 0));
    if xi + 1 >= i32(w) { ix1 = 0u; }
    var iy1 = u32(max(yi + 1, 0));
    if yi + 1 >= i32(h) { iy1 = 0u; }
    let a = mix(texel(tex, level, ix0, iy0), texel(tex, level, ix1, iy0), fx);
    let b = mix(texel(tex, level, ix0, iy1), texel(tex, level, ix1, iy1), fx);
    return mix(a, b, fy);
}

/// Trilinear sample for a UV footprint (UV units per pixel), as the CPU's `sample_texture`.
fn sample_texture(tex: u32, uv: vec2<f32>, footprint: f32) -> vec4<f32> {
    let header = tex_dir[tex];
    let base = tex_dir[header.x];
    let texels = footprint * f32(max(base.y, base.z));
    var lod = 0.0;
    if texels > 1.0 {
        lod = log2(texels);
    }
    let max_lod = f32(header.y - 1u);
    if is_finite(lod) {
        lod = clamp(lod, 0.0, max_lod);
    } else {
        lod = 0.0;
    }
    let l0 = floor(lod);
    let f = lod - l0;
    let a = sample_bilinear(tex, uv, u32(l0));
    if f <= 1e-4 {
        return a;
    }
    return mix(a, sample_bilinear(tex, uv, u32(l0) + 1u), f);
}

fn sample_map(map: i32, uv: vec2<f32>, footprint: f32) -> vec4<f32> {
    if map < 0 {
        return vec4<f32>(1.0);
    }
    return sample_texture(u32(map), uv, footprint);
}

