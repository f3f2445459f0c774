//! Field validation run by `build_gpu_task` before anything is recorded. The rules are listed in
//! the crate documentation's validation table; each returns [`Error::InvalidInput`] naming the
//! task, field and value.

use crate::error::{Error, Result};
use crate::tasks::*;

/// wgpu's copy alignment: buffer copies need 4-byte offsets and sizes.
pub(crate) const COPY_ALIGN: u64 = wgpu::COPY_BUFFER_ALIGNMENT;

/// The aligned byte range `[start, end)` to copy for `len` bytes (`count` elements) at `offset`,
/// or an error when it does not fit the buffer. Unaligned inputs are widened to 4 bytes (the
/// shader skips the slack).
///
/// Data running past the buffer's end is blamed on `{field}.offset`, or on `{field}.count` when
/// the offset is 0 (then the count, not the offset, asks for too much).
pub(crate) fn copy_range(
    task: &'static str,
    field: &str,
    buffer: &wgpu::Buffer,
    offset: u64,
    (count, len): (u32, u64),
) -> Result<(u64, u64)> {
    copy_range_blaming(task, field, Blame::Count, buffer, offset, (count, len))
}

/// The field [`copy_range_blaming`] names when the data does not fit from offset 0 (or its
/// unaligned end needs padding).
#[derive(Clone, Copy)]
enum Blame {
    /// The input's own `count` field.
    Count,
    /// Its `buffer`: for inputs without a count, whose elements are counted by another field
    /// (one texture coordinate per vertex, one flag per triangle); naming a `count` the caller
    /// cannot find would mislead.
    Buffer,
}

/// [`copy_range`], naming `blame` (in `field`) when the data does not fit from offset 0.
fn copy_range_blaming(
    task: &'static str,
    field: &str,
    blame: Blame,
    buffer: &wgpu::Buffer,
    offset: u64,
    (count, len): (u32, u64),
) -> Result<(u64, u64)> {
    if !buffer.usage().contains(wgpu::BufferUsages::COPY_SRC) {
        return Err(Error::input(
            task,
            format!("{field}.buffer"),
            buffer.usage(),
            "the SDK copies from this buffer inside your encoder: create it with BufferUsages::COPY_SRC",
        ));
    }
    let size = buffer.size();
    // Only built on error, so a valid input formats no field name.
    let too_much = |reason: String| match blame {
        Blame::Count => Error::input(task, format!("{field}.count"), count, reason),
        Blame::Buffer => Error::input(
            task,
            format!("{field}.buffer"),
            format!("{size} bytes"),
            reason,
        ),
    };
    let end = offset.checked_add(len).filter(|&e| e <= size);
    let Some(end) = end else {
        return Err(if offset == 0 {
            too_much(format!(
                "these {count} elements take {len} bytes, more than the buffer's {size}"
            ))
        } else {
            Error::input(
                task,
                format!("{field}.offset"),
                offset,
                format!("{len} bytes from this offset exceed the buffer's {size} bytes"),
            )
        });
    };
    let start = offset - offset % COPY_ALIGN;
    let aligned_end = end.div_ceil(COPY_ALIGN) * COPY_ALIGN;
    if aligned_end > size {
        return Err(too_much(
            "the data ends within 4 bytes of the buffer's end at an unaligned position; pad the buffer to a multiple of 4 bytes".into(),
        ));
    }
    Ok((start, aligned_end))
}

/// Bytes `count` (≥ 1) elements of `size` bytes, `stride` apart, span; `None` past 2^64 bytes.
/// Stride and count are the caller's: a product past u64 must be refused, not wrap to a small
/// length a bounds check would accept.
fn strided_span(stride: u64, count: u32, size: u64) -> Option<u64> {
    stride
        .checked_mul(u64::from(count) - 1)
        .and_then(|b| b.checked_add(size))
}

// Scalar checks take the field as `prefix` + `name` and join them only on error, so validating a
// good task (every frame) formats no field names.

fn finite(task: &'static str, (prefix, name): (&str, &str), v: f32) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::input(
            task,
            format!("{prefix}{name}"),
            v,
            "must be finite",
        ))
    }
}

