// Push-pull hole fill. See `pushpull.rs`.

struct PpTexel {
    a: vec4<f32>,
    b: vec4<f32>,
};

struct PpParams {
    dst: vec4<u32>,
    src: vec4<u32>,
};

@group(0) @binding(0) var<storage, read> pp: PpParams;
@group(0) @binding(1) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> out_depth: array<f32>;
@group(0) @binding(3) var<storage, read_write> out_motion: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read_write> out_mask: array<u32>;
@group(0) @binding(5) var<storage, read_write> pyramid: array<PpTexel>;

// Texel `t` of level 0, which is the output itself: weight 1 where written,
// 0 in a hole.
fn level0(t: u32) -> PpTexel {
    if out_mask[t] == EMPTY_MASK {
        return PpTexel(vec4<f32>(0.0), vec4<f32>(0.0));
    }
    let c = out_color[t];
    let m = out_motion[t];
    let d = out_depth[t];
    return PpTexel(vec4<f32>(c.xyz, 1.0), vec4<f32>(select(1.0 / d, 0.0, is_inf(d)), m, 0.0));
}

// Texel `i` of the level `pp.src` describes (`src.w == 1`: level 0).
fn child(i: u32) -> PpTexel {
    if pp.src.w == 1u {
        return level0(i);
    }
    return pyramid[pp.src.x + i];
}

@compute @workgroup_size(256)
fn pp_pull(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    let dw = pp.dst.y;
    if i >= dw * pp.dst.z {
        return;
    }
    let x = i % dw;
    let y = i / dw;
    var sum_w = 0.0;
    var sa = vec4<f32>(0.0);
    var sb = vec4<f32>(0.0);
    for (var dy = 0u; dy < 2u; dy++) {
        for (var dx = 0u; dx < 2u; dx++) {
            let cx = 2u * x + dx;
            let cy = 2u * y + dy;
            if cx < pp.src.y && cy < pp.src.z {
                let c = child(cy * pp.src.y + cx);
                let w = c.a.w;
                sum_w += w;
                sa += c.a * w;
                sb += c.b * w;
            }
        }
    }
    var t = PpTexel(vec4<f32>(0.0), vec4<f32>(0.0));
    if sum_w > 0.0 {
        let a = sa / sum_w;
        t = PpTexel(vec4<f32>(a.xyz, min(sum_w, 1.0)), sb / sum_w);
    }
    pyramid[pp.dst.x + i] = t;
}

fn at(x: f32, y: f32) -> PpTexel {
    let xi = min(u32(max(x, 0.0)), pp.src.y - 1u);
    let yi = min(u32(max(y, 0.0)), pp.src.z - 1u);
    return pyramid[pp.src.x + yi * pp.src.y + xi];
}

@compute @workgroup_size(256)
fn pp_push(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    let w = pp.dst.y;
    if i >= w * pp.dst.z {
        return;
    }
    let own = pyramid[pp.dst.x + i];
    let wgt = own.a.w;
    if wgt >= 1.0 {
        return;
    }
    let par = parent(i, w);
    let a = own.a * wgt + par.a * (1.0 - wgt);
    let b = own.b * wgt + par.b * (1.0 - wgt);
    pyramid[pp.dst.x + i] = PpTexel(vec4<f32>(a.xyz, wgt + (1.0 - wgt) * par.a.w), b);
}

struct Parent {
    a: vec4<f32>,
    b: vec4<f32>,
};

// The parent value of texel `i` of a `w`-wide level: the coarser level
// `pp.src` sampled at the texel's centre, each tap weighted by its own
// weight (see pushpull.rs).
fn parent(i: u32, w: u32) -> Parent {
    let p = vec2<f32>(f32(i % w) + 0.5, f32(i / w) + 0.5) * 0.5;
    let q = p - 0.5;
    let base = floor(q);
    let f = q - base;
    var taps = array<PpTexel, 4>(
        at(base.x, base.y),
        at(base.x + 1.0, base.y),
        at(base.x, base.y + 1.0),
        at(base.x + 1.0, base.y + 1.0),
    );
    var bws = array<f32, 4>((1.0 - f.x) * (1.0 - f.y), f.x * (1.0 - f.y), (1.0 - f.x) * f.y, f.x * f.y);
    var sw = 0.0;
    var sa = vec4<f32>(0.0);
    var sb = vec4<f32>(0.0);
    for (var j = 0; j < 4; j++) {
        let wt = bws[j] * taps[j].a.w;
        sw += wt;
        sa += taps[j].a * wt;
        sb += taps[j].b * wt;
    }
    var res = Parent(vec4<f32>(0.0), vec4<f32>(0.0));
    if sw > 0.0 {
        res = Parent(vec4<f32>((sa / sw).xyz, sw), sb / sw);
    }
    return res;
}

@compute @workgroup_size(256)
fn pp_resolve(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    if t >= pp.dst.y * pp.dst.z || out_mask[t] != EMPTY_MASK {
        return;
    }
    // Level 0's push: a hole (weight 0) takes its parent outright; without
    // a level 1 (`src.y == 0`) it stays empty and becomes black sky.
    var par = Parent(vec4<f32>(0.0), vec4<f32>(0.0));
    if pp.src.y > 0u {
        par = parent(t, pp.dst.y);
    }
    var color = vec3<f32>(0.0);
    var inv_depth = 0.0;
    var motion = vec2<f32>(0.0);
    if par.a.w > 0.0 {
        color = par.a.xyz;
        inv_depth = par.b.x;
        motion = par.b.yz;
    }
    out_color[t] = vec4<f32>(color, 1.0);
    if inv_depth > 0.0 {
        out_depth[t] = 1.0 / inv_depth;
    } else {
        out_depth[t] = inf_f32();
    }
    out_motion[t] = motion;
    out_mask[t] = FILLED_MASK;
}
