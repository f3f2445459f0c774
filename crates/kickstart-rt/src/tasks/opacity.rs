//! Cutout (alpha-tested) geometry: what makes a component's triangles let rays through.
//!
//! The SDK bakes each cutout triangle's opacity into an **opacity micro-map** when the geometry
//! is ingested: the triangle is split into `4^level` micro-triangles (a regular grid of `2^level`
//! segments per edge), each one bit, opaque or not, taken at its centre. Every traversal then
//! tests the bit under a candidate hit's barycentrics: no texture is bound while tracing (it
//! works on a device with `Features::empty()` and `Limits::default()`, and in WebGPU), and
//! geometry without opacity pays one comparison per triangle hit. Layout and costs:
//! `docs/ray-tracing-core.md` ("Cutout geometry").

/// Format of a 2-component texture coordinate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UvFormat {
    /// Two `f32`.
    #[default]
    Float32x2,
    /// Two `f16`.
    Float16x2,
    /// Two unsigned-normalised `u16` (0..=65535 → 0..=1).
    Unorm16x2,
}

impl UvFormat {
    /// Bytes one coordinate pair occupies.
    pub fn size(self) -> u64 {
        match self {
            UvFormat::Float32x2 => 8,
            UvFormat::Float16x2 | UvFormat::Unorm16x2 => 4,
        }
    }
}

/// Texture coordinates of a component's vertices, in an application buffer (needs `COPY_SRC`):
/// one per vertex of its `vertex_buffer`, indexed by the same indices.
#[derive(Debug, Clone)]
pub struct UvBufferInput {
    /// The buffer; the SDK keeps a clone while GPU work reads it.
    pub buffer: wgpu::Buffer,
    /// Byte offset of vertex 0's coordinates.
    pub offset: u64,
    /// Bytes between consecutive vertices' coordinates; at least the format's size.
    pub stride: u64,
    /// Coordinate format.
    pub format: UvFormat,
}

/// Where a component's opacity comes from.
#[derive(Debug, Clone)]
pub enum OpacitySource {
    /// glTF `alphaMode: MASK`: alpha = `factor` × the texture's `channel` (0 = r … 3 = a) at the
    /// surface's coordinates (the texel they fall in, mip level 0, repeating outside 0..1);
    /// opaque where alpha ≥ `cutoff`.
    Texture {
        /// A 2D view of a texture with a float sample type (`Rgba8Unorm`, `Rgba8UnormSrgb`,
        /// `R8Unorm`, `Rgba16Float`, …) and `TEXTURE_BINDING` usage; kept while GPU work reads
        /// it.
        texture: wgpu::TextureView,
        /// The coordinates the texture is read at (glTF `TEXCOORD_n`, after
        /// `KHR_texture_transform` if the material has one: apply it to the coordinates).
        uvs: UvBufferInput,
        /// The channel holding alpha: 0..=3.
        channel: u32,
        /// Multiplies the texture's alpha (glTF `baseColorFactor.a`); finite, ≥ 0.
        factor: f32,
        /// Opaque where `factor × alpha ≥ cutoff` (glTF `alphaCutoff`, default 0.5); in 0..=1.
        cutoff: f32,
    },
    /// One `u32` per triangle of the component (after its `index_range`), in an application
    /// buffer with `COPY_SRC` usage: 0 lets rays through, anything else is opaque.
    PerTriangle {
        /// The buffer.
        buffer: wgpu::Buffer,
        /// Byte offset of the first triangle's flag (a multiple of 4).
        offset: u64,
    },
}

/// A component's opacity: its source and the resolution of its triangles' micro-maps.
#[derive(Debug, Clone)]
pub struct ComponentOpacity {
    /// Where the opacity comes from.
    pub source: OpacitySource,
    /// Each triangle's micro-map has `4^micromap_level` micro-triangles (bits), 0..=
    /// [`ComponentOpacity::MAX_MICROMAP_LEVEL`]. Pick it so that a micro-triangle is smaller
    /// than a texel on the triangle: a leaf card whose two triangles span a 64×64-texel cutout
    /// needs level 6 (4096 micro-triangles over 2048 texels). A geometry's triangles all take
    /// its components' largest level: 1 word (4 bytes) a triangle up to level 2, then
    /// `4^level / 8` bytes. Ignored by [`OpacitySource::PerTriangle`] alone (level 0).
    pub micromap_level: u32,
}

impl ComponentOpacity {
    /// The finest micro-map: 4096 micro-triangles (512 bytes) a triangle.
    pub const MAX_MICROMAP_LEVEL: u32 = 6;
    /// The level [`ComponentOpacity::texture`] picks: 256 micro-triangles (32 bytes) a
    /// triangle.
    pub const DEFAULT_MICROMAP_LEVEL: u32 = 4;

    /// The glTF `MASK` model with the default micro-map level: `texture`'s alpha channel at
    /// `uvs`, times `factor`, against `cutoff`.
    pub fn texture(
        texture: wgpu::TextureView,
        uvs: UvBufferInput,
        factor: f32,
        cutoff: f32,
    ) -> Self {
        ComponentOpacity {
            source: OpacitySource::Texture {
                texture,
                uvs,
                channel: 3,
                factor,
                cutoff,
            },
            micromap_level: Self::DEFAULT_MICROMAP_LEVEL,
        }
    }

    /// A flag per triangle (`buffer` from byte `offset`: one `u32` each, 0 = lets rays
    /// through).
    pub fn per_triangle(buffer: wgpu::Buffer, offset: u64) -> Self {
        ComponentOpacity {
            source: OpacitySource::PerTriangle { buffer, offset },
            micromap_level: 0,
        }
    }

    /// The micro-map level the component's triangles need: its `micromap_level`, or 0 for a
    /// per-triangle flag.
    pub(crate) fn level(&self) -> u32 {
        match self.source {
            OpacitySource::Texture { .. } => self.micromap_level,
            OpacitySource::PerTriangle { .. } => 0,
        }
    }
}

/// `u32` words of one triangle's micro-map at `level`: one up to level 2 (16 bits used), then
/// `4^level / 32`.
pub(crate) fn micromap_words(level: u32) -> u32 {
    (1u32 << (2 * level.min(ComponentOpacity::MAX_MICROMAP_LEVEL))).div_ceil(32)
}
