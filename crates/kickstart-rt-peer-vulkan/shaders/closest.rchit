#version 460
#extension GL_EXT_ray_tracing : require
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(location = 0) rayPayloadInEXT PeerHit payload;
hitAttributeEXT vec2 bary;

void main() {
    // The hit distance is the same parameter in object and world space (the direction is
    // transformed, not renormalised), as in our tracer. bary.x weights vertex 1, bary.y vertex 2.
    payload = PeerHit(gl_HitTEXT, bary.x, bary.y, uint(gl_InstanceCustomIndexEXT),
        uint(gl_PrimitiveID), 1u, 0u, 0u);
}
