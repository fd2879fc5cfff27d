//! `targets`: the frame's GPU textures, one per buffer of design §2 (paper Table 2), made once
//! per frame size and reused frame after frame.

/// G-buffer target formats (design §2).
pub const POSITION_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
/// Normal, emission, ambient, diffuse+opacity, specular+shininess, optical, and the lighting,
/// shadow, reflection and refraction buffers.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
pub const OBJECT_ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
pub const MASK_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;
/// Reversed-Z: cleared to 0 (far), compare Greater.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// The final image: sRGB-encoded by the blend shader (as the CPU's `encode_srgb`), stored as
/// plain 8-bit so the bytes are exactly what the shader wrote.
pub const FINAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// The capsule's packed colour + depth frame (paper 2, block P).
pub const PACKED_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Uint;

/// The G-buffer's colour attachments in the order of the raster pass's `@location`s.
pub const GBUFFER_COLOR_FORMATS: [wgpu::TextureFormat; 8] = [
    POSITION_FORMAT,  // 0 position
    COLOR_FORMAT,     // 1 normal
    COLOR_FORMAT,     // 2 emission
    COLOR_FORMAT,     // 3 ambient
    COLOR_FORMAT,     // 4 diffuse (rgb) + opacity (a)
    COLOR_FORMAT,     // 5 specular (rgb) + shininess (a)
    COLOR_FORMAT,     // 6 optical: reflectivity, IOR, opacity
    OBJECT_ID_FORMAT, // 7 object id
];

/// Every format a frame target has (see [`FrameTargets::new`]).
pub const TARGET_FORMATS: [wgpu::TextureFormat; 7] =
    [POSITION_FORMAT, COLOR_FORMAT, OBJECT_ID_FORMAT, MASK_FORMAT, DEPTH_FORMAT, FINAL_FORMAT, PACKED_FORMAT];

/// The usages [`Target::new`] gives a texture of `format`.
pub fn target_usages(format: wgpu::TextureFormat) -> wgpu::TextureUsages {
    let mut usage = wgpu::TextureUsages::RENDER_ATTACHMENT
        | wgpu::TextureUsages::TEXTURE_BINDING
        | wgpu::TextureUsages::COPY_SRC
        | wgpu::TextureUsages::COPY_DST;
    if format != DEPTH_FORMAT {
        usage |= wgpu::TextureUsages::STORAGE_BINDING;
    }
    usage
}

/// One texture and its default view.
pub struct Target {
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
}

impl Target {
    pub fn new(device: &wgpu::Device, label: &str, width: u32, height: u32, format: wgpu::TextureFormat) -> Self {
        let usage = target_usages(format);
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        Self { texture, view }
    }
}

/// Every texture of one frame (design §2), for one size.
pub struct FrameTargets {
    pub width: u32,
    pub height: u32,
    pub position: Target,
    pub normal: Target,
    pub emission: Target,
    pub ambient: Target,
    pub diffuse: Target,
    pub specular: Target,
    pub optical: Target,
    pub object_id: Target,
    pub mask: Target,
    pub depth: Target,
    pub lighting: Target,
    pub shadow: Target,
    pub reflection: Target,
    pub refraction: Target,
    pub final_image: Target,
    /// The capsule's packed frame (written by its compute pass, read by the unpack pass).
    pub packed: Target,
}

impl FrameTargets {
    pub fn new(device: &wgpu::Device, width: u32, height: u32) -> Self {
        let t = |label: &str, format| Target::new(device, label, width, height, format);
        Self {
            width,
            height,
            position: t("gbuffer.position", POSITION_FORMAT),
            normal: t("gbuffer.normal", COLOR_FORMAT),
            emission: t("gbuffer.emission", COLOR_FORMAT),
            ambient: t("gbuffer.ambient", COLOR_FORMAT),
            diffuse: t("gbuffer.diffuse", COLOR_FORMAT),
            specular: t("gbuffer.specular", COLOR_FORMAT),
            optical: t("gbuffer.optical", COLOR_FORMAT),
            object_id: t("gbuffer.object_id", OBJECT_ID_FORMAT),
            mask: t("gbuffer.mask", MASK_FORMAT),
            depth: t("gbuffer.depth", DEPTH_FORMAT),
            lighting: t("lighting", COLOR_FORMAT),
            shadow: t("shadow", COLOR_FORMAT),
            reflection: t("reflection", COLOR_FORMAT),
            refraction: t("refraction", COLOR_FORMAT),
            final_image: t("final", FINAL_FORMAT),
            packed: t("rt_packed", PACKED_FORMAT),
        }
    }

