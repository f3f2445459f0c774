//! The skinning pass (`shaders/scene/skinning.wgsl`): poses the meshes of a GPU task's
//! [`SkinningTask`]s into their output buffers before the task's geometries read them. Every
//! input is read in place from the caller's buffers (no copies: a frame of characters would
//! otherwise stage their rest data every frame).

use crate::gpu::reflect::{ReflectedPipeline, ReflectedShader};
use crate::gpu::Recorder;
use crate::tasks::{JointFormat, SkinningTask, VertexFormat, WeightFormat};

/// Invocations of a skinning workgroup (`SKIN_WG`).
pub(crate) const WORKGROUP: u32 = 64;
/// Floats of one joint matrix in the pose buffer (three rows of four).
const MATRIX_FLOATS: usize = 12;

/// `Skin` in `shaders/scene/skinning.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Skin {
    vertex_count: u32,
    rest_word: u32,
    rest_stride: u32,
    joint_word: u32,
    joint_stride: u32,
    joint_format: u32,
    weight_word: u32,
    weight_stride: u32,
    weight_format: u32,
    joint_count: u32,
    morph_word: u32,
    morph_stride: u32,
    morph_target_stride: u32,
    morph_count: u32,
    morph_weight_at: u32,
    out_word: u32,
    out_stride: u32,
    joint_base: u32,
    _pad: [u32; 2],
}

/// A byte range of a caller's buffer bound as a storage window: it starts at an offset the
/// device can bind at, and `word` is the range's first word within it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Window {
    /// Bytes from the buffer's start to the window's.
    pub start: u64,
    /// Bytes the window spans (a multiple of 4).
    pub size: u64,
    /// Words from the window's start to the range's.
    pub word: u32,
}

/// The window binding bytes `offset..end` (`end > offset`, both multiples of 4) at the device's
/// storage offset alignment `align`; `None` when the word offset does not fit `u32`.
pub(crate) fn window(offset: u64, end: u64, align: u64) -> Option<Window> {
    let start = offset - offset % align.max(4);
    Some(Window {
        start,
        size: end.checked_sub(start)?.next_multiple_of(4),
        word: u32::try_from((offset - start) / 4).ok()?,
    })
}

/// The end of `count` strided values of `size` bytes from `offset` (`count > 0`; validated to
/// lie inside the buffer).
pub(crate) fn strided_end(offset: u64, stride: u64, count: u32, size: u64) -> Option<u64> {
    let last = stride.checked_mul(u64::from(count.checked_sub(1)?))?;
    offset.checked_add(last)?.checked_add(size)
}

/// The pose buffer's contents for `tasks`: each task's joint matrices (three rows of four floats
/// each), then its morph weights; returns the contents and each task's
/// `(first matrix, first weight)` index.
fn pose_data(tasks: &[&SkinningTask]) -> (Vec<f32>, Vec<(u32, u32)>) {
    let mut data = Vec::new();
    let mut at = Vec::with_capacity(tasks.len());
    for t in tasks {
        let first_matrix = data.len() / MATRIX_FLOATS;
        for m in &t.joint_matrices {
            let rows = m.transpose().to_cols_array();
            data.extend_from_slice(&rows[..MATRIX_FLOATS]);
        }
        let first_weight = data.len();
        data.extend_from_slice(&t.morph_weights);
        // The validation bounds joints and targets, so the indices fit.
        at.push((
            u32::try_from(first_matrix).unwrap_or(u32::MAX),
            u32::try_from(first_weight).unwrap_or(u32::MAX),
        ));
    }
    if data.is_empty() {
        data.push(0.0);
    }
    (data, at)
}

/// The skinning pass.
pub(crate) struct Skinner {
    pipeline: ReflectedPipeline,
}

/// The WGSL of the skinning pass, labelled.
pub(crate) fn shader_variants() -> Vec<(String, String)> {
    let shader = ReflectedShader::compose(&["scene/skinning"], &[]);
    vec![("scene/skinning".into(), shader.source().to_string())]
}

/// One bound input of a task: its buffer and window.
type Bound<'a> = (&'a wgpu::Buffer, Window);

impl Skinner {
    /// Creates the pipeline.
    pub fn new(device: &wgpu::Device) -> Self {
        let shader = ReflectedShader::compose(&["scene/skinning"], &[]);
        Skinner {
            pipeline: shader.pipeline(device, "kickstart-rt skinning", "skin_vertices"),
        }
    }

