// Primary-ray debug views (HitT, Barycentrics, RandomMeshColor, RandomTileColor,
// DirectLightingCache): one camera ray per pixel of the viewport, traced with scene/traversal
// (scene at @group(0)); the lighting cache's sampling module is at @group(2). OUTPUT_FORMAT is
// the storage format of the output texture.

#import scene/traversal
#import cache/sample
#param OUTPUT_FORMAT

struct DebugParams {
    // inverse(view_to_clip * world_to_view)
    clip_to_world: mat4x4<f32>,
    // Perspective: the eye (xyz).
    eye: vec4<f32>,
    // x, y, width, height in pixels.
    viewport: vec4<u32>,
    // 0: perspective (rays from the eye), 1: orthographic (rays from the near plane).
    ortho: u32,
    // 1: HitT, 2: Barycentrics, 3: RandomMeshColor, 4: RandomTileColor, 5: DirectLightingCache.
    kind: u32,
    // NDC depth of the ray origin (orthographic) and of the point the ray aims at.
    z_origin: f32,
    z_target: f32,
    // Instance inclusion mask of the primary rays (VISIBLE_IN_RT).
    mask: u32,
    // 1: interpolated cache reads (DirectLightingCache).
    bilinear: u32,
    pad1: u32,
    pad2: u32,
}

@group(1) @binding(0) var<uniform> params: DebugParams;
@group(1) @binding(1) var output: texture_storage_2d<{{OUTPUT_FORMAT}}, write>;

fn unproject(ndc: vec2<f32>, z: f32) -> vec3<f32> {
    let p = params.clip_to_world * vec4<f32>(ndc, z, 1.0);
    return p.xyz / p.w;
}

// PCG hash: an instance index → a well-spread colour.
fn hash_u32(x: u32) -> u32 {
    let state = x * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// The traversal module's workgroup size (the Rust side dispatches by it).
@compute @workgroup_size(RT_WORKGROUP_SIZE)
fn main(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = (wid.y * nwg.x + wid.x) * RT_WORKGROUP_SIZE + lid;
    let w = params.viewport.z;
    let h = params.viewport.w;
    if i >= w * h {
        return;
    }
    let px = i % w;
    let py = i / w;
    // Pixel centre → NDC (y up in NDC, down in the texture).
    let ndc = vec2<f32>(
        (f32(px) + 0.5) / f32(w) * 2.0 - 1.0,
        1.0 - (f32(py) + 0.5) / f32(h) * 2.0,
    );
    var origin = params.eye.xyz;
    if params.ortho == 1u {
        origin = unproject(ndc, params.z_origin);
    }
    // Unit length in world space, so t is the world distance from the ray origin.
    let dir = normalize(unproject(ndc, params.z_target) - origin);
    let hit = rt_closest_hit(RtRay(origin, 0.0, dir, RT_FLT_MAX), params.mask);
    var colour = vec4<f32>(0.0);
    if hit.hit != 0u {
        if params.kind == 1u {
            colour = vec4<f32>(hit.t, hit.t, hit.t, 1.0);
        } else if params.kind == 2u {
            colour = vec4<f32>(1.0 - hit.u - hit.v, hit.u, hit.v, 1.0);
        } else if params.kind == 4u {
            let c = hash_u32(cache_tile_id(hit.instance, hit.primitive, vec2<f32>(hit.u, hit.v)));
            colour = vec4<f32>(
                f32(c & 255u) / 255.0,
                f32((c >> 8u) & 255u) / 255.0,
                f32((c >> 16u) & 255u) / 255.0,
                1.0,
            );
        } else if params.kind == 5u {
            let c = cache_radiance(hit.instance, hit.primitive, vec2<f32>(hit.u, hit.v), params.bilinear != 0u);
            colour = vec4<f32>(c, 1.0);
        } else {
            let c = hash_u32(hit.instance);
            colour = vec4<f32>(
                f32(c & 255u) / 255.0,
                f32((c >> 8u) & 255u) / 255.0,
                f32((c >> 16u) & 255u) / 255.0,
                1.0,
            );
        }
    }
    textureStore(output, vec2<u32>(params.viewport.x + px, params.viewport.y + py), colour);
}
