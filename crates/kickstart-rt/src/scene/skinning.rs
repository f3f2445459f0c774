//! The skinning pass (`shaders/scene/skinning.wgsl`): poses the meshes of a GPU task's
//! [`SkinningTask`]s into their output buffers before the task's geometries read them. Every
//! input is read in place from the caller's buffers (no copies: a frame of characters would
//! otherwise stage their rest data every frame).

use super::skin_batch::{batches, Limit, Posing, Span};
use super::skin_layout::{strided_end, Skin, Window};
use crate::gpu::reflect::{ReflectedPipeline, ReflectedShader};
use crate::gpu::Recorder;
use crate::tasks::{JointFormat, SkinningTask, VertexFormat, WeightFormat};

/// Floats of one joint matrix in the pose buffer (three rows of four).
const MATRIX_FLOATS: usize = 12;

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

impl Skinner {
    /// Creates the pipeline.
    pub fn new(device: &wgpu::Device) -> Self {
        let shader = ReflectedShader::compose(&["scene/skinning"], &[]);
        Skinner {
            pipeline: shader.pipeline(device, "kickstart-rt skinning", "skin_vertices"),
        }
    }

    /// Records `tasks` in one compute pass: one dispatch a batch of tasks that read and write
    /// the same buffers ([`batches`]), so a frame of characters whose buffers the engine pools
    /// is posed by one dispatch. Validated: every range lies in its buffer, every window fits
    /// the device's binding size, vertex counts fit one dispatch.
    pub fn record(&self, rec: &mut Recorder<'_>, tasks: &[&SkinningTask]) {
        let limits = rec.device.limits();
        let align = u64::from(limits.min_storage_buffer_offset_alignment);
        let (pose, at) = pose_data(tasks);
        let pose = rec.storage_init("kickstart-rt skinning pose", bytemuck::cast_slice(&pose));
        let posings = tasks
            .iter()
            .zip(at)
            .filter(|(t, _)| t.vertex_count > 0)
            .filter_map(|(t, (first_matrix, first_weight))| {
                let (skin, spans) = params(t, first_weight)?;
                let skin = Skin {
                    joint_base: first_matrix,
                    ..skin
                };
                Some(Posing::new(skin, spans))
            });
        let limit = Limit {
            align,
            binding: limits.max_storage_buffer_binding_size,
        };
        let mut groups = Vec::new();
        for batch in batches(posings, limit) {
            let Some((skins, windows)) = batch.skins(align) else {
                continue;
            };
            let skins =
                rec.storage_init("kickstart-rt skinning tasks", bytemuck::cast_slice(&skins));
            let bound = batch.buffers();
            let bind = |i: usize| bind((bound[i], windows[i]));
            let group = self.pipeline.bind_resources(
                rec.device,
                "kickstart-rt skinning",
                0,
                &[
                    ("skins", skins.as_entire_binding()),
                    ("rest", bind(0)),
                    ("joints", bind(1)),
                    ("weights", bind(2)),
                    ("morphs", bind(3)),
                    ("pose", pose.as_entire_binding()),
                    ("posed", bind(4)),
                ],
            );
            groups.push((group, batch.workgroups));
        }
        rec.dispatch_each("skinning", &self.pipeline.pipeline, &groups);
    }
}

/// The binding of an input's window.
fn bind<'a>((buffer, w): (&'a wgpu::Buffer, Window)) -> wgpu::BindingResource<'a> {
    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
        buffer,
        offset: w.start,
        size: wgpu::BufferSize::new(w.size),
    })
}

/// The parameters and byte spans (rest, joints, weights, morphs, output) of task `t`, whose
/// morph weights start at `first_weight` of the pose buffer; the word offsets are left for the
/// batch to set ([`Batch::skins`]). `None` when an address does not fit 32-bit arithmetic (the
/// validation refuses those tasks first).
fn params(t: &SkinningTask, first_weight: u32) -> Option<(Skin, [Span<'_>; 5])> {
    let n = t.vertex_count;
    let rest_size = match t.rest_positions.format {
        VertexFormat::Float32x4 => 16,
        _ => 12,
    };
    let rp = &t.rest_positions;
    let rest = Span::new(
        &rp.buffer,
        rp.offset,
        strided_end(rp.offset, rp.stride, n, rest_size)?,
    );
    let out = &t.output;
    let posed = Span::new(
        &out.buffer,
        out.offset,
        strided_end(out.offset, out.stride, n, 12)?,
    );
    let mut skin = Skin {
        vertex_count: n,
        rest_stride: u32::try_from(rp.stride / 4).ok()?,
        out_stride: u32::try_from(out.stride / 4).ok()?,
        morph_weight_at: first_weight,
        ..Skin::default()
    };
    // A task without influences or targets binds its rest positions in their place (unread).
    let (mut joints, mut weights, mut morphs) = (rest, rest, rest);
    if let Some(inf) = &t.influences {
        let (j, w) = (&inf.joints, &inf.weights);
        joints = Span::new(
            &j.buffer,
            j.offset,
            strided_end(j.offset, j.stride, n, j.format.size())?,
        );
        weights = Span::new(
            &w.buffer,
            w.offset,
            strided_end(w.offset, w.stride, n, w.format.size())?,
        );
        skin.joint_stride = u32::try_from(j.stride / 4).ok()?;
        skin.joint_format = match j.format {
            JointFormat::Uint8x4 => 0,
            JointFormat::Uint16x4 => 1,
            JointFormat::Uint32x4 => 2,
        };
        skin.weight_stride = u32::try_from(w.stride / 4).ok()?;
        skin.weight_format = match w.format {
            WeightFormat::Float32x4 => 0,
            WeightFormat::Unorm8x4 => 1,
            WeightFormat::Unorm16x4 => 2,
        };
        skin.joint_count = u32::try_from(t.joint_matrices.len()).ok()?;
    }
    if let Some(m) = t.morph_targets.as_ref().filter(|m| m.count > 0) {
        let last_target = m.target_stride.checked_mul(u64::from(m.count - 1))?;
        let end = strided_end(m.offset.checked_add(last_target)?, m.stride, n, 12)?;
        // Targets may be stored in any order: the span covers the lowest to the highest.
        morphs = Span::new(&m.buffer, m.offset, end);
        skin.morph_stride = u32::try_from(m.stride / 4).ok()?;
        skin.morph_target_stride = u32::try_from(m.target_stride / 4).ok()?;
        skin.morph_count = m.count;
    }
    Some((skin, [rest, joints, weights, morphs, posed]))
}
