// GFFE eq. 1: next positions (camera-relative). See `motion.rs`.

struct MotionParams {
    config: vec4<u32>,
    motion: vec4<f32>,
};

@group(0) @binding(0) var<storage, read> mp: MotionParams;
@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> track: array<u32>;
@group(0) @binding(3) var<storage, read_write> next: array<vec4<f32>>;

@compute @workgroup_size(256)
fn estimate(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let x = thread_index(wid, nwg, lid);
    let n = mp.config.x;
    if x >= n {
        return;
    }
    let k = mp.config.y;
    let word = track[x];
    let m = word >> 2u;
    let p0 = positions[x];
    var np = p0;
    if (word & 1u) == 1u && m > 0u && m < k && p0.w == W_POINT {
        let pm = positions[m * n + x];
        if pm.w == W_POINT {
            let velocity = (p0.xyz - pm.xyz) / f32(m);
            np = vec4<f32>(p0.xyz + velocity * mp.motion.x, W_POINT);
        }
    }
    next[x] = np;
}
