//! The context's side of BLAS compaction: a task's fast-trace builds compact their nodes on the
//! GPU and write their node counts ([`crate::scene::gpu_scene::NodeCounts`]); the task reads
//! them back, and once they arrive each BLAS gives the rest of its node range back to the pool
//! ([`crate::scene::gpu_scene::GpuScene::shrink_compacted`], from `State::collect_node_counts`).
//! The next task without build work packs the node pool, and the BLASes that moved get their new
//! node base (`State::apply_node_moves`).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::handles::GeometryHandle;
use crate::scene::gpu_scene::NodeCounts;

/// A read-back node count: the geometry, its build's stamp, and the count.
pub(super) type NodeCount = (GeometryHandle, u32, u32);

/// One task's node counts of its compacted BLASes, read back after it completes.
pub(super) struct NodeCountReadback {
    buffer: wgpu::Buffer,
    mapped: Arc<AtomicBool>,
    /// The task that built them.
    serial: u64,
    /// Per count: the geometry and its build's stamp (a later rebuild makes the count stale).
    blases: Vec<Option<(GeometryHandle, u32)>>,
}

impl NodeCountReadback {
    /// Records the copies of `counts` into a new read-back inside `encoder`; `blas_of` names
    /// each count's geometry and build stamp by slot. `None` when no BLAS was compacted.
    pub(super) fn record(
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        counts: NodeCounts,
        blas_of: impl Fn(u32) -> Option<(GeometryHandle, u32)>,
        serial: u64,
    ) -> Option<Self> {
        if counts.slots.is_empty() {
            return None;
        }
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("kickstart-rt BLAS node counts read-back"),
            size: counts.slots.len() as u64 * 4,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut at = 0;
        for (part, words) in &counts.parts {
            let bytes = *words as u64 * 4;
            encoder.copy_buffer_to_buffer(part, 0, &buffer, at, bytes);
            at += bytes;
        }
        let blases = counts.slots.iter().map(|&slot| blas_of(slot)).collect();
        Some(NodeCountReadback {
            buffer,
            mapped: Arc::new(AtomicBool::new(false)),
            serial,
            blases,
        })
    }

    /// The counts once mapped, each with its geometry and build stamp, and the serial of the
    /// task that built them; `None` while the mapping is pending (or when it failed).
    pub(super) fn arrived(&self) -> Option<(u64, Vec<NodeCount>)> {
        if !self.mapped.load(Ordering::Acquire) {
            return None;
        }
        let words: Vec<u32> = match self.buffer.slice(..).get_mapped_range() {
            Ok(view) => bytemuck::pod_collect_to_vec(&view),
            Err(_) => return None,
        };
        let counts = self
            .blases
            .iter()
            .zip(words)
            .filter_map(|(b, count)| b.map(|(handle, stamp)| (handle, stamp, count)))
            .collect();
        Some((self.serial, counts))
    }

    /// Whether its mapping has completed (successfully or not: see [`Self::arrived`]).
    pub(super) fn is_mapped(&self) -> bool {
        self.mapped.load(Ordering::Acquire)
    }

    /// Starts mapping it (its task has completed).
    pub(super) fn start_mapping(&self) {
        let flag = self.mapped.clone();
        self.buffer.map_async(wgpu::MapMode::Read, .., move |res| {
            if res.is_ok() {
                flag.store(true, Ordering::Release);
            }
        });
    }
}
