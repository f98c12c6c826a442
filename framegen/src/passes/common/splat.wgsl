// The deterministic nearest-wins splat; see `splat.rs`.

struct SplatParams {
    count: u32,
    slots: u32,
    pad0: u32,
    pad1: u32,
};

@group(0) @binding(0) var<storage, read> sp: SplatParams;
@group(0) @binding(1) var<storage, read> candidates: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read_write> keys: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> winners: array<atomic<u32>>;

@compute @workgroup_size(256)
fn splat_key(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    if i >= sp.count {
        return;
    }
    let c = candidates[i];
    if c.x >= sp.slots {
        return;
    }
    atomicMax(&keys[c.x], c.y);
}

@compute @workgroup_size(256)
fn splat_index(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    if i >= sp.count {
        return;
    }
    let c = candidates[i];
    if c.x >= sp.slots {
        return;
    }
    if atomicLoad(&keys[c.x]) == c.y {
        atomicMax(&winners[c.x], ~i);
    }
}