    /// Targets for a layer that only the raster and lighting passes write (the fallbacks'
    /// see-through layer): the G-buffer, depth and lighting at `width` × `height`, the rest
    /// (mask, the trace outputs, final, packed) 1 × 1, unused.
    pub fn raster_layer(device: &wgpu::Device, width: u32, height: u32) -> Self {
        let full = |label: &str, format| Target::new(device, label, width, height, format);
        let unused = |label: &str, format| Target::new(device, label, 1, 1, format);
        Self {
            width,
            height,
            position: full("layer.position", POSITION_FORMAT),
            normal: full("layer.normal", COLOR_FORMAT),
            emission: full("layer.emission", COLOR_FORMAT),
            ambient: full("layer.ambient", COLOR_FORMAT),
            diffuse: full("layer.diffuse", COLOR_FORMAT),
            specular: full("layer.specular", COLOR_FORMAT),
            optical: full("layer.optical", COLOR_FORMAT),
            object_id: full("layer.object_id", OBJECT_ID_FORMAT),
            mask: unused("layer.mask (unused)", MASK_FORMAT),
            depth: full("layer.depth", DEPTH_FORMAT),
            lighting: full("layer.lighting", COLOR_FORMAT),
            shadow: unused("layer.shadow (unused)", COLOR_FORMAT),
            reflection: unused("layer.reflection (unused)", COLOR_FORMAT),
            refraction: unused("layer.refraction (unused)", COLOR_FORMAT),
            final_image: unused("layer.final (unused)", FINAL_FORMAT),
            packed: unused("layer.packed (unused)", PACKED_FORMAT),
        }
    }

    /// Every texture of the frame (destructured, so a new one cannot be left out): what
    /// `hybrid_core::memory::GPU_TARGET_BYTES_PER_PIXEL` counts (a test ties the two).
    pub fn all(&self) -> [&Target; 16] {
        let Self {
            width: _,
            height: _,
            position,
            normal,
            emission,
            ambient,
            diffuse,
            specular,
            optical,
            object_id,
            mask,
            depth,
            lighting,
            shadow,
            reflection,
            refraction,
            final_image,
            packed,
        } = self;
        [
            position,
            normal,
            emission,
            ambient,
            diffuse,
            specular,
            optical,
            object_id,
            mask,
            depth,
            lighting,
            shadow,
            reflection,
            refraction,
            final_image,
            packed,
        ]
    }

    /// The G-buffer's colour attachments in `GBUFFER_COLOR_FORMATS` order.
    pub fn gbuffer_color_views(&self) -> [&wgpu::TextureView; 8] {
        [
            &self.position.view,
            &self.normal.view,
            &self.emission.view,
            &self.ambient.view,
            &self.diffuse.view,
            &self.specular.view,
            &self.optical.view,
            &self.object_id.view,
        ]
    }
}

/// A render pipeline that writes the whole G-buffer: the 8 colour targets in
/// [`GBUFFER_COLOR_FORMATS`] order and reversed-Z depth (compare Greater, write on), no culling,
/// no vertex buffers. The raster, primary-ray and capsule-unpack passes all use it.
pub fn gbuffer_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    vertex_entry: &str,
    fragment_entry: &str,
) -> wgpu::RenderPipeline {
    let targets: Vec<Option<wgpu::ColorTargetState>> = GBUFFER_COLOR_FORMATS
        .iter()
        .map(|&format| Some(wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL }))
        .collect();
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        vertex: wgpu::VertexState { module, entry_point: Some(vertex_entry), compilation_options: Default::default(), buffers: &[] },
        primitive: wgpu::PrimitiveState { topology: wgpu::PrimitiveTopology::TriangleList, cull_mode: None, ..Default::default() },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(fragment_entry),
            compilation_options: Default::default(),
            targets: &targets,
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// Begins a render pass over the G-buffer's 8 colour targets and depth. `clear = true` clears
/// them first (object id to `NO_OBJECT` = u32::MAX, depth to 0 = far, the rest to 0);
/// `clear = false` loads what an earlier pass wrote (depth-testing against it).
pub fn begin_gbuffer_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    targets: &FrameTargets,
    clear: bool,
    label: &str,
    timestamp_writes: Option<wgpu::RenderPassTimestampWrites<'_>>,
) -> wgpu::RenderPass<'e> {
    let views = targets.gbuffer_color_views();
    let last = views.len() - 1;
    let attachments: Vec<Option<wgpu::RenderPassColorAttachment>> = views
        .iter()
        .enumerate()
        .map(|(i, view)| {
            // The object id target (the last) clears to NO_OBJECT (u32::MAX, exact in f64).
            let value = if i == last { wgpu::Color { r: f64::from(u32::MAX), g: 0.0, b: 0.0, a: 0.0 } } else { wgpu::Color::TRANSPARENT };
            let load = if clear { wgpu::LoadOp::Clear(value) } else { wgpu::LoadOp::Load };
            Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load, store: wgpu::StoreOp::Store },
            })
        })
        .collect();
    let depth_load = if clear { wgpu::LoadOp::Clear(0.0) } else { wgpu::LoadOp::Load };
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &attachments,
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: &targets.depth.view,
            depth_ops: Some(wgpu::Operations { load: depth_load, store: wgpu::StoreOp::Store }),
            stencil_ops: None,
        }),
        timestamp_writes,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}
