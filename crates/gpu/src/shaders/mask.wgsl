// Stage 2, last pass (design §2, §4): the heuristic mask from the object-id target. The WGSL twin
// of hybrid_heuristic::write_mask (mode OBJECTS) and of the CPU frame's rt-only rule (mode
// ALL_COVERED: every pixel with an id, the RT-scene's included); mode NOTHING (raster) clears it.

const MODE_OBJECTS: u32 = 0u;
const MODE_ALL_COVERED: u32 = 1u;

struct MaskParams {
    mode: u32,
    // Length of `selected`; ids at or beyond it get 0 (sky and RT-scene included).
    object_count: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var object_id: texture_2d<u32>;
// One flag per object: non-zero = selected.
@group(0) @binding(1) var<storage, read> selected: array<u32>;
@group(0) @binding(2) var<uniform> params: MaskParams;
@group(0) @binding(3) var mask: texture_storage_2d<r32float, write>;

@compute @workgroup_size(8, 8, 1)
fn write_mask(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(object_id);
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    let p = gid.xy;
    let id = textureLoad(object_id, p, 0).x;
    var on = false;
    if params.mode == MODE_OBJECTS {
        on = id < params.object_count && selected[id] != 0u;
    } else if params.mode == MODE_ALL_COVERED {
        on = id != NO_OBJECT;
    }
    textureStore(mask, p, vec4<f32>(select(0.0, 1.0, on), 0.0, 0.0, 1.0));
}