fn in_range(
    task: &'static str,
    (prefix, name): (&str, &str),
    v: f32,
    lo: f32,
    hi: f32,
) -> Result<()> {
    if v >= lo && v <= hi {
        Ok(())
    } else {
        Err(Error::input(
            task,
            format!("{prefix}{name}"),
            v,
            format!("must be in [{lo}, {hi}]"),
        ))
    }
}

/// `> 0`; NaN fails, +∞ passes (callers that forbid ∞ check `finite` too).
fn positive(task: &'static str, (prefix, name): (&str, &str), v: f32) -> Result<()> {
    if v > 0.0 {
        Ok(())
    } else {
        Err(Error::input(
            task,
            format!("{prefix}{name}"),
            v,
            "must be > 0",
        ))
    }
}

/// Bytes a component reads from its vertex buffer, and the triangles it contributes.
pub(crate) struct ComponentExtent {
    pub vertex_bytes: (u64, u64),
    pub index_bytes: Option<(u64, u64)>,
    pub triangles: u32,
    /// The copy range of its opacity source's buffer (the coordinates of a texture source, the
    /// flags of a per-triangle one), when it has one.
    pub opacity_bytes: Option<(u64, u64)>,
}

/// Validates a geometry input; returns each component's copy ranges.
pub(crate) fn geometry_input(input: &GeometryInput) -> Result<Vec<ComponentExtent>> {
    const T: &str = "GeometryTask";
    if input.components.is_empty() {
        return Err(Error::input(
            T,
            "input.components",
            "[]",
            "needs at least one component",
        ));
    }
    finite(T, ("input.", "tile_unit_length"), input.tile_unit_length)?;
    if input.tile_unit_length <= 0.0 {
        return Err(Error::input(
            T,
            "input.tile_unit_length",
            input.tile_unit_length,
            "must be > 0 (world units)",
        ));
    }
    if input.tile_resolution_limit == 0 {
        return Err(Error::input(
            T,
            "input.tile_resolution_limit",
            0,
            "must be ≥ 1",
        ));
    }
    if !(0.0..=1.0).contains(&input.direct_tile_mapping_threshold) {
        return Err(Error::input(
            T,
            "input.direct_tile_mapping_threshold",
            input.direct_tile_mapping_threshold,
            "must be in [0, 1]",
        ));
    }
    let extents: Vec<ComponentExtent> = input
        .components
        .iter()
        .enumerate()
        .map(|(i, c)| component(&format!("input.components[{i}]"), c))
        .collect::<Result<_>>()?;
    // Callers sum the components' triangles as u32. Each component's count is bounded by its
    // buffers, but components may share one buffer: refuse a sum that does not fit.
    let total = extents
        .iter()
        .try_fold(0_u32, |sum, e| sum.checked_add(e.triangles));
    if total.is_none() {
        return Err(Error::input(
            T,
            "input.components",
            format!("{} components", extents.len()),
            "their triangles add up to more than 2^32 - 1",
        ));
    }
    Ok(extents)
}

/// Validates a component's vertex buffer (`f` names the component); returns its copy range.
fn vertex_range(f: &str, vb: &VertexBufferInput) -> Result<(u64, u64)> {
    const T: &str = "GeometryTask";
    if vb.stride < vb.format.size() {
        return Err(Error::input(
            T,
            format!("{f}.vertex_buffer.stride"),
            vb.stride,
            format!("must be ≥ {} bytes for {:?}", vb.format.size(), vb.format),
        ));
    }
    if vb.count == 0 {
        return Err(Error::input(
            T,
            format!("{f}.vertex_buffer.count"),
            0,
            "must be ≥ 1",
        ));
    }
    let vlen = strided_span(vb.stride, vb.count, vb.format.size());
    let Some(vlen) = vlen else {
        return Err(Error::input(
            T,
            format!("{f}.vertex_buffer.stride"),
            vb.stride,
            format!(
                "{} vertices this far apart span more than 2^64 bytes",
                vb.count
            ),
        ));
    };
    copy_range(
        T,
        &format!("{f}.vertex_buffer"),
        &vb.buffer,
        vb.offset,
        (vb.count, vlen),
    )
}

