//! `readback`: GPU textures copied back into the CPU backend's buffer types (`GBuffer`,
//! `FrameBuffers`, `PackedRtFrame`), so dumps, reports and tests see both backends the same way.

use glam::{Vec3, Vec4};
use hybrid_core::depth_merge::PackedRtFrame;
use hybrid_core::{FrameBuffers, GBuffer};

use crate::context::{GpuContext, GpuError};
use crate::targets::{FrameTargets, Target};

/// The texture's texels, rows tightly packed (row 0 at the top), as raw bytes.
pub fn read_texture_bytes(ctx: &GpuContext, texture: &wgpu::Texture) -> Result<Vec<u8>, GpuError> {
    read_texture_layer_bytes(ctx, texture, 0)
}

/// As [`read_texture_bytes`], array layer `layer` of the texture.
pub fn read_texture_layer_bytes(ctx: &GpuContext, texture: &wgpu::Texture, layer: u32) -> Result<Vec<u8>, GpuError> {
    let (w, h) = (texture.width(), texture.height());
    let format = texture.format();
    let aspect = if format.is_depth_stencil_format() { wgpu::TextureAspect::DepthOnly } else { wgpu::TextureAspect::All };
    let texel = format.block_copy_size(Some(aspect)).ok_or_else(|| GpuError::Device(format!("cannot read back {format:?}")))?;
    let row = w * texel;
    let padded = row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: padded as u64 * h as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo { texture, mip_level: 0, origin: wgpu::Origin3d { x: 0, y: 0, z: layer }, aspect },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(padded), rows_per_image: Some(h) },
        },
        wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
    );
    ctx.queue.submit([encoder.finish()]);
    read_buffer_padded(ctx, &buffer, row as usize, padded as usize, h as usize)
}

/// Maps `buffer` (MAP_READ), waits, and returns its bytes with each row's padding removed.
fn read_buffer_padded(ctx: &GpuContext, buffer: &wgpu::Buffer, row: usize, padded: usize, rows: usize) -> Result<Vec<u8>, GpuError> {
    let bytes = read_buffer(ctx, buffer)?;
    let mut out = Vec::with_capacity(row * rows);
    for r in 0..rows {
        out.extend_from_slice(&bytes[r * padded..r * padded + row]);
    }
    Ok(out)
}

/// Maps a whole MAP_READ buffer, waits for the GPU, and copies its bytes out.
pub fn read_buffer(ctx: &GpuContext, buffer: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
    let slice = buffer.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    ctx.wait()?;
    rx.recv().map_err(|e| GpuError::Device(e.to_string()))?.map_err(|e| GpuError::Device(e.to_string()))?;
    let bytes = slice.get_mapped_range().map_err(|e| GpuError::Device(format!("{e:?}")))?.to_vec();
    buffer.unmap();
    Ok(bytes)
}

/// Rgba32Float or Rgba16Float texels as f32 RGBA.
pub fn read_rgba_f32(ctx: &GpuContext, t: &Target) -> Result<Vec<Vec4>, GpuError> {
    let bytes = read_texture_bytes(ctx, &t.texture)?;
    Ok(match t.texture.format() {
        wgpu::TextureFormat::Rgba32Float => bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(&bytes).into_iter().map(Vec4::from).collect(),
        wgpu::TextureFormat::Rgba16Float => {
            bytemuck::pod_collect_to_vec::<u8, [half::f16; 4]>(&bytes).into_iter().map(|h| Vec4::from(h.map(half::f16::to_f32))).collect()
        }
        f => return Err(GpuError::Device(format!("read_rgba_f32: unexpected format {f:?}"))),
    })
}

/// R32Float or Depth32Float texels.
pub fn read_f32(ctx: &GpuContext, t: &Target) -> Result<Vec<f32>, GpuError> {
    Ok(bytemuck::pod_collect_to_vec(&read_texture_bytes(ctx, &t.texture)?))
}

/// R32Uint texels.
pub fn read_u32(ctx: &GpuContext, t: &Target) -> Result<Vec<u32>, GpuError> {
    Ok(bytemuck::pod_collect_to_vec(&read_texture_bytes(ctx, &t.texture)?))
}

/// Rgba8Unorm texels as bytes.
pub fn read_rgba8(ctx: &GpuContext, t: &Target) -> Result<Vec<[u8; 4]>, GpuError> {
    Ok(bytemuck::pod_collect_to_vec(&read_texture_bytes(ctx, &t.texture)?))
}

/// Rgba16Uint texels.
pub fn read_rgba16u(ctx: &GpuContext, t: &Target) -> Result<Vec<[u16; 4]>, GpuError> {
    Ok(bytemuck::pod_collect_to_vec(&read_texture_bytes(ctx, &t.texture)?))
}

fn rgb(v: Vec<Vec4>) -> Vec<Vec3> {
    v.into_iter().map(Vec4::truncate).collect()
}

