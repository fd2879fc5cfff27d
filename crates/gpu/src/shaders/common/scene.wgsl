// common/*.wgsl — prepended to every shader of the GPU backend (see `shaders.rs`).
// Group 0 is the scene (`scene.rs`, `SceneGpu`); the functions here are the WGSL twins of
// hybrid-core's shading (`shading.rs`) and hybrid-cpu's surface evaluation (`prepare.rs`), so the
// raster, lighting and trace passes all see and light surfaces exactly as the CPU backend does.

struct FrameUniforms {
    view_proj: mat4x4<f32>,
    inv_view_proj: mat4x4<f32>,
    camera_position: vec4<f32>, // w = 1: orthographic
    camera_forward: vec4<f32>,
    camera_right: vec4<f32>,    // × half width (at distance 1, or world units when orthographic)
    camera_up: vec4<f32>,       // × half height
    size: vec4<f32>,            // width, height, 1/width, 1/height
    near_far: vec4<f32>,        // near, far, pixel size at distance 1 (or world, orthographic), -
    env_ambient: vec4<f32>,     // rgb, w = environment IOR
    sky_zenith: vec4<f32>,
    sky_horizon: vec4<f32>,
    sky_ground: vec4<f32>,
    sky_faces0: vec4<i32>,
    sky_faces1: vec4<i32>,      // faces +Z, -Z, sky kind, -
    counts: vec4<u32>,          // lights, objects, triangles, -
    raygen_rot: array<vec4<f32>, 3>, // the CPU capsule's RayGen: view → world rotation columns
    raygen_eye: vec4<f32>,      // camera position exactly
    raygen_proj: vec4<f32>,     // P00, P11, near, far
}

struct Vertex {
    position: vec4<f32>,
    normal: vec4<f32>,
    uv: vec4<f32>,
    tangent: vec4<f32>,
    color: vec4<f32>,
}

struct Triangle {
    v0: u32,
    v1: u32,
    v2: u32,
    mesh: u32,
}

struct MeshInfo {
    object: u32,
    material: u32,
    flags: u32,
    first_triangle: u32,
}

struct Material {
    emission: vec4<f32>,
    ambient: vec4<f32>,
    diffuse: vec4<f32>,      // rgb, a = opacity
    specular: vec4<f32>,     // rgb, a = shininess
    optical: vec4<f32>,      // reflectivity, IOR, casts_shadows, textured
    uv_transform: vec4<f32>, // tiling.xy, offset.xy
    maps0: vec4<i32>,        // emission, ambient, diffuse, specular
    maps1: vec4<i32>,        // normal, optical, -, -
}

struct Light {
    kind: vec4<u32>,        // kind, casts_shadows, -, -
    position: vec4<f32>,
    direction: vec4<f32>,   // directional: towards the light; spot: where it points
    power: vec4<f32>,       // colour × intensity
    attenuation: vec4<f32>, // constant, linear, quadratic
    cone: vec4<f32>,        // cos inner, cos outer
}

@group(0) @binding(0) var<uniform> frame: FrameUniforms;
@group(0) @binding(1) var<storage, read> vertices: array<Vertex>;
@group(0) @binding(2) var<storage, read> triangles: array<Triangle>;
@group(0) @binding(3) var<storage, read> meshes: array<MeshInfo>;
@group(0) @binding(4) var<storage, read> materials: array<Material>;
// Texture directory: entry t (< texture count) = (first level entry, level count, sRGB, -);
// level entries = (texel offset, width, height, page).
@group(0) @binding(5) var<storage, read> tex_dir: array<vec4<u32>>;
@group(0) @binding(6) var<storage, read> texels0: array<u32>;
@group(0) @binding(7) var<storage, read> texels1: array<u32>;
@group(0) @binding(8) var<storage, read> lights: array<Light>;

/// What the G-buffer holds for one pixel (hybrid_core::Surface).
struct Surface {
    position: vec3<f32>,
    normal: vec3<f32>,
    emission: vec3<f32>,
    ambient: vec3<f32>,
    diffuse: vec3<f32>,
    opacity: f32,
    specular: vec3<f32>,
    shininess: f32,
    reflectivity: f32,
    ior: f32,
}

