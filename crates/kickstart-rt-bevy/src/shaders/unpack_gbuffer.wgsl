// Unpacks Bevy 0.20's deferred G-buffer (Rgba32Uint, bevy_pbr's deferred/functions.wesl) into
// the textures the SDK and the composite read:
// - normal_roughness: world-space unit normal (RGB), perceptual roughness (A);
// - specular: F0 (RGB), metallic (A);
// - diffuse: the diffuse colour, base colour × (1 − metallic) (RGB).
// Unlit materials reflect nothing: their F0 and diffuse colour are zero.

@group(0) @binding(0) var gbuffer: texture_2d<u32>;
@group(0) @binding(1) var normal_roughness: texture_storage_2d<rgba16float, write>;
@group(0) @binding(2) var specular: texture_storage_2d<rgba16float, write>;
@group(0) @binding(3) var diffuse: texture_storage_2d<rgba16float, write>;

const UNLIT_FLAG: u32 = 1u;

fn unpack_unorm4x8(v: u32) -> vec4<f32> {
    return vec4<f32>(
        f32(v & 0xffu),
        f32((v >> 8u) & 0xffu),
        f32((v >> 16u) & 0xffu),
        f32(v >> 24u),
    ) / 255.0;
}

// Bevy's octahedral encoding, mapped to [0, 1].
fn octahedral_decode(e: vec2<f32>) -> vec3<f32> {
    let f = e * 2.0 - 1.0;
    var n = vec3<f32>(f, 1.0 - abs(f.x) - abs(f.y));
    let t = saturate(-n.z);
    let w = select(vec2<f32>(t), vec2<f32>(-t), n.xy >= vec2<f32>(0.0));
    n = vec3<f32>(n.xy + w, n.z);
    return normalize(n);
}

@compute @workgroup_size(8, 8)
fn unpack(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(gbuffer);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let g = textureLoad(gbuffer, id.xy, 0);
    let base_roughness = unpack_unorm4x8(g.r);
    let props = unpack_unorm4x8(g.b);
    let flags = (g.a >> 24u) & 0xffu;
    let oct = vec2<f32>(f32(g.a & 0xfffu), f32((g.a >> 12u) & 0xfffu)) / 4095.0;
    let n = octahedral_decode(oct);
    let reflectance = props.r;
    let metallic = props.g;
    var base = pow(base_roughness.rgb, vec3<f32>(2.2));
    var f0 = mix(vec3<f32>(0.16 * reflectance * reflectance), base, metallic);
    if (flags & UNLIT_FLAG) != 0u {
        base = vec3<f32>(0.0);
        f0 = vec3<f32>(0.0);
    }
    textureStore(normal_roughness, id.xy, vec4<f32>(n, base_roughness.a));
    textureStore(specular, id.xy, vec4<f32>(f0, metallic));
    textureStore(diffuse, id.xy, vec4<f32>(base * (1.0 - metallic), 1.0));
}
