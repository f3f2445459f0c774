//! Skinning and morph targets on the GPU: a [`SkinningTask`] poses one mesh (rest positions,
//! morph-target deltas, up to four joint influences a vertex) into a positions buffer, which an
//! `allow_update` geometry then refits from in the same GPU task.

use glam::Mat4;

use super::VertexFormat;

/// Layout of a vertex's four joint indices (glTF `JOINTS_0`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum JointFormat {
    /// Four `u8`.
    Uint8x4,
    /// Four `u16` (glTF's usual choice).
    #[default]
    Uint16x4,
    /// Four `u32`.
    Uint32x4,
}

impl JointFormat {
    /// Bytes one vertex's joints occupy.
    pub fn size(self) -> u64 {
        match self {
            JointFormat::Uint8x4 => 4,
            JointFormat::Uint16x4 => 8,
            JointFormat::Uint32x4 => 16,
        }
    }
}

/// Layout of a vertex's four joint weights (glTF `WEIGHTS_0`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WeightFormat {
    /// Four `f32`.
    #[default]
    Float32x4,
    /// Four unsigned-normalised `u8`.
    Unorm8x4,
    /// Four unsigned-normalised `u16`.
    Unorm16x4,
}

impl WeightFormat {
    /// Bytes one vertex's weights occupy.
    pub fn size(self) -> u64 {
        match self {
            WeightFormat::Float32x4 => 16,
            WeightFormat::Unorm8x4 => 4,
            WeightFormat::Unorm16x4 => 8,
        }
    }
}

/// One per-vertex attribute of a skinning task read from a buffer: vertex `v`'s value starts
/// at `offset + v * stride`. The buffer needs `STORAGE` usage (the pass reads it in place).
#[derive(Debug, Clone)]
pub struct SkinAttribute<F> {
    /// The buffer.
    pub buffer: wgpu::Buffer,
    /// Byte offset of vertex 0's value; a multiple of 4.
    pub offset: u64,
    /// Bytes between consecutive vertices' values; a multiple of 4, at least the format's size.
    pub stride: u64,
    /// Layout of one value.
    pub format: F,
}

/// Which joints move each vertex and by how much (one glTF `JOINTS_0`/`WEIGHTS_0` pair).
///
/// A vertex's position is `Σ weight[i] · joint_matrices[joint[i]] · p` over its four influences.
/// The weights are used as given (glTF requires them to sum to 1); a vertex whose weights are
/// all zero keeps its unskinned position, and an influence naming a joint past the end of
/// [`SkinningTask::joint_matrices`] is ignored.
#[derive(Debug, Clone)]
pub struct SkinInfluences {
    /// Four joint indices a vertex.
    pub joints: SkinAttribute<JointFormat>,
    /// Four weights a vertex.
    pub weights: SkinAttribute<WeightFormat>,
}

/// A mesh's morph targets' position deltas, all in one buffer: target `t`'s delta of vertex `v`
/// is three `f32` at `offset + t * target_stride + v * stride`. The buffer needs `STORAGE`
/// usage.
#[derive(Debug, Clone)]
pub struct MorphTargetsInput {
    /// The buffer.
    pub buffer: wgpu::Buffer,
    /// Byte offset of target 0's vertex 0; a multiple of 4.
    pub offset: u64,
    /// Bytes between consecutive vertices of a target; a multiple of 4, at least 12.
    pub stride: u64,
    /// Bytes between consecutive targets; a multiple of 4.
    pub target_stride: u64,
    /// Number of targets (the length of [`SkinningTask::morph_weights`]).
    pub count: u32,
}

/// Where a skinning task writes the posed positions: three `f32` (`VertexFormat::Float32x3`)
/// of vertex `v` at `offset + v * stride`; the bytes between them are left alone, so the
/// positions may sit in an interleaved vertex buffer. The buffer needs `STORAGE` usage, and
/// `COPY_SRC` when a geometry reads it (as every geometry does).
#[derive(Debug, Clone)]
pub struct SkinningOutput {
    /// The buffer; it must not be one of the task's input buffers.
    pub buffer: wgpu::Buffer,
    /// Byte offset of vertex 0's position; a multiple of 4.
    pub offset: u64,
    /// Bytes between consecutive positions; a multiple of 4, at least 12.
    pub stride: u64,
}

/// Poses one mesh on the GPU: `output[v] = skin(rest[v] + Σ morph_weights[t] · delta[t][v])`.
///
/// Scheduled as a BVH task (`TaskContainer::schedule_bvh_task`): every skinning task of a
/// container is recorded before the container's geometry tasks, whatever the order they were
/// scheduled in, so a `GeometryTask` with `TaskOperation::Update` whose vertex buffer is
/// `output` refits the geometry at this frame's pose. Schedule all of a frame's characters in
/// one container: their refits then share one BVH build.
///
/// Tasks whose rest positions, joints, weights, morph deltas and outputs lie in the same five
/// buffers (at offsets of their own, as an engine's vertex allocator places meshes) are posed
/// by one dispatch; others by a dispatch each, in the same compute pass. Tasks still run in
/// their order where it matters: a task whose output overlaps what an earlier task reads or
/// writes is posed after it.
///
/// Positions are in the mesh's own space: a joint matrix is the one a vertex shader would use,
/// `inverse(mesh world) · joint world · inverse bind matrix`. Only positions are posed (tracing
/// needs no normals).
#[derive(Debug, Clone)]
pub struct SkinningTask {
    /// Name used in errors and GPU timings.
    pub name: String,
    /// The rest (bind-pose) positions, `Float32x3` or `Float32x4` (`w` ignored); the buffer
    /// needs `STORAGE` usage.
    pub rest_positions: SkinAttribute<VertexFormat>,
    /// Vertices posed.
    pub vertex_count: u32,
    /// The joints and weights; `None` for a mesh that only morphs.
    pub influences: Option<SkinInfluences>,
    /// One matrix a joint (affine: the last row must be `0, 0, 0, 1`); at most
    /// [`SkinningTask::MAX_JOINTS`].
    pub joint_matrices: Vec<Mat4>,
    /// The morph targets; `None` for a mesh without them.
    pub morph_targets: Option<MorphTargetsInput>,
    /// One weight a morph target; targets of weight 0 cost nothing.
    pub morph_weights: Vec<f32>,
    /// Where the posed positions go.
    pub output: SkinningOutput,
}

impl SkinningTask {
    /// Most joints one task may name (glTF skins rarely pass a few hundred).
    pub const MAX_JOINTS: usize = 1 << 16;
    /// Most morph targets one task may name.
    pub const MAX_MORPH_TARGETS: u32 = 256;
}
