//! `present`: draws a frame texture (8-bit RGBA holding sRGB-encoded bytes, as the renderers
//! write their final image) into the window's swapchain image with one full-screen triangle.
//! The texture is read with `textureLoad` at the pixel under each window pixel, so a CPU frame
//! rendered at reduced resolution is shown scaled up (nearest) without resampling state.
//!
//! The overlay's object table highlights one object: the blit reads the frame's object ids
//! (an `R32Uint` texture: the GPU renderer's own target, or the CPU frame's ids uploaded) and
//! tints that object's pixels, with a bright outline where the id changes.

/// The blit pass: one pipeline per swapchain format, a bind group per source texture.
pub struct Blit {
    pipeline: wgpu::RenderPipeline,
    /// The same with the highlight (`fs_highlight`).
    highlight_pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    /// The swapchain format encodes sRGB itself, so the frame's bytes are decoded first.
    decode_srgb: bool,
    /// The pass's parameters, rewritten each frame (`write_buffer`).
    params: wgpu::Buffer,
    /// Bound in place of object ids when nothing is highlighted.
    no_ids: Upload,
    /// The last bind group and the views it binds: frames that show the same textures reuse it
    /// (a new bind group per frame grew lavapipe's memory by ~0.6 MB a frame).
    bound: Option<(wgpu::TextureView, wgpu::TextureView, wgpu::BindGroup)>,
}

const SHADER: &str = r#"
@group(0) @binding(0) var src: texture_2d<f32>;
struct Params {
    // Window size in pixels.
    size: vec2<f32>,
    // 1 when the swapchain encodes sRGB itself (decode first).
    decode: u32,
    // `fs_highlight`: the object to tint.
    highlight: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    _pad3: u32,
};
@group(0) @binding(1) var<uniform> params: Params;
@group(0) @binding(2) var ids: texture_2d<u32>;

@vertex
fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let p = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(p * 2.0 - 1.0, 0.0, 1.0);
}

fn decode(c: f32) -> f32 {
    if c <= 0.04045 { return c / 12.92; }
    return pow((c + 0.055) / 1.055, 2.4);
}

fn id_at(p: vec2<f32>) -> u32 {
    let size = vec2<f32>(textureDimensions(ids));
    let texel = min(vec2<u32>(floor(clamp(p, vec2<f32>(0.0), params.size - 1.0) * size / params.size)), vec2<u32>(size) - 1u);
    return textureLoad(ids, texel, 0).r;
}

fn shown(frag: vec4<f32>) -> vec3<f32> {
    let size = vec2<f32>(textureDimensions(src));
    let texel = min(vec2<u32>(floor(frag.xy * size / params.size)), vec2<u32>(size) - 1u);
    return textureLoad(src, texel, 0).rgb;
}

fn out(c: vec3<f32>) -> vec4<f32> {
    if params.decode == 1u {
        return vec4<f32>(decode(c.r), decode(c.g), decode(c.b), 1.0);
    }
    return vec4<f32>(c, 1.0);
}

@fragment
fn fs(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    return out(shown(frag));
}

// The frame with the object `params.highlight` tinted and outlined. A pipeline of its own: with
// this code in the plain blit, lavapipe's memory grew by ~0.5 MB every frame.
@fragment
fn fs_highlight(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    var c = shown(frag);
    let h = params.highlight;
    let inside = id_at(frag.xy) == h;
    // The outline: a pixel of the object with a neighbour 2 window pixels away that is not.
    let ring = vec4<u32>(
        id_at(frag.xy + vec2<f32>(2.0, 0.0)),
        id_at(frag.xy - vec2<f32>(2.0, 0.0)),
        id_at(frag.xy + vec2<f32>(0.0, 2.0)),
        id_at(frag.xy - vec2<f32>(0.0, 2.0)),
    );
    let edge = inside & any(ring != vec4<u32>(h));
    if edge {
        c = vec3<f32>(1.0, 0.85, 0.1);
    } else if inside {
        c = mix(c, vec3<f32>(1.0, 0.6, 0.0), 0.35);
    }
    return out(c);
}
"#;

