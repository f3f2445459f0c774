//! BVH tasks: register/update geometry and instances, and control BLAS/TLAS builds.

use crate::handles::{GeometryHandle, InstanceHandle};
use glam::{Affine3A, Vec4};

/// Whether a task registers a new object or updates one registered earlier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TaskOperation {
    /// First submission of the object's data.
    #[default]
    Register,
    /// New data for an object registered earlier (vertices of an `allow_update` geometry, an
    /// instance's transform or mask).
    Update,
}

/// Layout of one vertex position in a vertex buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum VertexFormat {
    /// Three `f32` (the reference's format).
    #[default]
    Float32x3,
    /// Four `f32`; `w` is ignored.
    Float32x4,
    /// Four `f16`; `w` is ignored.
    Float16x4,
    /// Four signed-normalised `i16`; `w` is ignored.
    Snorm16x4,
}

impl VertexFormat {
    /// Bytes one position occupies.
    pub fn size(self) -> u64 {
        match self {
            VertexFormat::Float32x3 => 12,
            VertexFormat::Float32x4 => 16,
            VertexFormat::Float16x4 | VertexFormat::Snorm16x4 => 8,
        }
    }
}

/// Width of one index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum IndexFormat {
    /// `u16` indices.
    Uint16,
    /// `u32` indices.
    #[default]
    Uint32,
}

impl IndexFormat {
    /// Bytes one index occupies.
    pub fn size(self) -> u64 {
        match self {
            IndexFormat::Uint16 => 2,
            IndexFormat::Uint32 => 4,
        }
    }
}

/// Vertex positions in an application buffer. The buffer needs `COPY_SRC` usage (the SDK copies
/// the bytes it reads into its own memory inside the engine's encoder).
#[derive(Debug, Clone)]
pub struct VertexBufferInput {
    /// The buffer; the SDK keeps a clone (reference counted) while GPU work reads it.
    pub buffer: wgpu::Buffer,
    /// Byte offset of the first vertex.
    pub offset: u64,
    /// Bytes between consecutive vertices; at least the format's size.
    pub stride: u64,
    /// Number of vertices.
    pub count: u32,
    /// Position format.
    pub format: VertexFormat,
}

/// Triangle-list indices in an application buffer (needs `COPY_SRC`).
#[derive(Debug, Clone)]
pub struct IndexBufferInput {
    /// The buffer.
    pub buffer: wgpu::Buffer,
    /// Byte offset of the first index; a multiple of the index size.
    pub offset: u64,
    /// Number of indices; a multiple of 3.
    pub count: u32,
    /// Index width.
    pub format: IndexFormat,
}

/// One mesh part of a geometry. Several components are merged into one BLAS; a hit's primitive
/// index counts the triangles of all earlier components first.
#[derive(Debug, Clone)]
pub struct GeometryComponent {
    /// Vertex positions.
    pub vertex_buffer: VertexBufferInput,
    /// Indices, or `None` for a non-indexed triangle list (3 consecutive vertices a triangle).
    pub index_buffer: Option<IndexBufferInput>,
    /// A transform applied to this component's positions (geometry space), if any.
    pub transform: Option<Affine3A>,
    /// `(first, count)` in indices (or vertices when non-indexed) of the part to use; `None` uses
    /// all. Both are multiples of 3.
    pub index_range: Option<(u32, u32)>,
    /// Cutout geometry: where rays pass through this component's triangles (glTF `MASK`, or a
    /// flag per triangle). `None`: opaque.
    pub opacity: Option<super::ComponentOpacity>,
}

/// Layout of the direct lighting cache on a geometry's surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SurfelType {
    /// A tile grid per triangle.
    WarpedBarycentricStorage,
    /// Samples shared across neighbouring triangles' vertices and edges; allows bilinear reads.
    #[default]
    MeshColors,
}

