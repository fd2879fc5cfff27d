//! `scene`: the prepared scene uploaded once (world-space vertices, triangles, meshes, Table 1
//! materials, every texture with its mips, lights) plus the per-frame uniforms. Every pass binds
//! the same group 0 (`SceneGpu::layout`), declared once in `shaders/common/*.wgsl`, so raster,
//! lighting and trace evaluate surfaces and lights with the same WGSL functions.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use hybrid_core::PreparedScene;
use hybrid_scene::{Camera, ColorSpace, Environment, Lights, Skybox};

use crate::context::{GpuContext, GpuError};

/// `struct Vertex` in common/*.wgsl: world-space attributes of one vertex (w components unused
/// unless noted). 80 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuVertex {
    pub position: [f32; 4],
    pub normal: [f32; 4],
    pub uv: [f32; 4],
    /// xyz tangent, w bitangent sign.
    pub tangent: [f32; 4],
    /// Linear vertex colour (rgb), white where the mesh has none.
    pub color: [f32; 4],
}

/// `struct Triangle`: global vertex indices and the mesh it belongs to.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuTriangle {
    pub v: [u32; 3],
    pub mesh: u32,
}

/// `MESH_HAS_NORMALS` etc.: which optional attributes a mesh has.
pub const MESH_HAS_NORMALS: u32 = 1;
pub const MESH_HAS_UVS: u32 = 2;
/// Tangents present and the material has a normal map.
pub const MESH_HAS_TANGENTS: u32 = 4;
pub const MESH_HAS_COLORS: u32 = 8;

/// `struct MeshInfo`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuMesh {
    pub object: u32,
    pub material: u32,
    pub flags: u32,
    pub first_triangle: u32,
}

/// `struct Material` (paper Table 1). Texture slots hold a texture index or −1.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuMaterial {
    pub emission: [f32; 4],
    pub ambient: [f32; 4],
    /// rgb diffuse, a opacity.
    pub diffuse: [f32; 4],
    /// rgb specular, a shininess (0..1).
    pub specular: [f32; 4],
    /// reflectivity, IOR, casts_shadows (0/1), textured (0/1: any map present).
    pub optical: [f32; 4],
    /// tiling.xy, offset.xy (`uv' = offset + uv * tiling`).
    pub uv_transform: [f32; 4],
    /// emission, ambient, diffuse, specular map.
    pub maps0: [i32; 4],
    /// normal map, optical map, unused, unused.
    pub maps1: [i32; 4],
}

pub const LIGHT_DIRECTIONAL: u32 = 0;
pub const LIGHT_POINT: u32 = 1;
pub const LIGHT_SPOT: u32 = 2;

/// `struct Light`, in the order directional, point, spot (listings 5 and 8a).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuLight {
    /// kind, casts_shadows (0/1), unused, unused.
    pub kind: [u32; 4],
    pub position: [f32; 4],
    /// Directional: direction *towards* the light. Spot: the direction the spot points.
    pub direction: [f32; 4],
    /// colour × intensity.
    pub power: [f32; 4],
    /// constant, linear, quadratic, unused.
    pub attenuation: [f32; 4],
    /// cos(inner), cos(outer), unused, unused.
    pub cone: [f32; 4],
}

pub const SKY_COLOR: u32 = 0;
pub const SKY_GRADIENT: u32 = 1;
pub const SKY_CUBE: u32 = 2;

