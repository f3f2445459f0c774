//! Validation of a component's opacity ([`ComponentOpacity`]): the source's scalars, its texture
//! and the buffer it is baked from. Runs with the component's other checks, before anything is
//! recorded, so a bad cutout never reaches the baking pass.

use super::{copy_range_blaming, strided_span, Blame};
use crate::error::{Error, Result};
use crate::tasks::{ComponentOpacity, OpacitySource, UvBufferInput};

/// The task whose components carry opacity.
const T: &str = "GeometryTask";

/// Validates component `f`'s opacity, for its `vertices` vertices and `triangles` triangles
/// (after its `index_range`); returns the copy range of the source's buffer (the coordinates of
/// a texture source, the flags of a per-triangle one).
pub(super) fn component(
    f: &str,
    o: &ComponentOpacity,
    vertices: u32,
    triangles: u32,
) -> Result<(u64, u64)> {
    match &o.source {
        OpacitySource::Texture {
            texture,
            uvs,
            channel,
            factor,
            cutoff,
        } => {
            // Only a texture is baked at a resolution: a per-triangle flag ignores the level.
            if o.micromap_level > ComponentOpacity::MAX_MICROMAP_LEVEL {
                return Err(Error::input(
                    T,
                    format!("{f}.opacity.micromap_level"),
                    o.micromap_level,
                    format!("must be in 0..={}", ComponentOpacity::MAX_MICROMAP_LEVEL),
                ));
            }
            scalars(f, *channel, *factor, *cutoff)?;
            texture_view(f, texture)?;
            uv_range(f, uvs, vertices)
        }
        OpacitySource::PerTriangle { buffer, offset } => {
            // The flags are read as u32 words: a misaligned offset would split them.
            if offset % 4 != 0 {
                return Err(Error::input(
                    T,
                    format!("{f}.opacity.source.offset"),
                    offset,
                    "must be a multiple of 4 (one u32 a triangle)",
                ));
            }
            // At most 4 × (2^32 - 1): cannot overflow u64.
            let len = 4 * u64::from(triangles);
            // No `count` field here: the triangle count is the component's, so a buffer too
            // short for it is the buffer's fault.
            copy_range_blaming(
                T,
                &format!("{f}.opacity.source"),
                Blame::Buffer,
                buffer,
                *offset,
                (triangles, len),
            )
        }
    }
}

/// Checks a texture source's channel, factor and cutoff (component `f`).
fn scalars(f: &str, channel: u32, factor: f32, cutoff: f32) -> Result<()> {
    if channel > 3 {
        return Err(Error::input(
            T,
            format!("{f}.opacity.source.channel"),
            channel,
            "must be 0..=3 (r, g, b, a)",
        ));
    }
    // A NaN or infinite alpha would make every micro-triangle's comparison meaningless.
    if !(factor.is_finite() && factor >= 0.0) {
        return Err(Error::input(
            T,
            format!("{f}.opacity.source.factor"),
            factor,
            "must be finite and ≥ 0",
        ));
    }
    // Written so that NaN fails too.
    if !(0.0..=1.0).contains(&cutoff) {
        return Err(Error::input(
            T,
            format!("{f}.opacity.source.cutoff"),
            cutoff,
            "must be in [0, 1]",
        ));
    }
    Ok(())
}

/// Checks that a texture source's view can be read as alpha while baking (component `f`): a
/// sampled, single-sample 2D texture with a float sample type.
fn texture_view(f: &str, view: &wgpu::TextureView) -> Result<()> {
    let texture = view.texture();
    let field = || format!("{f}.opacity.source.texture");
    if !texture
        .usage()
        .contains(wgpu::TextureUsages::TEXTURE_BINDING)
    {
        return Err(Error::input(
            T,
            field(),
            texture.usage(),
            "the SDK reads it while baking: create it with TextureUsages::TEXTURE_BINDING",
        ));
    }
    if texture.dimension() != wgpu::TextureDimension::D2 {
        return Err(Error::input(
            T,
            field(),
            texture.dimension(),
            "must be a 2D texture",
        ));
    }
    if texture.sample_count() != 1 {
        return Err(Error::input(
            T,
            field(),
            texture.sample_count(),
            "must have sample_count 1 (not multisampled)",
        ));
    }
    // Depth, stencil and integer textures bind with other sample types than the baking pass's
    // float one; combined depth-stencil and multi-planar formats have none without an aspect.
    let format = texture.format();
    if !matches!(
        format.sample_type(None, None),
        Some(wgpu::TextureSampleType::Float { .. })
    ) {
        return Err(Error::input(
            T,
            field(),
            format,
            format!("{format:?} has no float sample type: use a colour format such as Rgba8Unorm, R8Unorm or Rgba16Float"),
        ));
    }
    Ok(())
}

/// Checks a texture source's coordinates (component `f`): one per vertex, as many as its
/// `vertices`, indexed like the positions. Returns their copy range.
fn uv_range(f: &str, uvs: &UvBufferInput, vertices: u32) -> Result<(u64, u64)> {
    let size = uvs.format.size();
    if uvs.stride < size {
        return Err(Error::input(
            T,
            format!("{f}.opacity.source.uvs.stride"),
            uvs.stride,
            format!("must be ≥ {size} bytes for {:?}", uvs.format),
        ));
    }
    let Some(len) = strided_span(uvs.stride, vertices, size) else {
        return Err(Error::input(
            T,
            format!("{f}.opacity.source.uvs.stride"),
            uvs.stride,
            format!("{vertices} coordinates this far apart span more than 2^64 bytes"),
        ));
    };
    // No `count` field here: the vertex count is the vertex buffer's, so a buffer too short for
    // it is the buffer's fault.
    copy_range_blaming(
        T,
        &format!("{f}.opacity.source.uvs"),
        Blame::Buffer,
        &uvs.buffer,
        uvs.offset,
        (vertices, len),
    )
}
