// ksrt's composite (a full-screen triangle): direct + diffuse GI × diffuse albedo × AO + specular
// radiance × the split-sum BRDF (Karis's analytic fit), the sun's shadow map swapped for the
// SDK's ray-traced shadow when it is on; then a fixed exposure and the ACES filmic fit
// (Narkowicz 2015) to display values.

struct View {
    view_proj: mat4x4f,
    inv_view_proj: mat4x4f,
    unjittered_view_proj: mat4x4f,
    prev_view_proj: mat4x4f,
    eye: vec4f,
    size: vec4f,
}

struct Settings {
    // specular, diffuse, ao, shadow: 1 when that SDK channel is used
    enabled: vec4f,
    // shadow input is the raw trace (hit distance, < 0 lit) rather than denoised visibility;
    // encode sRGB in the shader (the target is not an sRGB format); exposure; ambient level
    // used when there is no diffuse GI
    params: vec4f,
    // what to show: 0 the composite, 1 direct light, 2 specular, 3 diffuse, 4 AO, 5 shadow
    // visibility, 6 the SDK debug view; the scene's size (hit distance shading)
    view: vec4f,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> settings: Settings;
@group(0) @binding(2) var depth_tex: texture_depth_2d;
@group(0) @binding(3) var normal_tex: texture_2d<f32>;
@group(0) @binding(4) var base_color_tex: texture_2d<f32>;
@group(0) @binding(5) var specular_tex: texture_2d<f32>;
@group(0) @binding(6) var direct_tex: texture_2d<f32>;
@group(0) @binding(7) var sun_tex: texture_2d<f32>;
@group(0) @binding(8) var rt_specular: texture_2d<f32>;
@group(0) @binding(9) var rt_diffuse: texture_2d<f32>;
@group(0) @binding(10) var rt_ao: texture_2d<f32>;
@group(0) @binding(11) var rt_shadow: texture_2d<f32>;
@group(0) @binding(12) var rt_debug: texture_2d<f32>;

@vertex
fn vs_fullscreen(@builtin(vertex_index) i: u32) -> @builtin(position) vec4f {
    let uv = vec2f(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4f(uv * 2.0 - 1.0, 0.0, 1.0);
}

struct Out {
    @location(0) hdr: vec4f,
    @location(1) ldr: vec4f,
}

fn env_brdf(f0: vec3f, roughness: f32, nv: f32) -> vec3f {
    let c0 = vec4f(-1.0, -0.0275, -0.572, 0.022);
    let c1 = vec4f(1.0, 0.0425, 1.04, -0.04);
    let r = roughness * c0 + c1;
    let a004 = min(r.x * r.x, exp2(-9.28 * nv)) * r.x + r.y;
    let ab = vec2f(-1.04, 1.04) * a004 + r.zw;
    return f0 * ab.x + ab.y;
}

fn aces(x: vec3f) -> vec3f {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), vec3f(0.0), vec3f(1.0));
}

fn srgb(c: vec3f) -> vec3f {
    let lo = c * 12.92;
    let hi = 1.055 * pow(c, vec3f(1.0 / 2.4)) - 0.055;
    return select(hi, lo, c <= vec3f(0.0031308));
}

@fragment
fn fs_main(@builtin(position) frag: vec4f) -> Out {
    let pixel = vec2i(frag.xy);
    let depth = textureLoad(depth_tex, pixel, 0);
    var color = textureLoad(direct_tex, pixel, 0).rgb;
    if (depth < 1.0) {
        let ndc = vec2f(frag.x * view.size.z * 2.0 - 1.0, 1.0 - frag.y * view.size.w * 2.0);
        let wp = view.inv_view_proj * vec4f(ndc, depth, 1.0);
        let p = wp.xyz / wp.w;
        let n = normalize(textureLoad(normal_tex, pixel, 0).xyz);
        let nv = clamp(dot(n, normalize(view.eye.xyz - p)), 1e-4, 1.0);
        let base_m = textureLoad(base_color_tex, pixel, 0);
        let spec = textureLoad(specular_tex, pixel, 0);
        let diffuse_albedo = base_m.rgb * (1.0 - base_m.a);
        if (settings.enabled.w > 0.5) {
            let sun = textureLoad(sun_tex, pixel, 0);
            var vis = textureLoad(rt_shadow, pixel, 0).r;
            if (settings.params.x > 0.5) {
                vis = select(0.0, 1.0, vis < 0.0);
            }
            color += sun.rgb * (clamp(vis, 0.0, 1.0) - sun.a);
        }
        var ao = 1.0;
        if (settings.enabled.z > 0.5) {
            ao = clamp(textureLoad(rt_ao, pixel, 0).r, 0.0, 1.0);
        }
        var indirect = vec3f(settings.params.w);
        if (settings.enabled.y > 0.5) {
            indirect = max(textureLoad(rt_diffuse, pixel, 0).rgb, vec3f(0.0));
        }
        color += diffuse_albedo * indirect * ao;
        if (settings.enabled.x > 0.5) {
            let l = max(textureLoad(rt_specular, pixel, 0).rgb, vec3f(0.0));
            color += l * env_brdf(spec.rgb, spec.a, nv);
        }
    }
    let mode = u32(settings.view.x);
    if (mode == 1u) {
        color = textureLoad(direct_tex, pixel, 0).rgb;
    } else if (mode == 2u) {
        color = textureLoad(rt_specular, pixel, 0).rgb;
    } else if (mode == 3u) {
        color = textureLoad(rt_diffuse, pixel, 0).rgb;
    } else if (mode == 4u) {
        color = vec3f(textureLoad(rt_ao, pixel, 0).r);
    } else if (mode == 5u) {
        var vis = textureLoad(rt_shadow, pixel, 0).r;
        if (settings.params.x > 0.5) {
            vis = select(0.0, 1.0, vis < 0.0);
        }
        color = vec3f(vis);
    } else if (mode == 6u) {
        color = textureLoad(rt_debug, pixel, 0).rgb;
    }
    var out: Out;
    out.hdr = vec4f(color, 1.0);
    var display = aces(color * settings.params.z);
    if (settings.params.y > 0.5) {
        display = srgb(display);
    }
    out.ldr = vec4f(display, 1.0);
    return out;
}