/// `struct FrameUniforms`: the camera and environment of one frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct FrameUniforms {
    pub view_proj: [[f32; 4]; 4],
    pub inv_view_proj: [[f32; 4]; 4],
    /// xyz camera position, w = 1 for orthographic cameras.
    pub camera_position: [f32; 4],
    /// xyz unit forward (the view matrix's −Z), w unused.
    pub camera_forward: [f32; 4],
    /// xyz camera right × half the image width at distance 1 (perspective) or in world units
    /// (orthographic): the primary ray through NDC (x, y) is `forward + x·right + y·up`.
    pub camera_right: [f32; 4],
    /// xyz camera up × half the image height (as `camera_right`).
    pub camera_up: [f32; 4],
    /// width, height, 1/width, 1/height.
    pub size: [f32; 4],
    /// near, far, world size of one pixel at distance 1 (perspective) or of one pixel
    /// (orthographic), unused.
    pub near_far: [f32; 4],
    /// rgb ambient, w environment IOR.
    pub env_ambient: [f32; 4],
    /// Skybox colour (SKY_COLOR) or zenith (SKY_GRADIENT); w unused.
    pub sky_zenith: [f32; 4],
    pub sky_horizon: [f32; 4],
    pub sky_ground: [f32; 4],
    /// Cube faces +X, −X, +Y, −Y (texture indices).
    pub sky_faces0: [i32; 4],
    /// Cube faces +Z, −Z, sky kind, unused.
    pub sky_faces1: [i32; 4],
    /// light count, object count, triangle count, unused.
    pub counts: [u32; 4],
    /// The CPU capsule's ray generation (`hybrid_cpu::camera_rays::RayGen`), exactly: the view → world
    /// rotation's columns (the transpose of the view matrix's rotation; w unused), so the GPU
    /// capsule's rays and synthesized depths are bit-identical to the CPU's.
    pub raygen_rot: [[f32; 4]; 3],
    /// xyz the camera position exactly as given (not through an inverse matrix), w unused.
    pub raygen_eye: [f32; 4],
    /// The projection's x and y scales (P₀₀, P₁₁), near, far.
    pub raygen_proj: [f32; 4],
}

impl FrameUniforms {
    pub fn new(camera: &Camera, width: u32, height: u32, env: &Environment, light_count: u32, objects: u32, triangles: u32) -> Self {
        let aspect = width as f32 / height as f32;
        let vp = camera.view_projection(aspect);
        let (near, far) = camera.near_far();
        let pixel = match camera.projection {
            hybrid_scene::Projection::Perspective { fov_y_deg, .. } => 2.0 * (fov_y_deg.to_radians() * 0.5).tan() / height as f32,
            hybrid_scene::Projection::Orthographic { height: h, .. } => h / height as f32,
        };
        let inv_view = camera.view().inverse();
        let half_h = match camera.projection {
            hybrid_scene::Projection::Perspective { fov_y_deg, .. } => (fov_y_deg.to_radians() * 0.5).tan(),
            hybrid_scene::Projection::Orthographic { height: h, .. } => h * 0.5,
        };
        let (kind, zenith, horizon, ground, faces) = match &env.skybox {
            Skybox::Color(c) => (SKY_COLOR, *c, *c, *c, [-1; 6]),
            Skybox::Gradient { zenith, horizon, ground } => (SKY_GRADIENT, *zenith, *horizon, *ground, [-1; 6]),
            Skybox::Cube { faces } => (SKY_CUBE, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, faces.map(|f| f as i32)),
        };
        let v4 = |v: Vec3, w: f32| v.extend(w).to_array();
        let rot = glam::Mat3::from_mat4(camera.view()).transpose();
        let proj = camera.projection(aspect);
        Self {
            view_proj: vp.to_cols_array_2d(),
            inv_view_proj: vp.inverse().to_cols_array_2d(),
            camera_position: v4(inv_view.w_axis.truncate(), if camera.is_orthographic() { 1.0 } else { 0.0 }),
            camera_forward: v4(-inv_view.z_axis.truncate(), 0.0),
            camera_right: v4(inv_view.x_axis.truncate() * half_h * aspect, 0.0),
            camera_up: v4(inv_view.y_axis.truncate() * half_h, 0.0),
            size: [width as f32, height as f32, 1.0 / width as f32, 1.0 / height as f32],
            near_far: [near, far, pixel, 0.0],
            env_ambient: v4(env.ambient, env.ior),
            sky_zenith: v4(zenith, 0.0),
            sky_horizon: v4(horizon, 0.0),
            sky_ground: v4(ground, 0.0),
            sky_faces0: [faces[0], faces[1], faces[2], faces[3]],
            sky_faces1: [faces[4], faces[5], kind as i32, 0],
            counts: [light_count, objects, triangles, 0],
            raygen_rot: [v4(rot.x_axis, 0.0), v4(rot.y_axis, 0.0), v4(rot.z_axis, 0.0)],
            raygen_eye: v4(camera.position, 0.0),
            raygen_proj: [proj.x_axis.x, proj.y_axis.y, near, far],
        }
    }
}

