// Box pyramid over n boxes in sorted order (a BLAS refit's leaf boxes), shared by the BLAS
// refit's gather (prims.wgsl: it writes levels 1..=PYRAMID_GATHER_LEVELS) and the LBVH's range
// refit (lbvh.wgsl: lbvh_pyramid writes the levels above, lbvh_range_refit reads them).
//
// Level 0 is the n boxes themselves; level L >= 1 holds ceil(n / 2^L) boxes, box i of it being the
// union of boxes 2i and 2i + 1 of level L - 1 (only 2i at the end of an odd level). The levels
// follow each other in one array of boxes (two vec4 each: min, max; w unused), so box i of level
// L is box pyramid_level_start(n, L) + i, and all levels together are pyramid_boxes(n) boxes
// (src/scene/lbvh.rs: `pyramid_boxes`, the same sum). Empty boxes above level 0 are
// (PYRAMID_EMPTY, -PYRAMID_EMPTY): a union with them is exact for every finite coordinate.
//
// Why: every node of a Karras tree covers one range of sorted positions, and the box of any range
// is the union of at most two pyramid boxes per level. A refit of such a tree can then compute
// each node's boxes on its own, in one pass, instead of climbing from the leaves through chains
// of device-scope round trips (docs/ray-tracing-core.md, "Refit").

// Levels the gather writes: one per halving of its 64-invocation workgroup.
const PYRAMID_GATHER_LEVELS: u32 = 6u;
// Levels one lbvh_pyramid workgroup adds: 256 invocations reduce 512 boxes to one.
const PYRAMID_PASS_LEVELS: u32 = 9u;
const PYRAMID_EMPTY: f32 = 3.40282347e38;

// Boxes of the level above a level of `count` boxes (n <= 2^28: no overflow).
fn pyramid_parent_count(count: u32) -> u32 {
    return (count + 1u) / 2u;
}

// First box of level `level` of the pyramid over n boxes.
fn pyramid_level_start(n: u32, level: u32) -> u32 {
    var start = 0u;
    var count = n;
    for (var l = 0u; l < level; l++) {
        start += count;
        count = pyramid_parent_count(count);
    }
    return start;
}

// Boxes in level `level` of the pyramid over n boxes.
fn pyramid_level_count(n: u32, level: u32) -> u32 {
    var count = n;
    for (var l = 0u; l < level; l++) {
        count = pyramid_parent_count(count);
    }
    return count;
}
