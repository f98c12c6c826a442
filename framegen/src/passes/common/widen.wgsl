// Widen the uploaded f16 colour to f32. See `widen.rs`.

struct WidenParams {
    sizes: vec4<u32>,
};

@group(0) @binding(0) var<storage, read> wp: WidenParams;
@group(0) @binding(1) var<storage, read> narrow: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read_write> color: array<vec4<f32>>;

@compute @workgroup_size(256)
fn widen(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    if t >= wp.sizes.x {
        return;
    }
    color[t] = half4_to_f32(narrow[t]);
}
