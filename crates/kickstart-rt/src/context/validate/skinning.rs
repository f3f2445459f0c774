//! Validation of a [`SkinningTask`]: every attribute's layout, range, usage and binding window,
//! the matrices and weights, and the output's separation from the inputs. Runs before anything
//! is recorded, so the pass reads and writes only inside the caller's ranges.

use crate::error::{Error, Result};
use crate::scene::skin_layout::{strided_end, window, WORKGROUP};
use crate::tasks::{SkinningTask, VertexFormat};

/// The task named in errors.
const T: &str = "SkinningTask";

/// One strided attribute as the checks see it.
struct Attribute<'a> {
    field: &'static str,
    buffer: &'a wgpu::Buffer,
    offset: u64,
    stride: u64,
    /// Bytes of one value.
    size: u64,
    /// Values read: vertices, or vertices × targets (their span computed by the caller).
    end: Option<u64>,
}

/// Validates `t` against the device's `limits`.
pub(crate) fn skinning_task(t: &SkinningTask, limits: &wgpu::Limits) -> Result<()> {
    let most = u64::from(WORKGROUP) * u64::from(limits.max_compute_workgroups_per_dimension);
    if u64::from(t.vertex_count) > most {
        return Err(Error::input(
            T,
            "vertex_count",
            t.vertex_count,
            format!("one task poses at most {most} vertices (one dispatch); split the mesh"),
        ));
    }
    let rest_size = match t.rest_positions.format {
        VertexFormat::Float32x3 => 12,
        VertexFormat::Float32x4 => 16,
        other => {
            return Err(Error::input(
                T,
                "rest_positions.format",
                other,
                "skinning reads Float32x3 or Float32x4 positions",
            ))
        }
    };
    matrices(t)?;
    morph_weights(t)?;
    if t.vertex_count == 0 {
        return Ok(());
    }
    for a in attributes(t, rest_size) {
        attribute(&a, limits)?;
    }
    separate_output(t)
}

/// The task's attributes: rest positions, joints, weights, morph deltas, output.
fn attributes(t: &SkinningTask, rest_size: u64) -> Vec<Attribute<'_>> {
    let n = t.vertex_count;
    let rp = &t.rest_positions;
    let mut out = vec![Attribute {
        field: "rest_positions",
        buffer: &rp.buffer,
        offset: rp.offset,
        stride: rp.stride,
        size: rest_size,
        end: strided_end(rp.offset, rp.stride, n, rest_size),
    }];
    if let Some(inf) = &t.influences {
        let (j, w) = (&inf.joints, &inf.weights);
        out.push(Attribute {
            field: "influences.joints",
            buffer: &j.buffer,
            offset: j.offset,
            stride: j.stride,
            size: j.format.size(),
            end: strided_end(j.offset, j.stride, n, j.format.size()),
        });
        out.push(Attribute {
            field: "influences.weights",
            buffer: &w.buffer,
            offset: w.offset,
            stride: w.stride,
            size: w.format.size(),
            end: strided_end(w.offset, w.stride, n, w.format.size()),
        });
    }
    if let Some(m) = t.morph_targets.as_ref().filter(|m| m.count > 0) {
        let last = m
            .target_stride
            .checked_mul(u64::from(m.count - 1))
            .and_then(|l| m.offset.checked_add(l));
        out.push(Attribute {
            field: "morph_targets",
            buffer: &m.buffer,
            offset: m.offset,
            stride: m.stride,
            size: 12,
            end: last.and_then(|l| strided_end(l, m.stride, n, 12)),
        });
    }
    let o = &t.output;
    out.push(Attribute {
        field: "output",
        buffer: &o.buffer,
        offset: o.offset,
        stride: o.stride,
        size: 12,
        end: strided_end(o.offset, o.stride, n, 12),
    });
    out
}

