// The background pass: every pixel no geometry covered. Depth is +inf (a
// direction, not a point), motion is the rotation-only reprojection of that
// direction into the previous frame, color is the sky or a flat color.

@vertex
fn vs_fullscreen(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let x = f32((i << 1u) & 2u) * 2.0 - 1.0;
    let y = f32(i & 2u) * 2.0 - 1.0;
    // z = 0 is the far plane in reversed Z: only uncovered pixels pass.
    return vec4<f32>(x, y, 0.0, 1.0);
}

fn sky(dir: vec3<f32>) -> vec3<f32> {
    if frame.flags.x == 0u {
        return frame.sky_flat.rgb;
    }
    let up = clamp(dir.y, 0.0, 1.0);
    var c = mix(frame.sky_horizon.rgb, frame.sky_zenith.rgb, sqrt(up));
    if dir.y < 0.0 {
        c = frame.sky_horizon.rgb * (1.0 + dir.y * 0.5);
    }
    if dot(dir, frame.sun_dir.xyz) > frame.sun.w {
        c = c + frame.sun.rgb;
    }
    return c;
}

@fragment
fn fs_background(@builtin(position) p: vec4<f32>) -> GBufferOut {
    let ndc = vec2<f32>(frame.ray.x + p.x * frame.ray.z, frame.ray.y - p.y * frame.ray.w);
    let ray_view = vec3<f32>(ndc.x * frame.tan_half.x, ndc.y * frame.tan_half.y, -1.0);
    let view_rot = mat3x3<f32>(frame.view_from_camrel[0].xyz, frame.view_from_camrel[1].xyz, frame.view_from_camrel[2].xyz);
    let dir = normalize(transpose(view_rot) * ray_view);
    var out: GBufferOut;
    out.color = vec4<f32>(sky(dir), 1.0);
    out.depth = bitcast<u32>(frame.tan_half.w);
    // w = 0: a point at infinity, which translation does not move.
    out.motion = bitcast<vec2<u32>>(prev_pixel(frame.prev_clip_from_camrel * vec4<f32>(dir, 0.0)) - p.xy);
    out.id = 0u;
    return out;
}
