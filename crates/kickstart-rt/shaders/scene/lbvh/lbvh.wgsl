// GPU LBVH (Karras 2012, "Maximizing Parallelism in the Construction of BVHs, Octrees, and k-d
// Trees") over primitive AABBs, and its refit: the LBVH's shader, one module per pass (or per
// group of passes that share their bindings) in this folder, imported here in pass order. Their
// shared bindings, constants and layouts: scene/lbvh/common.wgsl; docs/ray-tracing-core.md.
// Driven by src/scene/lbvh/mod.rs, which documents the pass order and composes this module with
// scene/lbvh/hploc.wgsl (the clustered climb) into one shader.
//
// Entry points (all 256 invocations, 1-D workgroups split into 2-D by the Recorder):
//   lbvh_bounds    (bounds.wgsl) per primitive: centroid bounds of the valid primitives ->
//                  work[seg.work_base + 0..6] (not run when the caller's pass merged them: the
//                  TLAS's instance boxes)
//   lbvh_morton    (morton.wgsl) per primitive: Morton key of key_bits bits, min(key_bits / 3,
//                  10) per axis (empty: all ones, sorts last), value = index; with
//                  lbvh_morton_histogram, and a batch's lbvh_segment_keys and lbvh_rekey
//   (radix sort of (keys, values), key_bits bits, by the caller)
//   lbvh_gather    (gather.wgsl) per sorted position of a batch: the build's triangles in sorted
//                  order
//   lbvh_hierarchy (hierarchy.wgsl) per sorted position: order[], and for inner nodes children
//                  + parents
//   lbvh_climb     (climb.wgsl) per leaf: bottom-up boxes, writes the final nodes and bounds_out
//                  (build and refit share it)
//   lbvh_refit_gather, lbvh_refit_ingest, lbvh_range_refit
//                  (range_refit.wgsl) the range refit of a BLAS (a Karras tree, one triangle a
//                  leaf) from its re-ingested triangles: every node's boxes from its leaf range,
//                  each node on its own
//   lbvh_compact_mark, lbvh_compact_count, lbvh_compact_scan, lbvh_compact_assign,
//   lbvh_compact_scatter
//                  (compact.wgsl) after a clustered BLAS build's climb: the nodes its
//                  collapsed leaves left unreferenced dropped, the rest moved to the front

#import scene/lbvh/bounds
#import scene/lbvh/morton
#import scene/lbvh/gather
#import scene/lbvh/hierarchy
#import scene/lbvh/climb
#import scene/lbvh/range_refit
#import scene/lbvh/compact
