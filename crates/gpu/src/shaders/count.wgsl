// Stage 2, first pass (design §4, paper Table 3): A = the number of pixels each object covers,
// for every object in one pass over the object-id target. The WGSL twin of
// hybrid_heuristic::count_visible_pixels: ids >= object_count (sky = NO_OBJECT, the RT-scene =
// RT_SCENE_OBJECT, anything stale) are not counted.
//
// Each invocation walks SPAN consecutive pixels of one row and adds each run of equal ids once
// (rasterised images are long horizontal runs), so the atomics are few and rarely contended.

struct CountParams {
    object_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var object_id: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> counts: array<atomic<u32>>;
@group(0) @binding(2) var<uniform> params: CountParams;

// Pixels per invocation (one row segment).

fn add_run(id: u32, length: u32) {
    if id < params.object_count {
        atomicAdd(&counts[id], length);
    }
}

@compute @workgroup_size(64, 1, 1)
fn count_pixels(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(object_id);
    let y = gid.y;
    let x0 = gid.x * SPAN;
    if y >= size.y || x0 >= size.x {
        return;
    }
    let x1 = min(x0 + SPAN, size.x);
    var run_id = textureLoad(object_id, vec2<u32>(x0, y), 0).x;
    var run_length = 1u;
    for (var x = x0 + 1u; x < x1; x++) {
        let id = textureLoad(object_id, vec2<u32>(x, y), 0).x;
        if id == run_id {
            run_length += 1u;
        } else {
            add_run(run_id, run_length);
            run_id = id;
            run_length = 1u;
        }
    }
    add_run(run_id, run_length);
}
