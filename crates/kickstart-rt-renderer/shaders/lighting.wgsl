// Direct lighting pass of ksrt's deferred rasteriser (a full-screen triangle): the analytic
// lights (sun with a PCF shadow map, point, spot) with a Lambert + GGX BRDF, added (blending) to
// the emission the emission pass wrote; sky where nothing was drawn. Writes the direct lighting (what the SDK injects into its cache) and,
// separately, the sun's unshadowed radiance with the shadow map's visibility in alpha, so the
// composite can swap the shadow map for the SDK's ray-traced shadow.

struct View {
    view_proj: mat4x4f,
    inv_view_proj: mat4x4f,
    unjittered_view_proj: mat4x4f,
    prev_view_proj: mat4x4f,
    eye: vec4f,
    size: vec4f,
}

struct Light {
    // kind (0 sun, 1 point, 2 spot), range, cos(inner), cos(outer)
    kind: vec4f,
    position: vec4f,
    // direction the light travels / shines
    direction: vec4f,
    color: vec4f,
}

struct Lights {
    // count, index of the light with a separate shadow term (or 0xffffffff), 1 if it has a
    // shadow map, -
    count: vec4u,
    shadow_view_proj: mat4x4f,
    // texel size of the shadow map, depth bias, -, -
    shadow_params: vec4f,
    sky: vec4f,
    items: array<Light, 8>,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<uniform> lights: Lights;
@group(0) @binding(2) var depth_tex: texture_depth_2d;
@group(0) @binding(3) var normal_tex: texture_2d<f32>;
@group(0) @binding(5) var base_color_tex: texture_2d<f32>;
@group(0) @binding(6) var specular_tex: texture_2d<f32>;
@group(0) @binding(7) var shadow_map: texture_depth_2d;
@group(0) @binding(8) var shadow_sampler: sampler_comparison;

const PI: f32 = 3.14159265;

@vertex
fn vs_fullscreen(@builtin(vertex_index) i: u32) -> @builtin(position) vec4f {
    let uv = vec2f(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4f(uv * 2.0 - 1.0, 0.0, 1.0);
}

struct Out {
    @location(0) direct: vec4f,
    @location(1) sun: vec4f,
}

fn world_position(pixel: vec2f, depth: f32) -> vec3f {
    let ndc = vec2f(pixel.x * view.size.z * 2.0 - 1.0, 1.0 - pixel.y * view.size.w * 2.0);
    let p = view.inv_view_proj * vec4f(ndc, depth, 1.0);
    return p.xyz / p.w;
}

// Lambert diffuse plus GGX specular (Smith height-correlated visibility, Schlick Fresnel),
// times n·l: the radiance reflected towards `v` per unit irradiance from `l`.
fn brdf_cos(n: vec3f, v: vec3f, l: vec3f, base: vec3f, metallic: f32, f0: vec3f, roughness: f32) -> vec3f {
    let nl = dot(n, l);
    if (nl <= 0.0) {
        return vec3f(0.0);
    }
    let nv = max(dot(n, v), 1e-4);
    let h = normalize(v + l);
    let nh = max(dot(n, h), 0.0);
    let a = max(roughness * roughness, 0.02);
    let a2 = a * a;
    let d = a2 / (PI * pow(nh * nh * (a2 - 1.0) + 1.0, 2.0));
    let vis = 0.5 / (nl * sqrt(nv * nv * (1.0 - a2) + a2) + nv * sqrt(nl * nl * (1.0 - a2) + a2));
    let f = f0 + (1.0 - f0) * pow(1.0 - max(dot(v, h), 0.0), 5.0);
    let diffuse = base * (1.0 - metallic) / PI;
    return (diffuse * (1.0 - f) + d * vis * f) * nl;
}

fn shadow_visibility(p: vec3f, n: vec3f) -> f32 {
    let texel = lights.shadow_params.x;
    // Normal offset against acne, a few texels of the map.
    let c = lights.shadow_view_proj * vec4f(p + n * lights.shadow_params.z, 1.0);
    let uv = vec2f(c.x * 0.5 + 0.5, 0.5 - c.y * 0.5);
    if (any(uv < vec2f(0.0)) || any(uv > vec2f(1.0)) || c.z > 1.0) {
        return 1.0;
    }
    var sum = 0.0;
    for (var y = -1; y <= 1; y++) {
        for (var x = -1; x <= 1; x++) {
            sum += textureSampleCompareLevel(shadow_map, shadow_sampler, uv + vec2f(f32(x), f32(y)) * texel, c.z - lights.shadow_params.y);
        }
    }
    return sum / 9.0;
}

@fragment
fn fs_main(@builtin(position) frag: vec4f) -> Out {
    var out: Out;
    let pixel = vec2i(frag.xy);
    let depth = textureLoad(depth_tex, pixel, 0);
    if (depth >= 1.0) {
        out.direct = vec4f(lights.sky.rgb, 1.0);
        out.sun = vec4f(0.0, 0.0, 0.0, 1.0);
        return out;
    }
    let p = world_position(frag.xy, depth);
    let n = normalize(textureLoad(normal_tex, pixel, 0).xyz);
    let v = normalize(view.eye.xyz - p);
    let base_m = textureLoad(base_color_tex, pixel, 0);
    let spec = textureLoad(specular_tex, pixel, 0);
    var radiance = vec3f(0.0);
    out.sun = vec4f(0.0, 0.0, 0.0, 1.0);
    for (var i = 0u; i < lights.count.x; i++) {
        let light = lights.items[i];
        var l: vec3f;
        var e: vec3f;
        if (light.kind.x < 0.5) {
            l = -light.direction.xyz;
            e = light.color.rgb;
        } else {
            let to = light.position.xyz - p;
            let d2 = max(dot(to, to), 1e-8);
            let d = sqrt(d2);
            l = to / d;
            // Inverse square, windowed smoothly to 0 at the range (as glTF's punctual lights).
            let window = clamp(1.0 - pow(d / light.kind.y, 4.0), 0.0, 1.0);
            e = light.color.rgb / d2 * window * window;
            if (light.kind.x > 1.5) {
                let cos_axis = dot(-l, light.direction.xyz);
                e *= smoothstep(light.kind.w, light.kind.z, cos_axis);
            }
        }
        let lit = e * brdf_cos(n, v, l, base_m.rgb, base_m.a, spec.rgb, spec.a);
        if (i == lights.count.y) {
            var vis = 1.0;
            if (lights.count.z == 1u) {
                vis = shadow_visibility(p, n);
            }
            out.sun = vec4f(lit, vis);
            radiance += lit * vis;
        } else {
            radiance += lit;
        }
    }
    out.direct = vec4f(radiance, 1.0);
    return out;
}