/// Which BVH quality/speed trade-off to build.
///
/// Both builds start from the same GPU LBVH (Morton order, Karras hierarchy). Fast-build takes
/// that tree as it is, one triangle per leaf. Fast-trace clusters the Morton-ordered triangles
/// by PLOC while climbing it (H-PLOC: nearest neighbours by merged surface area), which hugs the
/// geometry more closely (lower SAH cost, fewer node visits per ray; most on scenes of separate
/// parts such as buildings), and turns every subtree of up to
/// [`BuildHint::FAST_TRACE_MAX_LEAF`] triangles that is cheaper by the surface area heuristic
/// into one leaf: the fast-trace build takes over twice as long as the fast-build one, for a
/// SAH cost close to a CPU binned-SAH build's (current figures: BENCHMARKS.md, "Builds").
/// Either can be refit (`allow_update`). A fast-build tree is refit from its nodes' leaf
/// ranges, straight from the re-ingested triangles (the range refit, with the ingestion fused
/// into it when both run in one task: no chains of device-scope round trips; see
/// docs/decisions/range-refit.md). A fast-trace tree's nodes are not ranges: its refit climbs
/// the tree bottom-up through device-scope round trips and re-decides its leaves, which is
/// slower.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BuildHint {
    /// Fast-build when `allow_update` is set, fast-trace otherwise.
    #[default]
    Auto,
    /// Highest trace speed.
    PreferFastTrace,
    /// Shortest build.
    PreferFastBuild,
}

impl BuildHint {
    /// Largest leaf of a fast-trace BLAS, in triangles.
    pub const FAST_TRACE_MAX_LEAF: u32 = 4;
}

/// Everything the SDK needs to build one BLAS and its lighting cache layout.
#[derive(Debug, Clone)]
pub struct GeometryInput {
    /// A name for logs and errors.
    pub name: String,
    /// The mesh parts; at least one.
    pub components: Vec<GeometryComponent>,
    /// Cache layout.
    pub surfel_type: SurfelType,
    /// Edge length of one cache tile, in world units (> 0).
    pub tile_unit_length: f32,
    /// Most tiles along a triangle edge (1..=64... any ≥ 1).
    pub tile_resolution_limit: u32,
    /// Use one tile per triangle when a triangle would get fewer tiles than this fraction (0..=1).
    pub direct_tile_mapping_threshold: f32,
    /// Always one tile per triangle.
    pub force_direct_tile_mapping: bool,
    /// The geometry's vertices will be updated (refit rather than rebuild).
    pub allow_update: bool,
    /// The geometry may receive lighting from a `DirectLightTransferTask`.
    pub allow_light_transfer_target: bool,
    /// BVH build trade-off.
    pub build_hint: BuildHint,
}

impl Default for GeometryInput {
    fn default() -> Self {
        GeometryInput {
            name: String::new(),
            components: Vec::new(),
            surfel_type: SurfelType::MeshColors,
            tile_unit_length: 1.0,
            tile_resolution_limit: 64,
            direct_tile_mapping_threshold: 0.7,
            force_direct_tile_mapping: false,
            allow_update: false,
            allow_light_transfer_target: false,
            build_hint: BuildHint::Auto,
        }
    }
}

/// Registers or updates a geometry.
#[derive(Debug, Clone)]
pub struct GeometryTask {
    /// Register or update.
    pub operation: TaskOperation,
    /// The handle from `ExecuteContext::create_geometry_handle`.
    pub handle: GeometryHandle,
    /// The mesh.
    pub input: GeometryInput,
}

/// Bits of [`InstanceInput::inclusion_mask`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct InstanceInclusionMask(pub u32);

impl InstanceInclusionMask {
    /// Receives direct lighting injection.
    pub const DIRECT_LIGHT_INJECTION_TARGET: Self = Self(1);
    /// Visible to traced rays.
    pub const VISIBLE_IN_RT: Self = Self(2);
    /// Every bit the SDK defines.
    pub const ALL: Self = Self(3);
    /// Whether every bit of `other` is set.
    pub fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }
}

impl std::ops::BitOr for InstanceInclusionMask {
    type Output = Self;
    fn bitor(self, rhs: Self) -> Self {
        Self(self.0 | rhs.0)
    }
}

impl Default for InstanceInclusionMask {
    fn default() -> Self {
        Self::ALL
    }
}

/// Places a geometry in the world.
#[derive(Debug, Clone)]
pub struct InstanceInput {
    /// The geometry instanced.
    pub geometry: GeometryHandle,
    /// Object-to-world transform. See [`crate::affine_from_row_major_3x4`] for C-style inputs.
    pub transform: Affine3A,
    /// Which SDK passes see the instance.
    pub inclusion_mask: InstanceInclusionMask,
    /// Whether the instance is in the TLAS at all.
    pub participating_in_tlas: bool,
    /// Colour a new lighting cache starts with (linear RGB, alpha unused); finite, ≥ 0.
    pub initial_tile_color: Vec4,
    /// A name for logs and errors.
    pub name: String,
}