/// The scene on the GPU: group 0 of every pass.
pub struct SceneGpu {
    pub layout: wgpu::BindGroupLayout,
    pub bind_group: wgpu::BindGroup,
    pub uniforms: wgpu::Buffer,
    pub vertices: wgpu::Buffer,
    pub triangles: wgpu::Buffer,
    pub meshes: wgpu::Buffer,
    pub materials: wgpu::Buffer,
    pub tex_dir: wgpu::Buffer,
    pub texels: [wgpu::Buffer; 2],
    pub lights: wgpu::Buffer,
    pub triangle_count: u32,
    pub vertex_count: u32,
    pub light_count: u32,
    pub object_count: u32,
    /// Host-side copies (the trace stage's BVH build reads them).
    pub host_triangles: Vec<GpuTriangle>,
    pub host_vertices: Vec<GpuVertex>,
}

/// Texels are packed RGBA8 (`unpack4x8unorm`, r in the low byte) in up to two pages (storage
/// buffers), each at most the device's binding limit.
const TEXEL_PAGES: usize = 2;

impl SceneGpu {
    pub fn new(ctx: &GpuContext, prepared: &PreparedScene) -> Result<Self, GpuError> {
        let scene = prepared.scene;
        let device = &ctx.device;

        // Vertices, triangles and meshes: every world mesh concatenated.
        let mut vertices = Vec::new();
        let mut triangles = Vec::with_capacity(prepared.triangles.len());
        let mut meshes = Vec::with_capacity(prepared.meshes.len());
        for (mi, m) in prepared.meshes.iter().enumerate() {
            let material = &scene.materials[m.material];
            let base = vertices.len() as u32;
            let has = |v: usize| v == m.positions.len() && v > 0;
            let mut flags = 0;
            if has(m.normals.len()) {
                flags |= MESH_HAS_NORMALS;
            }
            if has(m.uvs.len()) {
                flags |= MESH_HAS_UVS;
            }
            if has(m.tangents.len()) && material.normal_map.is_some() {
                flags |= MESH_HAS_TANGENTS;
            }
            if has(m.colors.len()) {
                flags |= MESH_HAS_COLORS;
            }
            for (i, p) in m.positions.iter().enumerate() {
                vertices.push(GpuVertex {
                    position: p.extend(1.0).to_array(),
                    normal: m.normals.get(i).map_or([0.0; 4], |n| n.extend(0.0).to_array()),
                    uv: m.uvs.get(i).map_or([0.0; 4], |u| [u.x, u.y, 0.0, 0.0]),
                    tangent: m.tangents.get(i).map_or([0.0; 4], |t| t.to_array()),
                    color: m.colors.get(i).map_or([1.0; 4], |c| c.extend(1.0).to_array()),
                });
            }
            meshes.push(GpuMesh { object: m.object, material: m.material as u32, flags, first_triangle: triangles.len() as u32 });
            triangles.extend(m.indices.iter().map(|t| GpuTriangle { v: t.map(|i| base + i), mesh: mi as u32 }));
        }

        let materials: Vec<GpuMaterial> = scene
            .materials
            .iter()
            .map(|m| {
                let map = |t: Option<usize>| t.map_or(-1, |t| t as i32);
                let textured =
                    [m.emission_map, m.ambient_map, m.diffuse_map, m.specular_map, m.normal_map, m.optical_map].iter().any(Option::is_some);
                GpuMaterial {
                    emission: m.emission.extend(0.0).to_array(),
                    ambient: m.ambient.extend(0.0).to_array(),
                    diffuse: m.diffuse.extend(m.opacity).to_array(),
                    specular: m.specular.extend(m.shininess).to_array(),
                    optical: [m.reflectivity, m.ior, f32::from(u8::from(m.casts_shadows)), f32::from(u8::from(textured))],
                    uv_transform: [m.tiling.x, m.tiling.y, m.offset.x, m.offset.y],
                    maps0: [map(m.emission_map), map(m.ambient_map), map(m.diffuse_map), map(m.specular_map)],
                    maps1: [map(m.normal_map), map(m.optical_map), 0, 0],
                }
            })
            .collect();

        // Textures: a directory (one header per texture, then one entry per mip level) and the
        // texels in pages.
        let limit = ctx.max_storage_binding() / 4; // in texels
        let mut pages: [Vec<u32>; TEXEL_PAGES] = Default::default();
        let level_count: usize = scene.textures.iter().map(|t| t.levels.len()).sum();
        let mut dir: Vec<[u32; 4]> = Vec::with_capacity(scene.textures.len() + level_count);
        let mut levels: Vec<[u32; 4]> = Vec::with_capacity(level_count);
        let first_level = scene.textures.len() as u32;
        for t in &scene.textures {
            dir.push([first_level + levels.len() as u32, t.levels.len() as u32, u32::from(t.color_space == ColorSpace::Srgb), 0]);
            for (i, l) in t.levels.iter().enumerate() {
                let n = l.texels.len() as u64;
                // Rejected, not downscaled: a smaller texture here would make the GPU image differ
                // from the CPU backend's, which reads the file's full resolution.
                let page = (0..TEXEL_PAGES).find(|&p| pages[p].len() as u64 + n <= limit).ok_or_else(|| GpuError::TooLarge {
                    adapter: ctx.summary.name.clone(),
                    why: format!(
                        "texture `{}` ({}x{}, mip level {i}: {} MiB) does not fit: the scene's textures need more than {TEXEL_PAGES} storage buffers of {} MiB",
                        t.name,
                        l.width,
                        l.height,
                        (n * 4) >> 20,
                        ctx.max_storage_binding() >> 20
                    ),
                })?;
                levels.push([pages[page].len() as u32, l.width, l.height, page as u32]);
                pages[page].extend(l.texels.iter().map(|&t| u32::from_le_bytes(t)));
            }
        }
        dir.extend(levels);

        let lights = gpu_lights(&scene.lights);
        let light_count = lights.len() as u32;

        let vertices_buf = ctx.storage_buffer("scene.vertices", bytemuck::cast_slice(&vertices))?;
        let triangles_buf = ctx.storage_buffer("scene.triangles", bytemuck::cast_slice(&triangles))?;
        let meshes_buf = ctx.storage_buffer("scene.meshes", bytemuck::cast_slice(&meshes))?;
        let materials_buf = ctx.storage_buffer("scene.materials", bytemuck::cast_slice(&materials))?;
        let dir_buf = ctx.storage_buffer("scene.tex_dir", bytemuck::cast_slice(&dir))?;
        let texels = [
            ctx.storage_buffer("scene.texels0", bytemuck::cast_slice(&pages[0]))?,
            ctx.storage_buffer("scene.texels1", bytemuck::cast_slice(&pages[1]))?,
        ];
        let lights_buf = ctx.storage_buffer("scene.lights", bytemuck::cast_slice(&lights))?;
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("scene.frame_uniforms"),
            size: std::mem::size_of::<FrameUniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });

        let layout = Self::create_layout(device);
        let buffers =
            [&uniforms, &vertices_buf, &triangles_buf, &meshes_buf, &materials_buf, &dir_buf, &texels[0], &texels[1], &lights_buf];
        let entries: Vec<wgpu::BindGroupEntry> =
            buffers.iter().enumerate().map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() }).collect();
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some("scene"), layout: &layout, entries: &entries });
        Ok(Self {
            layout,
            bind_group,
            uniforms,
            vertices: vertices_buf,
            triangles: triangles_buf,
            meshes: meshes_buf,
            materials: materials_buf,
            tex_dir: dir_buf,
            texels,
            lights: lights_buf,
            triangle_count: triangles.len() as u32,
            vertex_count: vertices.len() as u32,
            light_count,
            object_count: scene.objects.len() as u32,
            host_triangles: triangles,
            host_vertices: vertices,
        })
    }

    /// Group 0: binding 0 the frame uniforms, 1..=8 read-only storage (vertices, triangles,
    /// meshes, materials, texture directory, texel pages 0 and 1, lights). Visible to every stage.
    fn create_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
        let vis = wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT | wgpu::ShaderStages::COMPUTE;
        uniform_and_storage_layout(device, "scene", vis, 8)
    }

    /// Writes this frame's camera and environment (before the frame's passes are submitted).
    pub fn write_uniforms(&self, ctx: &GpuContext, camera: &Camera, width: u32, height: u32, env: &Environment) {
        let u = FrameUniforms::new(camera, width, height, env, self.light_count, self.object_count, self.triangle_count);
        ctx.queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&u));
    }
}