    /// Records one dispatch a task of `tasks`, all in one compute pass (validated: every range
    /// lies in its buffer, every window fits the device's binding size, vertex counts fit one
    /// dispatch).
    pub fn record(&self, rec: &mut Recorder<'_>, tasks: &[&SkinningTask]) {
        let align = u64::from(rec.device.limits().min_storage_buffer_offset_alignment);
        let (pose, at) = pose_data(tasks);
        let pose = rec.storage_init("kickstart-rt skinning pose", bytemuck::cast_slice(&pose));
        let mut groups = Vec::with_capacity(tasks.len());
        for (t, (first_matrix, first_weight)) in tasks.iter().zip(at) {
            if t.vertex_count == 0 {
                continue;
            }
            let Some((skin, inputs)) = params(t, align, first_weight) else {
                continue;
            };
            let skin = Skin {
                joint_base: first_matrix,
                ..skin
            };
            let uniform = rec.uniform("kickstart-rt skinning params", &skin);
            let pose_window = wgpu::BufferBinding {
                buffer: &pose,
                offset: 0,
                size: None,
            };
            let group = self.pipeline.bind_resources(
                rec.device,
                "kickstart-rt skinning",
                0,
                &[
                    ("skin", uniform.as_entire_binding()),
                    ("rest", bind(inputs[0])),
                    ("joints", bind(inputs[1])),
                    ("weights", bind(inputs[2])),
                    ("morphs", bind(inputs[3])),
                    ("pose", wgpu::BindingResource::Buffer(pose_window)),
                    ("posed", bind(inputs[4])),
                ],
            );
            groups.push((group, t.vertex_count.div_ceil(WORKGROUP)));
        }
        rec.dispatch_each("skinning", &self.pipeline.pipeline, &groups);
    }
}

/// The binding of an input's window.
fn bind<'a>((buffer, w): Bound<'a>) -> wgpu::BindingResource<'a> {
    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
        buffer,
        offset: w.start,
        size: wgpu::BufferSize::new(w.size),
    })
}

/// The parameters and bound windows (rest, joints, weights, morphs, output) of task `t`, whose
/// morph weights start at `first_weight` of the pose buffer; `None` when an address does not
/// fit 32-bit arithmetic (the validation refuses those tasks first).
fn params(t: &SkinningTask, align: u64, first_weight: u32) -> Option<(Skin, [Bound<'_>; 5])> {
    let n = t.vertex_count;
    let rest_size = match t.rest_positions.format {
        VertexFormat::Float32x4 => 16,
        _ => 12,
    };
    let rp = &t.rest_positions;
    let rest = window(
        rp.offset,
        strided_end(rp.offset, rp.stride, n, rest_size)?,
        align,
    )?;
    let out = &t.output;
    let posed = window(
        out.offset,
        strided_end(out.offset, out.stride, n, 12)?,
        align,
    )?;
    let mut skin = Skin {
        vertex_count: n,
        rest_word: rest.word,
        rest_stride: u32::try_from(rp.stride / 4).ok()?,
        out_word: posed.word,
        out_stride: u32::try_from(out.stride / 4).ok()?,
        morph_weight_at: first_weight,
        ..Skin::default()
    };
    let mut joints = (&rp.buffer, rest);
    let mut weights = (&rp.buffer, rest);
    if let Some(inf) = &t.influences {
        let (j, w) = (&inf.joints, &inf.weights);
        let jw = window(
            j.offset,
            strided_end(j.offset, j.stride, n, j.format.size())?,
            align,
        )?;
        let ww = window(
            w.offset,
            strided_end(w.offset, w.stride, n, w.format.size())?,
            align,
        )?;
        skin.joint_word = jw.word;
        skin.joint_stride = u32::try_from(j.stride / 4).ok()?;
        skin.joint_format = match j.format {
            JointFormat::Uint8x4 => 0,
            JointFormat::Uint16x4 => 1,
            JointFormat::Uint32x4 => 2,
        };
        skin.weight_word = ww.word;
        skin.weight_stride = u32::try_from(w.stride / 4).ok()?;
        skin.weight_format = match w.format {
            WeightFormat::Float32x4 => 0,
            WeightFormat::Unorm8x4 => 1,
            WeightFormat::Unorm16x4 => 2,
        };
        skin.joint_count = u32::try_from(t.joint_matrices.len()).ok()?;
        joints = (&j.buffer, jw);
        weights = (&w.buffer, ww);
    }
    let mut morphs = (&rp.buffer, rest);
    if let Some(m) = t.morph_targets.as_ref().filter(|m| m.count > 0) {
        let last_target = m.target_stride.checked_mul(u64::from(m.count - 1))?;
        let end = strided_end(m.offset.checked_add(last_target)?, m.stride, n, 12)?;
        // Targets may be stored in any order: the window covers the lowest to the highest.
        let mw = window(m.offset, end, align)?;
        skin.morph_word = mw.word;
        skin.morph_stride = u32::try_from(m.stride / 4).ok()?;
        skin.morph_target_stride = u32::try_from(m.target_stride / 4).ok()?;
        skin.morph_count = m.count;
        morphs = (&m.buffer, mw);
    }
    Some((
        skin,
        [
            (&rp.buffer, rest),
            joints,
            weights,
            morphs,
            (&out.buffer, posed),
        ],
    ))
}
