//! What the context keeps between GPU tasks: the handle slots, the working sets in flight, the
//! scene, the lighting cache, the effects and the bookkeeping that decides what the next task
//! records.

use std::collections::{BTreeMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use super::effects::Effects;
use super::settings::{DroppedTriangles, RecordedTaskCounts, INSTANCE_RECORD_SIZE};
use crate::error::Error;
use crate::handles::*;
use crate::logging::{Logger, Severity};
use crate::scene::gpu_scene::{GeometryGpu, GpuScene, PendingBvh, Uploads, GEOMETRY_RECORD_SIZE};
use crate::scene::opacity::geometry_level;
use crate::scene::pool::Move;
use crate::scene::strategy::BuildStrategy;
use crate::staging::{StagingBuffer, StagingPool};
use crate::tasks::*;
use crate::timing::TimingReadback;

pub(super) struct GeometryData {
    pub(super) name: String,
    pub(super) allow_update: bool,
    /// How its BLAS is built, resolved from `build_hint` at registration.
    pub(super) strategy: BuildStrategy,
    pub(super) triangles: u32,
    pub(super) gpu: GeometryGpu,
    pub(super) dropped: Option<DroppedTriangles>,
    pub(super) cache: crate::cache::CacheParams,
    pub(super) allow_light_transfer_target: bool,
}

/// Dropped-triangle counters of one task's ingestions, read back after it completes.
pub(super) struct DroppedReadback {
    pub(super) buffer: wgpu::Buffer,
    pub(super) mapped: Arc<AtomicBool>,
    pub(super) geometries: Vec<(GeometryHandle, String)>,
}

#[derive(Default)]
pub(super) struct GeometrySlot {
    pub(super) data: Option<GeometryData>,
    pub(super) last_used: u64,
}

#[derive(Default)]
pub(super) struct InstanceSlot {
    pub(super) input: Option<InstanceInput>,
    pub(super) last_used: u64,
}

pub(super) struct DenoisingSlot {
    pub(super) input: DenoisingContextInput,
}

/// Resources one in-flight GPU task holds until it is marked complete.
pub(super) struct WorkingSet {
    pub(super) staging: Vec<StagingBuffer>,
    /// Inputs the task reads and the raw copies it made, kept alive while the GPU may read them.
    pub(super) held: Vec<wgpu::Buffer>,
    pub(super) dropped: Option<DroppedReadback>,
    /// Node counts of the BLASes the task compacted.
    pub(super) node_counts: Option<super::compaction::NodeCountReadback>,
}

pub(super) struct State {
    pub(super) geometries: HandlePool<GeometryHandle, GeometrySlot>,
    pub(super) instances: HandlePool<InstanceHandle, InstanceSlot>,
    pub(super) denoisers: HandlePool<DenoisingContextHandle, DenoisingSlot>,
    pub(super) in_flight: BTreeMap<u64, WorkingSet>,
    pub(super) invoked: Vec<(u64, Arc<AtomicBool>)>,
    pub(super) staging: StagingPool,
    pub(super) scene: GpuScene,
    /// Every render effect's pipelines and history (ray batches, debug views, trace tasks,
    /// denoisers); the lighting cache owns its injection and transfer.
    pub(super) effects: Effects,
    /// Geometries waiting for a BLAS build or refit, in the order they were scheduled.
    pub(super) blas_queue: VecDeque<GeometryHandle>,
    /// Instance slots whose records must be rewritten as dead (destroyed instances, instances of
    /// destroyed geometry).
    pub(super) dead_instance_slots: Vec<u32>,
    /// Geometry slots whose table record must be cleared (destroyed geometry).
    pub(super) dead_geometry_slots: Vec<u32>,
    /// Instance records to write when the TLAS is next updated: rays always see the instance
    /// table that matches the TLAS, also while a BvhBuildTask defers the TLAS.
    pub(super) pending_records: BTreeMap<u32, [u8; INSTANCE_RECORD_SIZE as usize]>,
    /// The set of TLAS leaves changed (instances added/removed, participation, a BLAS built).
    pub(super) tlas_rebuild: bool,
    /// Only instance transforms (or refitted BLASes) changed since the last TLAS update.
    pub(super) tlas_refit: bool,
    pub(super) any_instance: bool,
    pub(super) dropped_readbacks: Vec<DroppedReadback>,
    /// Node counts of compacted BLASes whose tasks completed, being mapped.
    pub(super) node_count_readbacks: Vec<super::compaction::NodeCountReadback>,
    pub(super) timings: BTreeMap<u64, TimingReadback>,
    pub(super) next_serial: u64,
    pub(super) counts: RecordedTaskCounts,
    /// What the device reported during a task (see `Error::Device`): once set, every later task
    /// is refused with it.
    pub(super) device_error: Option<String>,
    /// The direct lighting cache (sampling contract in `crate::cache`).
    pub(super) cache: crate::cache::DirectLightingCache,
}

impl State {
    /// The registered geometry of a registered instance; `None` where either is not registered
    /// yet, [`crate::Error::InvalidHandle`] for a stale instance handle.
    pub(super) fn instance_geometry(
        &self,
        h: InstanceHandle,
    ) -> crate::error::Result<Option<&GeometryData>> {
        Ok(self
            .instances
            .get(h)?
            .input
            .as_ref()
            .and_then(|i| self.geometries.get(i.geometry).ok())
            .and_then(|g| g.data.as_ref()))
    }

    /// Slots of the registered instances whose geometry was destroyed: they must not trace a
    /// geometry that reuses its slot.
    pub(super) fn instances_of_dead_geometry(&self) -> Vec<u32> {
        self.instances
            .handles()
            .into_iter()
            .filter(|h| {
                self.instances
                    .get(*h)
                    .ok()
                    .and_then(|i| i.input.as_ref())
                    .is_some_and(|i| self.geometries.get(i.geometry).is_err())
            })
            .map(|h| h.index)
            .collect()
    }

    /// The serial of the oldest task in flight (`u64::MAX` when none is): what no task older
    /// than it reads is released at the start of the next record phase.
    pub(super) fn oldest_in_flight(&self) -> u64 {
        self.in_flight.keys().next().copied().unwrap_or(u64::MAX)
    }

    /// Returns a completed task's staging to the pool and starts reading back its counters.
    /// Records that the device reported `message` during `operation`: this and every later
    /// task is refused with the returned error.
    pub(super) fn device_lost(&mut self, operation: &'static str, message: String) -> Error {
        self.device_error = Some(message.clone());
        Error::Device { operation, message }
    }

    pub(super) fn retire(&mut self, serial: u64, ws: WorkingSet) {
        self.cache.task_completed(serial);
        for b in ws.staging {
            self.staging.release(b);
        }
        if let Some(r) = ws.dropped {
            let flag = r.mapped.clone();
            r.buffer.map_async(wgpu::MapMode::Read, .., move |res| {
                if res.is_ok() {
                    flag.store(true, Ordering::Release);
                }
            });
            self.dropped_readbacks.push(r);
        }
        if let Some(r) = ws.node_counts {
            r.start_mapping();
            self.node_count_readbacks.push(r);
        }
    }

    /// Logs and records the dropped-triangle counts whose read-back has arrived.
    pub(super) fn collect_dropped(&mut self, logger: &Logger) {
        let mut i = 0;
        while i < self.dropped_readbacks.len() {
            if !self.dropped_readbacks[i].mapped.load(Ordering::Acquire) {
                i += 1;
                continue;
            }
            let r = self.dropped_readbacks.swap_remove(i);
            let words: Vec<u32> = match r.buffer.slice(..).get_mapped_range() {
                Ok(view) => bytemuck::pod_collect_to_vec(&view),
                Err(_) => continue,
            };
            for (k, (handle, name)) in r.geometries.iter().enumerate() {
                let d = DroppedTriangles {
                    out_of_range_indices: words.get(2 * k).copied().unwrap_or(0),
                    non_finite_positions: words.get(2 * k + 1).copied().unwrap_or(0),
                };
                if d != DroppedTriangles::default() {
                    logger.message(
                        Severity::Warning,
                        &format!(
                            "GeometryTask: geometry `{name}` ({handle:?}): dropped {} triangle(s) with out-of-range indices and {} with NaN/infinite positions; they are never hit",
                            d.out_of_range_indices, d.non_finite_positions
                        ),
                    );
                }
                if let Ok(GeometrySlot { data: Some(g), .. }) = self.geometries.get_mut(*handle) {
                    g.dropped = Some(d);
                }
            }
        }
    }

    /// Allocation jobs of the instances waiting for a cache whose geometry's BLAS is built.
    pub(super) fn cache_jobs(&self) -> Vec<crate::cache::AllocJob> {
        if self.cache.waiting().is_empty() {
            return Vec::new();
        }
        let mut jobs = Vec::new();
        for h in self.instances.handles() {
            if !self.cache.waiting().contains(&h.index) {
                continue;
            }
            let Some(input) = self.instances.get(h).ok().and_then(|i| i.input.as_ref()) else {
                continue;
            };
            let Some(d) = self
                .geometries
                .get(input.geometry)
                .ok()
                .and_then(|g| g.data.as_ref())
            else {
                continue;
            };
            let Some(blas) = d
                .gpu
                .blas
                .filter(|_| d.gpu.pending != Some(PendingBvh::Build))
            else {
                continue;
            };
            jobs.push(crate::cache::AllocJob {
                slot: h.index,
                tri_base: blas.tris.start,
                tri_count: d.triangles,
                params: d.cache,
                transform: input.transform,
                initial: input.initial_tile_color,
            });
            // One task allocates at most this many (the rest wait for the next tasks): with a
            // million instances waiting, collecting them all every task would dominate it.
            if jobs.len() == crate::cache::alloc::MAX_ALLOCS_PER_TASK {
                break;
            }
        }
        jobs
    }
}

/// The instance's record (layout at [`INSTANCE_RECORD_SIZE`]).
pub(super) fn instance_record(input: &InstanceInput) -> [u8; INSTANCE_RECORD_SIZE as usize] {
    // Rows of the 3×4 affine: transposing the 4×4 turns its columns into rows.
    let rows = glam::Mat4::from(input.transform)
        .transpose()
        .to_cols_array();
    let inv = glam::Mat4::from(input.transform.inverse())
        .transpose()
        .to_cols_array();
    let mut words = [0u32; 32];
    for i in 0..12 {
        words[i] = rows[i].to_bits();
        words[12 + i] = inv[i].to_bits();
    }
    words[24] = input.geometry.index;
    words[25] = input.inclusion_mask.0;
    words[26] = input.participating_in_tlas as u32;
    bytemuck::cast(words)
}

impl State {
    /// Gives back the unused nodes of every compacted BLAS whose count has arrived (a BLAS
    /// destroyed or rebuilt since is skipped: its range is no longer that build's).
    pub(super) fn collect_node_counts(&mut self) {
        let mut i = 0;
        while i < self.node_count_readbacks.len() {
            if !self.node_count_readbacks[i].is_mapped() {
                i += 1;
                continue;
            }
            let r = self.node_count_readbacks.swap_remove(i);
            let Some((serial, counts)) = r.arrived() else {
                continue;
            };
            for (handle, stamp, count) in counts {
                let Ok(slot) = self.geometries.get_mut(handle) else {
                    continue;
                };
                let Some(blas) = slot.data.as_mut().and_then(|d| d.gpu.blas.as_mut()) else {
                    continue;
                };
                if blas.stamp == stamp {
                    self.scene.shrink_compacted(blas, count, serial);
                }
            }
        }
    }

    /// Gives the BLASes whose nodes `GpuScene::release_build_memory` moved their new node
    /// range, and queues their geometry headers' new node base into `uploads`.
    pub(super) fn apply_node_moves(&mut self, moves: &[Move], uploads: &mut Uploads) {
        if moves.is_empty() {
            return;
        }
        for h in self.geometries.handles() {
            let Ok(slot) = self.geometries.get_mut(h) else {
                continue;
            };
            let Some(blas) = slot.data.as_mut().and_then(|d| d.gpu.blas.as_mut()) else {
                continue;
            };
            let Some(start) = Move::moved(moves, blas.nodes.start) else {
                continue;
            };
            if start != blas.nodes.start {
                blas.nodes.start = start;
                uploads.push(
                    &self.scene.geometry_table.buffer,
                    u64::from(h.index) * GEOMETRY_RECORD_SIZE,
                    bytemuck::bytes_of(&start),
                );
            }
        }
    }
}

/// The BVH work a geometry task leaves its geometry (`data`: as registered before the task): a
/// refit for an update of a built geometry, else a build. The driver's BLAS keeps the opaque
/// flag it was built with, so on the hardware backend an update that makes a geometry cutout or
/// opaque rebuilds it; the software traversal reads the new opacity words in the geometry record.
/// The plan predicts with it what recording then does (`reserve`, `record`).
pub(super) fn geometry_task_work(
    data: Option<&GeometryData>,
    task: &GeometryTask,
    hardware: bool,
) -> PendingBvh {
    let cutout = geometry_level(&task.input).is_some();
    match (data, task.operation) {
        (Some(d), TaskOperation::Update)
            if d.gpu.blas.is_some() && !(hardware && d.gpu.opacity.is_some() != cutout) =>
        {
            PendingBvh::Refit
        }
        _ => PendingBvh::Build,
    }
}