impl InstanceInput {
    /// An instance of `geometry` at `transform` with the reference's defaults.
    pub fn new(geometry: GeometryHandle, transform: Affine3A) -> Self {
        InstanceInput {
            geometry,
            transform,
            inclusion_mask: InstanceInclusionMask::default(),
            participating_in_tlas: true,
            initial_tile_color: Vec4::ZERO,
            name: String::new(),
        }
    }
}

/// Registers or updates an instance.
#[derive(Debug, Clone)]
pub struct InstanceTask {
    /// Register or update.
    pub operation: TaskOperation,
    /// The handle from `ExecuteContext::create_instance_handle`.
    pub handle: InstanceHandle,
    /// Placement and flags.
    pub input: InstanceInput,
}

/// How a [`BvhBuildTask`] brings the TLAS up to date (see the reference's TLAS refit tutorial:
/// a refit is cheaper than a rebuild, but its boxes loosen as instances move apart).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TlasUpdate {
    /// Refit when only instance transforms changed since the last build, and fewer than
    /// [`TlasUpdate::AUTO_REBUILD_AFTER_REFITS`] refits followed the last rebuild; otherwise
    /// rebuild.
    #[default]
    Auto,
    /// Always rebuild.
    Rebuild,
    /// Refit whenever possible: rebuilds only when instances were added or removed, or a BLAS
    /// was (re)built, since the last build.
    Refit,
}

impl TlasUpdate {
    /// Refits in a row after which [`TlasUpdate::Auto`] rebuilds to restore tree quality.
    pub const AUTO_REBUILD_AFTER_REFITS: u32 = 16;
}

/// Controls how much BVH building one GPU task does. BLASes are built only by a task holding
/// one (as the reference): without it, geometry registered or updated waits, in order, for a
/// later task that has one. The TLAS is brought up to date in every task that changed an
/// instance (or built a BLAS), unless this task's `build_tlas` is false.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BvhBuildTask {
    /// Most BLAS builds (and refits) in this GPU task (≥ 1); the rest wait, in order, for later
    /// tasks.
    pub max_blas_build_count: u32,
    /// Build or refit the TLAS in this task when an instance or a BLAS it uses changed; `false`
    /// defers that, and the instance data rays see, to the next task that updates the TLAS (rays
    /// keep seeing the previous placements, consistently).
    pub build_tlas: bool,
    /// Rebuild or refit the TLAS.
    pub tlas_update: TlasUpdate,
}

impl Default for BvhBuildTask {
    fn default() -> Self {
        BvhBuildTask {
            max_blas_build_count: 4,
            build_tlas: true,
            tlas_update: TlasUpdate::Auto,
        }
    }
}

/// Any BVH task.
#[derive(Debug, Clone)]
pub enum BvhTask {
    /// See [`GeometryTask`].
    Geometry(GeometryTask),
    /// See [`InstanceTask`].
    Instance(InstanceTask),
    /// See [`BvhBuildTask`].
    Build(BvhBuildTask),
    /// See [`super::SkinningTask`]: recorded before every geometry task of its container.
    Skin(Box<super::SkinningTask>),
}

impl From<GeometryTask> for BvhTask {
    fn from(t: GeometryTask) -> Self {
        BvhTask::Geometry(t)
    }
}
impl From<InstanceTask> for BvhTask {
    fn from(t: InstanceTask) -> Self {
        BvhTask::Instance(t)
    }
}
impl From<super::SkinningTask> for BvhTask {
    fn from(t: super::SkinningTask) -> Self {
        BvhTask::Skin(Box::new(t))
    }
}
impl From<BvhBuildTask> for BvhTask {
    fn from(t: BvhBuildTask) -> Self {
        BvhTask::Build(t)
    }
}

/// Converts the reference's row-major 3x4 matrix (`m[row][col]`, translation in column 3) into
/// the SDK's [`Affine3A`].
pub fn affine_from_row_major_3x4(m: [[f32; 4]; 3]) -> Affine3A {
    Affine3A::from_cols_array(&[
        m[0][0], m[1][0], m[2][0], m[0][1], m[1][1], m[2][1], m[0][2], m[1][2], m[2][2], m[0][3],
        m[1][3], m[2][3],
    ])
}