/// The scene's lights in the order directional, point, spot, with per-light constants folded.
pub fn gpu_lights(l: &Lights) -> Vec<GpuLight> {
    let v = |v: Vec3| v.extend(0.0).to_array();
    let mut out = Vec::with_capacity(l.count());
    for d in &l.directional {
        out.push(GpuLight {
            kind: [LIGHT_DIRECTIONAL, d.casts_shadows.into(), 0, 0],
            position: [0.0; 4],
            direction: v(-d.direction),
            power: v(d.color * d.intensity),
            attenuation: [1.0, 0.0, 0.0, 0.0],
            cone: [0.0; 4],
        });
    }
    for p in &l.point {
        out.push(GpuLight {
            kind: [LIGHT_POINT, p.casts_shadows.into(), 0, 0],
            position: v(p.position),
            direction: [0.0; 4],
            power: v(p.color * p.intensity),
            attenuation: [p.attenuation.constant, p.attenuation.linear, p.attenuation.quadratic, 0.0],
            cone: [0.0; 4],
        });
    }
    for s in &l.spot {
        out.push(GpuLight {
            kind: [LIGHT_SPOT, s.casts_shadows.into(), 0, 0],
            position: v(s.position),
            direction: v(s.direction),
            power: v(s.color * s.intensity),
            attenuation: [s.attenuation.constant, s.attenuation.linear, s.attenuation.quadratic, 0.0],
            cone: [s.inner_angle.cos(), s.outer_angle.cos(), 0.0, 0.0],
        });
    }
    out
}

/// A bind group layout of one uniform buffer (binding 0) followed by `storage` read-only storage
/// buffers (bindings 1..=storage), all visible to `visibility`: the scene's group 0 and the
/// spheres' group 2.
pub fn uniform_and_storage_layout(
    device: &wgpu::Device,
    label: &str,
    visibility: wgpu::ShaderStages,
    storage: u32,
) -> wgpu::BindGroupLayout {
    let entry = |binding: u32, ty: wgpu::BufferBindingType| wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None },
        count: None,
    };
    let entries: Vec<wgpu::BindGroupLayoutEntry> = std::iter::once(entry(0, wgpu::BufferBindingType::Uniform))
        .chain((1..=storage).map(|b| entry(b, wgpu::BufferBindingType::Storage { read_only: true })))
        .collect();
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries })
}