impl Blit {
    pub fn new(device: &wgpu::Device, target_format: wgpu::TextureFormat) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("view.blit"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view.blit"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
            ],
        });
        let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("view.blit"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline_for = |entry: &str| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("view.blit"),
                layout: Some(&pl),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState { format: target_format, blend: None, write_mask: wgpu::ColorWrites::ALL })],
                }),
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: None,
                multisample: wgpu::MultisampleState::default(),
                multiview_mask: None,
                cache: None,
            })
        };
        let pipeline = pipeline_for("fs");
        let highlight_pipeline = pipeline_for("fs_highlight");
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("view.blit.params"),
            size: 32,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let no_ids = Upload::new(device, (1, 1), wgpu::TextureFormat::R32Uint);
        Self { pipeline, highlight_pipeline, layout, decode_srgb: target_format.is_srgb(), params, no_ids, bound: None }
    }

    /// Records the draw of `src` over the whole of `target` (a view and its size in pixels); with
    /// `highlight` = (object ids of the frame, id), that object's pixels are tinted and outlined.
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        enc: &mut wgpu::CommandEncoder,
        src: &wgpu::TextureView,
        highlight: Option<(&wgpu::TextureView, u32)>,
        (target, target_size): (&wgpu::TextureView, (u32, u32)),
    ) {
        let (ids, id) = match highlight {
            Some((view, id)) => (view, Some(id)),
            None => (&self.no_ids.view, None),
        };
        let mut params = [0u32; 8];
        params[0] = (target_size.0 as f32).to_bits();
        params[1] = (target_size.1 as f32).to_bits();
        params[2] = self.decode_srgb as u32;
        params[3] = id.unwrap_or(0);
        let bytes: Vec<u8> = params.iter().flat_map(|v| v.to_le_bytes()).collect();
        queue.write_buffer(&self.params, 0, &bytes);
        let reuse = self.bound.as_ref().is_some_and(|(s, i, _)| s == src && i == ids);
        if !reuse {
            let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("view.blit"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(src) },
                    wgpu::BindGroupEntry { binding: 1, resource: self.params.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(ids) },
                ],
            });
            self.bound = Some((src.clone(), ids.clone(), bind));
        }
        let Some((_, _, bind)) = &self.bound else { return };
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("view.blit"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::BLACK), store: wgpu::StoreOp::Store },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(if id.is_some() { &self.highlight_pipeline } else { &self.pipeline });
        pass.set_bind_group(0, bind, &[]);
        pass.draw(0..3, 0..1);
    }
}

/// A texture frames from the host are uploaded into (the CPU backend's image, a buffer view,
/// object ids), re-made only when its size changes: `Rgba8Unorm` (sRGB-encoded bytes) or
/// `R32Uint` (ids).
pub struct Upload {
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    pub size: (u32, u32),
    format: wgpu::TextureFormat,
}

impl Upload {
    pub fn new(device: &wgpu::Device, size: (u32, u32), format: wgpu::TextureFormat) -> Self {
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("view.cpu_frame"),
            size: wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        Self { texture, view, size, format }
    }

    /// Keeps `slot` an upload of `size` and `format` (re-made when either changed) and writes
    /// `bytes` (`size.0 * size.1 * 4`) into it.
    pub fn refresh<'a>(
        slot: &'a mut Option<Upload>,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        size: (u32, u32),
        format: wgpu::TextureFormat,
        bytes: &[u8],
    ) -> &'a Upload {
        if slot.as_ref().is_none_or(|u| u.size != size || u.format != format) {
            *slot = Some(Upload::new(device, size, format));
        }
        let u = slot.get_or_insert_with(|| Upload::new(device, size, format));
        u.write(queue, bytes);
        u
    }

    /// Uploads `bytes` (`size.0 * size.1 * 4`: RGBA8 or one u32 per pixel).
    pub fn write(&self, queue: &wgpu::Queue, rgba: &[u8]) {
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            rgba,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(self.size.0 * 4), rows_per_image: Some(self.size.1) },
            wgpu::Extent3d { width: self.size.0, height: self.size.1, depth_or_array_layers: 1 },
        );
    }
}