/// Checks one attribute's alignment, stride, usage, range and binding window.
fn attribute(a: &Attribute<'_>, limits: &wgpu::Limits) -> Result<()> {
    let f = a.field;
    // The shader addresses whole words.
    if !a.offset.is_multiple_of(4) {
        return Err(Error::input(
            T,
            format!("{f}.offset"),
            a.offset,
            "must be a multiple of 4",
        ));
    }
    if !a.stride.is_multiple_of(4) || a.stride < a.size {
        return Err(Error::input(
            T,
            format!("{f}.stride"),
            a.stride,
            format!(
                "must be a multiple of 4 and at least {} (one value)",
                a.size
            ),
        ));
    }
    if !a.buffer.usage().contains(wgpu::BufferUsages::STORAGE) {
        return Err(Error::input(
            T,
            format!("{f}.buffer"),
            a.buffer.usage(),
            "the skinning pass binds this buffer: create it with BufferUsages::STORAGE",
        ));
    }
    let size = a.buffer.size();
    let Some(end) = a.end.filter(|&e| e <= size) else {
        return Err(Error::input(
            T,
            format!("{f}.offset"),
            a.offset,
            format!("the values from this offset run past the buffer's {size} bytes"),
        ));
    };
    let align = u64::from(limits.min_storage_buffer_offset_alignment);
    let limit = limits.max_storage_buffer_binding_size;
    match window(a.offset, end, align) {
        Some(w) if w.size <= limit => Ok(()),
        _ => Err(Error::OutOfDeviceMemory {
            what: format!("{T}.{f}"),
            bytes: end - a.offset,
            limit,
        }),
    }
}

/// Joint matrices: within the cap, finite, and present when the task has influences.
fn matrices(t: &SkinningTask) -> Result<()> {
    let n = t.joint_matrices.len();
    if n > SkinningTask::MAX_JOINTS {
        return Err(Error::input(
            T,
            "joint_matrices",
            format!("{n} matrices"),
            format!("at most {} joints a task", SkinningTask::MAX_JOINTS),
        ));
    }
    if t.influences.is_some() && n == 0 {
        return Err(Error::input(
            T,
            "joint_matrices",
            "0 matrices",
            "influences name joints: give one matrix a joint",
        ));
    }
    for (k, m) in t.joint_matrices.iter().enumerate() {
        if !m.is_finite() {
            return Err(Error::input(
                T,
                format!("joint_matrices[{k}]"),
                m,
                "must be finite",
            ));
        }
    }
    Ok(())
}

/// Morph weights: one a target, finite, within the cap.
fn morph_weights(t: &SkinningTask) -> Result<()> {
    let targets = t.morph_targets.as_ref().map_or(0, |m| m.count);
    if targets > SkinningTask::MAX_MORPH_TARGETS {
        return Err(Error::input(
            T,
            "morph_targets.count",
            targets,
            format!("at most {} targets", SkinningTask::MAX_MORPH_TARGETS),
        ));
    }
    if t.morph_weights.len() != targets as usize {
        return Err(Error::input(
            T,
            "morph_weights",
            format!("{} weights", t.morph_weights.len()),
            format!("needs one weight a morph target ({targets})"),
        ));
    }
    if let Some(m) = &t.morph_targets {
        if m.target_stride % 4 != 0 {
            return Err(Error::input(
                T,
                "morph_targets.target_stride",
                m.target_stride,
                "must be a multiple of 4",
            ));
        }
    }
    if let Some((k, w)) = t
        .morph_weights
        .iter()
        .enumerate()
        .find(|(_, w)| !w.is_finite())
    {
        return Err(Error::input(
            T,
            format!("morph_weights[{k}]"),
            w,
            "must be finite",
        ));
    }
    Ok(())
}

/// The output buffer is none of the inputs: one dispatch cannot bind a buffer for reading and
/// writing at once.
fn separate_output(t: &SkinningTask) -> Result<()> {
    let out = &t.output.buffer;
    let mut inputs = vec![("rest_positions", &t.rest_positions.buffer)];
    if let Some(inf) = &t.influences {
        inputs.push(("influences.joints", &inf.joints.buffer));
        inputs.push(("influences.weights", &inf.weights.buffer));
    }
    if let Some(m) = &t.morph_targets {
        inputs.push(("morph_targets", &m.buffer));
    }
    match inputs.into_iter().find(|(_, b)| *b == out) {
        Some((field, _)) => Err(Error::input(
            T,
            "output.buffer",
            format!("the buffer of {field}"),
            "the output must be a buffer of its own (the pass reads its inputs while writing it)",
        )),
        None => Ok(()),
    }
}
