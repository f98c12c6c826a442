// The shadow map pass (only for scenes with the `shadows` effect): depth of
// every opaque surface seen from the shadow-casting light.

@vertex
fn vs_shadow(v: VertexIn) -> @builtin(position) vec4<f32> {
    return frame.shadow_from_camrel * (object.model * vec4<f32>(v.position, 1.0));
}
