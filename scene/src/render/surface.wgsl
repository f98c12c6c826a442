// Geometry shading shared by the opaque and translucent passes: vertex
// transform with previous-frame position, procedural textures, lights,
// optional specular and shadow map.

@group(2) @binding(0) var shadow_map: texture_depth_2d;
@group(2) @binding(1) var shadow_sampler: sampler_comparison;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) camrel: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) prev_clip: vec4<f32>,
    @location(4) view_depth: f32,
};

@vertex
fn vs_surface(v: VertexIn) -> VsOut {
    var out: VsOut;
    let camrel = object.model * vec4<f32>(v.position, 1.0);
    let view = frame.view_from_camrel * camrel;
    out.clip = frame.clip_from_view * view;
    out.camrel = camrel.xyz;
    out.normal = (object.normal_m * vec4<f32>(v.normal, 0.0)).xyz;
    out.uv = v.uv;
    out.prev_clip = frame.prev_clip_from_camrel * (object.prev_model * vec4<f32>(v.position, 1.0));
    out.view_depth = -view.z;
    return out;
}

fn hash2(p: vec2<f32>) -> f32 {
    return fract(sin(dot(p, vec2<f32>(127.1, 311.7))) * 43758.5453);
}

fn value_noise(p: vec2<f32>) -> f32 {
    let i = floor(p);
    let f = fract(p);
    let u = f * f * (3.0 - 2.0 * f);
    let a = hash2(i);
    let b = hash2(i + vec2<f32>(1.0, 0.0));
    let c = hash2(i + vec2<f32>(0.0, 1.0));
    let d = hash2(i + vec2<f32>(1.0, 1.0));
    return mix(mix(a, b, u.x), mix(c, d, u.x), u.y);
}

// Albedo multiplier of the procedural texture at `uv`.
fn pattern(uv: vec2<f32>, tex: vec4<f32>) -> f32 {
    let kind = u32(tex.x);
    let p = uv * tex.y;
    switch kind {
        case 1u: {
            let q = floor(p);
            let odd = abs(q.x + q.y) % 2.0;
            return select(1.0, 1.0 - tex.z, odd > 0.5);
        }
        case 2u: {
            return 1.0 - tex.z * (0.5 + 0.5 * sin(p.x * 2.0 * PI));
        }
        case 3u: {
            let n = 0.6 * value_noise(p) + 0.4 * value_noise(p * 4.0);
            return 1.0 - tex.z * n;
        }
        case 4u: {
            let f = fract(p);
            let line = f.x < tex.z || f.y < tex.z;
            return select(1.0, 0.15, line);
        }
        default: {
            return 1.0;
        }
    }
}

// Fraction of light reaching `camrel` from the shadow-map light, 3×3 PCF.
// The receiver's biases (a normal offset and a depth offset) were set for
// the largest map (SHADOW_MAP_MAX², from Rust) and grow with the texel: a
// coarser map's texel spans more
// depth on a slope, and fixed biases let the surface shadow itself in
// bands (acne).
fn shadow(camrel: vec3<f32>, n: vec3<f32>) -> f32 {
    let texels = vec2<f32>(textureDimensions(shadow_map));
    let coarse = SHADOW_MAP_MAX / texels.x;
    let c = frame.shadow_from_camrel * vec4<f32>(camrel + n * (0.02 * coarse), 1.0);
    if c.w <= 0.0 {
        return 1.0;
    }
    let ndc = c.xyz / c.w;
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    if any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) || ndc.z > 1.0 {
        return 1.0;
    }
    let texel = 1.0 / texels;
    var sum = 0.0;
    for (var y = -1; y <= 1; y++) {
        for (var x = -1; x <= 1; x++) {
            let o = vec2<f32>(f32(x), f32(y)) * texel;
            sum += textureSampleCompareLevel(shadow_map, shadow_sampler, uv + o, ndc.z - 0.0015 * coarse);
        }
    }
    return sum / 9.0;
}

fn shade(camrel: vec3<f32>, normal_in: vec3<f32>, uv: vec2<f32>) -> vec3<f32> {
    let v = normalize(-camrel);
    var n = normalize(normal_in);
    // Thin and planar geometry is lit from whichever side is seen.
    if dot(n, v) < 0.0 {
        n = -n;
    }
    let albedo = object.albedo.rgb * pattern(uv, object.texture);
    var c = frame.ambient.rgb * albedo + object.emissive.rgb;
    let roughness = object.emissive.w;
    for (var i = 0u; i < frame.flags.w; i++) {
        let light = frame.lights[i];
        let kind = u32(light.pos_kind.w);
        var l = -light.dir_cos.xyz;
        var radiance = light.color_shadow.rgb;
        if kind != 0u {
            let d = light.pos_kind.xyz - camrel;
            let dist2 = max(dot(d, d), 1e-4);
            l = d * inverseSqrt(dist2);
            radiance = radiance / dist2;
            if kind == 2u {
                let cos_angle = dot(-l, light.dir_cos.xyz);
                radiance = radiance * smoothstep(light.dir_cos.w, light.dir_cos.w + 0.05, cos_angle);
            }
        }
        let ndl = max(dot(n, l), 0.0);
        if ndl <= 0.0 {
            continue;
        }
        var visible = 1.0;
        if frame.flags.z != 0u && light.color_shadow.w > 0.5 {
            visible = shadow(camrel, n);
        }
        var lit = albedo * ndl;
        if frame.flags.y != 0u {
            let h = normalize(l + v);
            let shininess = mix(256.0, 4.0, roughness);
            let spec = object.texture.w * pow(max(dot(n, h), 0.0), shininess) * (shininess + 8.0) / (8.0 * PI);
            lit = lit + vec3<f32>(spec * ndl);
        }
        c += lit * radiance * visible;
    }
    return c;
}

// Opaque surfaces: HDR color, linear view depth, motion current → previous.
@fragment
fn fs_opaque(in: VsOut) -> GBufferOut {
    var out: GBufferOut;
    out.color = vec4<f32>(shade(in.camrel, in.normal, in.uv), 1.0);
    out.depth = bitcast<u32>(in.view_depth);
    out.motion = bitcast<vec2<u32>>(prev_pixel(in.prev_clip) - in.clip.xy);
    out.id = object.ids.x;
    return out;
}

// Translucent surfaces: blended color only; depth and motion keep
// describing the opaque surface behind (their targets are write-masked).
@fragment
fn fs_translucent(in: VsOut) -> GBufferOut {
    var out: GBufferOut;
    out.color = vec4<f32>(shade(in.camrel, in.normal, in.uv), object.albedo.a);
    out.depth = bitcast<u32>(in.view_depth);
    out.motion = bitcast<vec2<u32>>(vec2<f32>(0.0));
    out.id = 0u;
    return out;
}