/// The whole G-buffer (design §2) as the CPU backend's type.
pub fn read_gbuffer(ctx: &GpuContext, t: &FrameTargets) -> Result<GBuffer, GpuError> {
    Ok(GBuffer {
        width: t.width,
        height: t.height,
        position: rgb(read_rgba_f32(ctx, &t.position)?),
        normal: rgb(read_rgba_f32(ctx, &t.normal)?),
        emission: rgb(read_rgba_f32(ctx, &t.emission)?),
        ambient: rgb(read_rgba_f32(ctx, &t.ambient)?),
        diffuse: read_rgba_f32(ctx, &t.diffuse)?,
        specular: read_rgba_f32(ctx, &t.specular)?,
        optical: rgb(read_rgba_f32(ctx, &t.optical)?),
        object_id: read_u32(ctx, &t.object_id)?,
        mask: read_f32(ctx, &t.mask)?,
        depth: read_f32(ctx, &t.depth)?,
    })
}

/// Lighting, shadow, reflection, refraction and the final image.
pub fn read_frame_buffers(ctx: &GpuContext, t: &FrameTargets) -> Result<FrameBuffers, GpuError> {
    Ok(FrameBuffers {
        width: t.width,
        height: t.height,
        lighting: rgb(read_rgba_f32(ctx, &t.lighting)?),
        shadow: rgb(read_rgba_f32(ctx, &t.shadow)?),
        reflection: rgb(read_rgba_f32(ctx, &t.reflection)?),
        refraction: rgb(read_rgba_f32(ctx, &t.refraction)?),
        shadow_fallback: Vec::new(),
        reflection_fallback: Vec::new(),
        refraction_fallback: Vec::new(),
        final_srgb: read_rgba8(ctx, &t.final_image)?,
    })
}

/// The three fallback targets (shadow, reflection, refraction) of stage 3b.
pub fn read_fallback(ctx: &GpuContext, t: &[Target; 3]) -> Result<[Vec<Vec3>; 3], GpuError> {
    Ok([rgb(read_rgba_f32(ctx, &t[0])?), rgb(read_rgba_f32(ctx, &t[1])?), rgb(read_rgba_f32(ctx, &t[2])?)])
}

/// The capsule's packed RGBA16UI frame.
pub fn read_packed(ctx: &GpuContext, t: &FrameTargets) -> Result<PackedRtFrame, GpuError> {
    let mut packed = PackedRtFrame::new(t.width, t.height);
    let texels = read_rgba16u(ctx, &t.packed)?;
    if texels.len() != packed.texels.len() {
        return Err(GpuError::Device("packed frame size mismatch".into()));
    }
    packed.texels = texels;
    Ok(packed)
}

// ---- the other way: CPU buffers written into the GPU targets (tests drive one stage with the
// CPU backend's inputs, so each stage is compared on its own) ----

/// Writes raw texel bytes (rows tightly packed) into a whole texture.
pub fn write_texture_bytes(ctx: &GpuContext, t: &Target, bytes: &[u8]) {
    let texel = t.texture.format().block_copy_size(None).expect("colour format");
    ctx.queue.write_texture(
        t.texture.as_image_copy(),
        bytes,
        wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(t.texture.width() * texel), rows_per_image: Some(t.texture.height()) },
        t.texture.size(),
    );
}

/// Writes RGBA values into an Rgba32Float or Rgba16Float target.
pub fn write_rgba_f32(ctx: &GpuContext, t: &Target, values: &[Vec4]) {
    match t.texture.format() {
        wgpu::TextureFormat::Rgba32Float => write_texture_bytes(ctx, t, bytemuck::cast_slice(values)),
        _ => {
            let halfs: Vec<[half::f16; 4]> = values.iter().map(|v| v.to_array().map(half::f16::from_f32)).collect();
            write_texture_bytes(ctx, t, bytemuck::cast_slice(&halfs));
        }
    }
}

/// Writes RGB values (alpha 1) into an Rgba32Float or Rgba16Float target.
pub fn write_rgb(ctx: &GpuContext, t: &Target, values: &[Vec3]) {
    let v: Vec<Vec4> = values.iter().map(|c| c.extend(1.0)).collect();
    write_rgba_f32(ctx, t, &v);
}

/// Writes every G-buffer target but depth (Depth32Float cannot be a copy destination), the
/// object ids and the mask included.
pub fn write_gbuffer(ctx: &GpuContext, t: &FrameTargets, g: &GBuffer) {
    write_rgb(ctx, &t.position, &g.position);
    write_rgb(ctx, &t.normal, &g.normal);
    write_rgb(ctx, &t.emission, &g.emission);
    write_rgb(ctx, &t.ambient, &g.ambient);
    write_rgba_f32(ctx, &t.diffuse, &g.diffuse);
    write_rgba_f32(ctx, &t.specular, &g.specular);
    write_rgb(ctx, &t.optical, &g.optical);
    write_texture_bytes(ctx, &t.object_id, bytemuck::cast_slice(&g.object_id));
    write_texture_bytes(ctx, &t.mask, bytemuck::cast_slice(&g.mask));
}

/// Writes lighting, shadow, reflection and refraction (not the final image).
pub fn write_frame_buffers(ctx: &GpuContext, t: &FrameTargets, b: &FrameBuffers) {
    write_rgb(ctx, &t.lighting, &b.lighting);
    write_rgb(ctx, &t.shadow, &b.shadow);
    write_rgb(ctx, &t.reflection, &b.reflection);
    write_rgb(ctx, &t.refraction, &b.refraction);
}