/// Validates one component (`f` names it); returns its copy ranges and triangles.
fn component(f: &str, c: &GeometryComponent) -> Result<ComponentExtent> {
    const T: &str = "GeometryTask";
    let vb = &c.vertex_buffer;
    let vertex_bytes = vertex_range(f, vb)?;
    if let Some(t) = c.transform {
        if !t.is_finite() {
            return Err(Error::input(
                T,
                format!("{f}.transform"),
                t,
                "must be finite",
            ));
        }
    }
    let (total, index_bytes) = match &c.index_buffer {
        Some(ib) => {
            if ib.offset % ib.format.size() != 0 {
                return Err(Error::input(
                    T,
                    format!("{f}.index_buffer.offset"),
                    ib.offset,
                    format!(
                        "must be a multiple of the index size ({} bytes)",
                        ib.format.size()
                    ),
                ));
            }
            if ib.count % 3 != 0 || ib.count == 0 {
                return Err(Error::input(
                    T,
                    format!("{f}.index_buffer.count"),
                    ib.count,
                    "must be a non-zero multiple of 3",
                ));
            }
            let len = ib.count as u64 * ib.format.size();
            let r = copy_range(
                T,
                &format!("{f}.index_buffer"),
                &ib.buffer,
                ib.offset,
                (ib.count, len),
            )?;
            (ib.count, Some(r))
        }
        None => {
            if !vb.count.is_multiple_of(3) {
                return Err(Error::input(
                    T,
                    format!("{f}.vertex_buffer.count"),
                    vb.count,
                    "a non-indexed triangle list needs a multiple of 3 vertices",
                ));
            }
            (vb.count, None)
        }
    };
    let triangles = match c.index_range {
        Some((first, count)) => {
            if first % 3 != 0 || count % 3 != 0 || count == 0 {
                return Err(Error::input(
                    T,
                    format!("{f}.index_range"),
                    (first, count),
                    "first and count must be multiples of 3, count > 0",
                ));
            }
            if first.checked_add(count).is_none_or(|e| e > total) {
                return Err(Error::input(
                    T,
                    format!("{f}.index_range"),
                    (first, count),
                    format!("exceeds the component's {total} indices"),
                ));
            }
            count / 3
        }
        None => total / 3,
    };
    // Checked last: a per-triangle source holds one flag per triangle counted above.
    let opacity_bytes = match &c.opacity {
        Some(o) => Some(opacity::component(f, o, vb.count, triangles)?),
        None => None,
    };
    Ok(ComponentExtent {
        vertex_bytes,
        index_bytes,
        triangles,
        opacity_bytes,
    })
}

/// Validates an instance input's own fields (the geometry handle is checked by the context).
pub(crate) fn instance_input(input: &InstanceInput) -> Result<()> {
    const T: &str = "InstanceTask";
    if !input.transform.is_finite() {
        return Err(Error::input(
            T,
            "input.transform",
            input.transform,
            "must be finite",
        ));
    }
    if input.inclusion_mask.0 & !InstanceInclusionMask::ALL.0 != 0 {
        return Err(Error::input(
            T,
            "input.inclusion_mask",
            format!("{:#x}", input.inclusion_mask.0),
            "only DIRECT_LIGHT_INJECTION_TARGET (1) and VISIBLE_IN_RT (2) are defined",
        ));
    }
    let c = input.initial_tile_color;
    if !c.is_finite() || c.min_element() < 0.0 {
        return Err(Error::input(
            T,
            "input.initial_tile_color",
            c,
            "must be finite and ≥ 0",
        ));
    }
    Ok(())
}

/// Validates a BVH build task.
pub(crate) fn bvh_build(task: &BvhBuildTask) -> Result<()> {
    if task.max_blas_build_count == 0 {
        return Err(Error::input(
            "BvhBuildTask",
            "max_blas_build_count",
            0,
            "must be ≥ 1",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod fuzz;
mod opacity;
mod render;
mod skinning;
pub(crate) use render::render_task;
pub(crate) use skinning::skinning_task;
