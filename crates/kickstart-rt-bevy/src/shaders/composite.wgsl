// Adds the SDK's ray-traced lighting to Bevy's lit image (a full-screen triangle writing the
// view's other main texture):
//   out = lit − sun diffuse × (1 − visibility)          (shadows)
//       + diffuse colour × GI × AO                      (GI; without GI, AO scales `lit`)
//       + reflections × split-sum specular term         (reflections)
// Pixels with nothing rendered (depth 0 under Bevy's reverse Z) pass through.

struct Params {
    // Clip space to world space (the inverse of Bevy's unjittered clip_from_world).
    world_from_clip: mat4x4<f32>,
    // Camera position (xyz): the view vector's fallback on the near plane.
    camera: vec4<f32>,
    // Unit vector towards the sun (xyz); w = 1 when there is a sun.
    to_sun: vec4<f32>,
    // Sun colour × illuminance × exposure (rgb).
    sun: vec4<f32>,
    // Effects on: reflections, GI, AO, shadows (shadows 2: the raw trace, denoising off).
    effects: vec4<u32>,
    // Per signal (reflections, GI, AO, shadow): the pixel block it was traced in, and the
    // traced pixel in the block (bits 0–7 side, 8–15 x, 16–23 y); side 1 reads every pixel.
    traced_pixels: vec4<u32>,
};

@group(0) @binding(0) var lit: texture_2d<f32>;
@group(0) @binding(1) var depth: texture_depth_2d;
@group(0) @binding(2) var normal_roughness: texture_2d<f32>;
@group(0) @binding(3) var specular: texture_2d<f32>;
@group(0) @binding(4) var diffuse_color: texture_2d<f32>;
@group(0) @binding(5) var reflections: texture_2d<f32>;
@group(0) @binding(6) var gi: texture_2d<f32>;
@group(0) @binding(7) var ao: texture_2d<f32>;
@group(0) @binding(8) var shadow: texture_2d<f32>;
@group(0) @binding(9) var<uniform> params: Params;

const PI: f32 = 3.14159265;

@vertex
fn fullscreen(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

// The split-sum specular term's scale and bias for F0 (Karis' analytic fit of the
// environment BRDF).
fn environment_brdf(f0: vec3<f32>, roughness: f32, n_dot_v: f32) -> vec3<f32> {
    let c0 = vec4<f32>(-1.0, -0.0275, -0.572, 0.022);
    let c1 = vec4<f32>(1.0, 0.0425, 1.04, -0.04);
    let r = roughness * c0 + c1;
    let a004 = min(r.x * r.x, exp2(-9.28 * n_dot_v)) * r.x + r.y;
    let ab = vec2<f32>(-1.04, 1.04) * a004 + r.zw;
    return f0 * ab.x + ab.y;
}

// The world position of clip-space depth `d` (reverse Z) at `ndc`.
fn unproject(ndc: vec2<f32>, d: f32) -> vec3<f32> {
    let h = params.world_from_clip * vec4<f32>(ndc, d, 1.0);
    return h.xyz / h.w;
}

// Unit vector from `world` (at `ndc`) back along the pixel's view ray: towards the pixel's point
// on the near plane, so an orthographic camera gets its view direction (the same everywhere)
// and a perspective one the direction to the camera. A point on the near plane itself falls back
// to the camera position.
fn to_viewer(ndc: vec2<f32>, world: vec3<f32>) -> vec3<f32> {
    let back = unproject(ndc, 1.0) - world;
    if dot(back, back) > 1e-12 {
        return normalize(back);
    }
    return normalize(params.camera.xyz - world);
}

// The texel of a signal traced in blocks (`code`: see `Params::traced_pixels`) that stands for
// pixel `p`: the traced pixel of `p`'s block, or of the block before it where that one falls
// outside the image (the last, partial, block of a row or column).
fn traced_pixel(p: vec2<i32>, code: u32) -> vec2<i32> {
    let side = i32(code & 0xffu);
    if side <= 1 {
        return p;
    }
    let offset = vec2<i32>(i32((code >> 8u) & 0xffu), i32((code >> 16u) & 0xffu));
    var q = p - p % side + offset;
    let size = vec2<i32>(textureDimensions(lit));
    q = select(q, q - vec2<i32>(side), q >= size);
    return max(q, vec2<i32>(0));
}

@fragment
fn composite(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    let p = vec2<i32>(position.xy);
    var color = textureLoad(lit, p, 0).rgb;
    let d = textureLoad(depth, p, 0);
    if d <= 0.0 {
        return vec4<f32>(color, 1.0);
    }
    let size = vec2<f32>(textureDimensions(lit));
    let ndc = vec2<f32>(position.x / size.x * 2.0 - 1.0, 1.0 - position.y / size.y * 2.0);
    let world = unproject(ndc, d);
    let nr = textureLoad(normal_roughness, p, 0);
    let n = normalize(nr.xyz);
    let albedo = textureLoad(diffuse_color, p, 0).rgb;
    let on = params.effects != vec4<u32>(0u);

    if on.w && params.to_sun.w > 0.0 {
        // Denoised: visibility. Raw (denoising off): the occluder's distance, negative where the
        // sun is visible.
        let s = textureLoad(shadow, traced_pixel(p, params.traced_pixels.w), 0).r;
        let visibility = select(saturate(s), select(0.0, 1.0, s < 0.0), params.effects.w == 2u);
        let n_dot_l = max(dot(n, params.to_sun.xyz), 0.0);
        let sun_diffuse = albedo / PI * params.sun.rgb * n_dot_l;
        color = max(color - sun_diffuse * (1.0 - visibility), vec3<f32>(0.0));
    }
    let ao_texel = traced_pixel(p, params.traced_pixels.z);
    let occlusion = select(1.0, saturate(textureLoad(ao, ao_texel, 0).r), on.z);
    if on.y {
        let gi_texel = traced_pixel(p, params.traced_pixels.y);
        color += albedo * max(textureLoad(gi, gi_texel, 0).rgb, vec3<f32>(0.0)) * occlusion;
    } else {
        color *= occlusion;
    }
    if on.x {
        let v = to_viewer(ndc, world);
        let f0 = textureLoad(specular, p, 0).rgb;
        let brdf = environment_brdf(f0, nr.w, saturate(dot(n, v)));
        let reflected = textureLoad(reflections, traced_pixel(p, params.traced_pixels.x), 0).rgb;
        color += max(reflected, vec3<f32>(0.0)) * brdf;
    }
    return vec4<f32>(color, 1.0);
}
