// Shared by the peer's ray-tracing shaders: the hit record, laid out as kickstart-rt's GpuHit
// (32 bytes, std430), so hits can be compared field by field with ours.
struct PeerHit {
    float t;          // ray parameter of the hit; -1 on a miss
    float u;          // barycentric weight of the triangle's second vertex
    float v;          // barycentric weight of the third vertex
    uint instance;    // instance custom index (our instance slot index); 0xffffffff on a miss
    uint primitive;   // triangle index within the BLAS's geometry; 0xffffffff on a miss
    uint hit;         // 1 on a hit, 0 on a miss
    uint pad0;
    uint pad1;
};

PeerHit peer_miss() {
    return PeerHit(-1.0, 0.0, 0.0, 0xffffffffu, 0xffffffffu, 0u, 0u, 0u);
}
