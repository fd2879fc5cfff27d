// lighting.wgsl — stage 1b, deferred lighting (listing 5; hybrid_cpu::lighting::deferred_lighting).
// common/*.wgsl is prepended. One invocation per pixel: the sky along the pixel's primary ray where
// no object was drawn, else emission + env_ambient · ambient + Σ lights Blinn–Phong (unshadowed).

@group(1) @binding(0) var g_position: texture_2d<f32>;
@group(1) @binding(1) var g_normal: texture_2d<f32>;
@group(1) @binding(2) var g_emission: texture_2d<f32>;
@group(1) @binding(3) var g_ambient: texture_2d<f32>;
@group(1) @binding(4) var g_diffuse: texture_2d<f32>;
@group(1) @binding(5) var g_specular: texture_2d<f32>;
@group(1) @binding(6) var g_object_id: texture_2d<u32>;
@group(1) @binding(7) var out_lighting: texture_storage_2d<rgba16float, write>;

@compute @workgroup_size(8, 8)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(out_lighting);
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    let px = vec2<i32>(gid.xy);
    var c: vec3<f32>;
    if textureLoad(g_object_id, px, 0).x == NO_OBJECT {
        c = sky(primary_ray(f32(gid.x) + 0.5, f32(gid.y) + 0.5).dir);
    } else {
        let d = textureLoad(g_diffuse, px, 0);
        let sp = textureLoad(g_specular, px, 0);
        // The fields lighting reads, as the CPU's `deferred_lighting` builds them.
        var s: Surface;
        s.position = textureLoad(g_position, px, 0).xyz;
        s.normal = textureLoad(g_normal, px, 0).xyz;
        s.emission = textureLoad(g_emission, px, 0).xyz;
        s.ambient = textureLoad(g_ambient, px, 0).xyz;
        s.diffuse = d.xyz;
        s.opacity = d.w;
        s.specular = sp.xyz;
        s.shininess = sp.w;
        s.reflectivity = 0.0;
        s.ior = 1.0;
        c = local_lighting(s, view_dir(s.position));
    }
    textureStore(out_lighting, px, vec4<f32>(c, 1.0));
}
