//! The record phase of `build_gpu_task`: carries out a checked [`FramePlan`] into the engine's
//! encoder, one function per step of the data flow (`docs/design.md`, "Data flow of one
//! `build_gpu_task`"). Nothing here can fail: the plan checked every input, resolved every
//! render task's effect, and ran this phase's allocations on copies of the pools' bookkeeping
//! (`super::reserve`), so every allocation made here fits. A refused task therefore never
//! leaves a step half done.

use std::collections::HashMap;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use super::compaction::NodeCountReadback;
use super::effects::{Inputs, Route};
use super::plan::FramePlan;
use super::raw_copy::RawCopy;
use super::settings::INSTANCE_RECORD_SIZE;
use super::state::{
    geometry_task_work, instance_record, DroppedReadback, GeometryData, State, WorkingSet,
};
use super::validate::ComponentExtent;
use crate::gpu::recorder::Timestamps;
use crate::gpu::Recorder;
use crate::handles::*;
use crate::scene::gpu_scene::{
    DeferredIngest, GeometryGpu, GpuScene, PendingBvh, Uploads, GEOMETRY_OPACITY_AT,
    GEOMETRY_RECORD_SIZE,
};
use crate::scene::ingest::{component_rows, ComponentIngest, OpacityIngest};
use crate::scene::opacity::{
    elements as opacity_elements, geometry_level, OpacityMaps, OPAQUE_RECORD,
};
use crate::scene::pool::Range;
use crate::scene::strategy::BuildStrategy;
use crate::scene::traversal::LeafTest;
use crate::tasks::*;

/// The encoder and what one GPU task's recording carries from step to step.
pub(super) struct Frame<'a> {
    pub device: &'a wgpu::Device,
    pub queue: &'a wgpu::Queue,
    pub encoder: &'a mut wgpu::CommandEncoder,
    /// Timestamp queries around every pass, when GPU timing is on.
    pub timestamps: Option<Timestamps>,
    /// What the task holds until it is marked complete.
    pub ws: WorkingSet,
    pub serial: u64,
}

impl Frame<'_> {
    /// A recorder for the passes of `scope`.
    fn recorder(&mut self, scope: &'static str) -> Recorder<'_> {
        Recorder {
            device: self.device,
            encoder: self.encoder,
            timestamps: self.timestamps.as_mut(),
            scope,
            dispatches: 0,
        }
    }

    /// Records the copies of `uploads` through the staging pool; the working set keeps them.
    fn flush(&mut self, s: &mut State, uploads: Uploads) {
        let staged = uploads.flush(self.device, &mut s.staging, self.encoder);
        self.ws.staging.extend(staged);
    }
}

/// One geometry task's ingestion: the task, its extents, its staged range, triangle count and
/// opacity micro-maps (cutout geometry).
type Ingestion<'c> = (
    &'c GeometryTask,
    &'c [ComponentExtent],
    Range,
    u32,
    Option<OpacityMaps>,
);

/// Records `plan`, in the order of the data flow.
pub(super) fn record(frame: &mut Frame<'_>, s: &mut State, plan: &FramePlan<'_>) {
    release_completed(s);
    s.scene.ensure_tables(
        frame.encoder,
        s.geometries.slot_count(),
        s.instances.slot_count(),
    );
    if !plan.skins.is_empty() {
        // Before the ingestions below copy the posed positions.
        let mut rec = frame.recorder("skinning");
        s.scene.record_skinning(&mut rec, &plan.skins);
    }
    let ingestions = allocate_staged(frame, s, plan);
    // Only geometry tasks and queued builds use the BLAS pools' free space and the build
    // scratch: a task with neither gives them back.
    let mut uploads = Uploads::default();
    if ingestions.is_empty() && s.blas_queue.is_empty() {
        let moves = s.scene.release_build_memory(frame.encoder);
        s.apply_node_moves(&moves, &mut uploads);
    } else {
        s.scene.note_build_work();
    }
    clear_dead_slots(s, &mut uploads, frame.serial);
    queue_geometry_records(s, &ingestions, &mut uploads);
    queue_instance_records(s, &plan.instances);
    frame.flush(s, uploads);
    let deferred = ingest(frame, s, plan, &ingestions);
    register_geometries(s, &ingestions, frame.serial);
    let deferred = build_blases(frame, s, plan, deferred);
    record_deferred_ingestions(frame, s, deferred);
    if let Some(dropped) = &frame.ws.dropped {
        // The dropped-triangle counts, after every pass that counts them.
        let size = dropped.buffer.size();
        frame
            .encoder
            .copy_buffer_to_buffer(&s.scene.counters, 0, &dropped.buffer, 0, size);
    }
    update_tlas(frame, s, plan);
    record_hardware_structures(frame, s);
    register_instances(s, &plan.instances, frame.serial);
    allocate_caches(frame, s);
    for route in &plan.render {
        record_render_task(frame, s, route);
    }
}

/// The geometry-table words of each ingestion: a registration's record cleared, and its opacity
/// words where they change.
fn queue_geometry_records(s: &State, ingestions: &[Ingestion<'_>], uploads: &mut Uploads) {
    for (task, .., maps) in ingestions {
        let record = task.handle.index as u64 * GEOMETRY_RECORD_SIZE;
        if task.operation == TaskOperation::Register {
            uploads.push(
                &s.scene.geometry_table.buffer,
                record,
                bytemuck::bytes_of(&[0u32; 4]),
            );
        }
        // An update that keeps the geometry's micro-maps where they are leaves its record's
        // opacity words as they are: every upload is a copy command of its own (the records are
        // apart), each with a fixed cost, which an animated scene would pay for every refit
        // geometry every frame.
        let kept = task.operation == TaskOperation::Update
            && s.geometries
                .get(task.handle)
                .ok()
                .and_then(|g| g.data.as_ref())
                .is_some_and(|d| d.gpu.opacity == *maps);
        if !kept {
            let opacity = maps.map_or(OPAQUE_RECORD, |m| m.record());
            uploads.push(
                &s.scene.geometry_table.buffer,
                record + GEOMETRY_OPACITY_AT,
                bytemuck::bytes_of(&opacity),
            );
        }
    }
}

/// Step 1, deferred destruction: releases what no in-flight task can still read (the plan
/// simulated this on its copies of the pools); creates the history of new denoising contexts
/// and retires that of destroyed ones.
fn release_completed(s: &mut State) {
    let oldest = s.oldest_in_flight();
    s.scene.collect(oldest);
    s.cache.collect(oldest);
    let live: Vec<_> = s
        .denoisers
        .handles()
        .into_iter()
        .filter_map(|h| s.denoisers.get(h).ok().map(|d| (h, d.input)))
        .collect();
    s.effects.denoisers.sync(&live);
    s.effects.denoisers.collect(oldest);
}

/// Staged-triangle space for every geometry task (reserved by the plan): updates reuse their
/// range.
fn allocate_staged<'c>(
    frame: &mut Frame<'_>,
    s: &mut State,
    plan: &'c FramePlan<'_>,
) -> Vec<Ingestion<'c>> {
    let mut ingestions = Vec::new();
    s.scene
        .reserve_staged(frame.encoder, plan.reserved.staged_triangles);
    for (task, extents) in &plan.geometries {
        let triangles: u32 = extents.iter().map(|e| e.triangles).sum();
        let Ok(slot) = s.geometries.get_mut(task.handle) else {
            continue;
        };
        let staged = match (&mut slot.data, task.operation) {
            (Some(d), TaskOperation::Update) => d.gpu.staged,
            _ => None,
        };
        let staged = match staged {
            Some(r) => r,
            None => s.scene.alloc_staged(frame.encoder, triangles),
        };
        // Micro-maps of the same size are baked again where they are; others get a new range
        // (the old one is freed by `register_geometries`).
        let existing = slot.data.as_ref().and_then(|d| d.gpu.opacity);
        let maps = geometry_level(&task.input).map(|level| {
            let need = opacity_elements(triangles, level);
            match existing {
                Some(m) if m.level == level && m.range.len == need => m,
                _ => OpacityMaps {
                    range: s.scene.alloc_opacity(frame.encoder, need),
                    level,
                },
            }
        });
        ingestions.push((*task, extents.as_slice(), staged, triangles, maps));
    }
    ingestions
}

/// Step 2: destroyed objects leave the tables.
fn clear_dead_slots(s: &mut State, uploads: &mut Uploads, serial: u64) {
    if !s.dead_geometry_slots.is_empty() {
        for slot in std::mem::take(&mut s.dead_geometry_slots) {
            if let Some(hw) = s.scene.hardware.as_mut() {
                hw.remove(slot);
            }
            uploads.push(
                &s.scene.geometry_table.buffer,
                slot as u64 * GEOMETRY_RECORD_SIZE,
                bytemuck::bytes_of(&[0u32; 4]),
            );
        }
        let dead = s.instances_of_dead_geometry();
        s.dead_instance_slots.extend(dead);
    }
    if !s.dead_instance_slots.is_empty() {
        for slot in std::mem::take(&mut s.dead_instance_slots) {
            s.cache.release(slot, serial);
            s.pending_records
                .insert(slot, [0u8; INSTANCE_RECORD_SIZE as usize]);
        }
        s.tlas_rebuild = true;
    }
}

/// Step 3: instance records, at the instance's slot index (the invariant of the instance-id
/// bug report: the index a hit reports is the index of the instance's data).
fn queue_instance_records(s: &mut State, instances: &[&InstanceTask]) {
    for t in instances {
        // Only a move keeps the TLAS's leaves; compared in place (this runs for every
        // instance update of every frame).
        let moved_only = s
            .instances
            .get(t.handle)
            .ok()
            .and_then(|i| i.input.as_ref())
            .is_some_and(|o| {
                o.geometry == t.input.geometry
                    && o.participating_in_tlas == t.input.participating_in_tlas
            });
        if moved_only {
            s.tlas_refit = true;
        } else {
            s.tlas_rebuild = true;
        }
        s.pending_records
            .insert(t.handle.index, instance_record(&t.input));
    }
}

/// Step 4, geometry ingestion: copies the application's bytes (inside its encoder), then
/// decodes them into the shared staged-triangle pool. Returns the ingestions fused into this
/// task's refits (recorded by them, or after them if the refit waits).
fn ingest(
    frame: &mut Frame<'_>,
    s: &mut State,
    plan: &FramePlan<'_>,
    ingestions: &[Ingestion<'_>],
) -> HashMap<GeometryHandle, DeferredIngest> {
    let mut deferred = HashMap::new();
    if ingestions.is_empty() {
        return deferred;
    }
    let (raw, components) = copy_raw_geometry(frame, ingestions);
    s.scene
        .reset_counters(frame.encoder, ingestions.len() as u32);
    // Geometries ingested once in this task (a second ingestion must follow the first).
    let mut ingested: HashMap<GeometryHandle, u32> = HashMap::new();
    for (t, ..) in ingestions {
        *ingested.entry(t.handle).or_default() += 1;
    }
    let mut rec = frame.recorder("ingest");
    // Every ingestion not fused into a refit, recorded as one pass below.
    let mut plain: Vec<(Vec<ComponentIngest>, Range, u32)> = Vec::new();
    for (i, ((task, _, staged, triangles, maps), comps)) in
        ingestions.iter().zip(components).enumerate()
    {
        if let Some(maps) = maps {
            s.scene.bake_opacity(&mut rec, &raw, &comps, *maps);
        }
        // An update refit in this task decodes its own triangles (the ingestion fused into
        // the refit): deferred to step 5, and recorded after it if the refit waits for a
        // later task (max_blas_build_count).
        let candidate = plan.build.is_some()
            && task.operation == TaskOperation::Update
            && ingested.get(&task.handle) == Some(&1);
        let rows = candidate
            .then(|| component_rows(&comps, staged.start))
            .flatten()
            .filter(|rows| {
                s.geometries.get(task.handle).is_ok_and(|slot| {
                    slot.data.as_ref().is_some_and(|d| {
                        d.gpu.pending != Some(PendingBvh::Build)
                            && GpuScene::can_refit_from_raw(&d.gpu, *triangles, rows)
                    })
                })
            });
        match rows {
            Some(rows) => {
                let d = DeferredIngest {
                    raw: raw.clone(),
                    components: comps,
                    rows,
                    staged: *staged,
                    ingestion: i as u32,
                };
                deferred.insert(task.handle, d);
            }
            None => plain.push((comps, *staged, i as u32)),
        }
    }
    let plain: Vec<(&[ComponentIngest], Range, u32)> = plain
        .iter()
        .map(|(c, staged, i)| (c.as_slice(), *staged, *i))
        .collect();
    s.scene.record_ingests(&mut rec, &raw, &plain);
    frame.ws.held.push(raw);
    frame.ws.dropped = Some(dropped_readback(frame.device, ingestions));
    deferred
}

/// Copies the bytes every ingestion reads (vertices, indices, opacity sources) into one raw
/// buffer ([`RawCopy`]: ranges of one buffer copied once) and plans each component's decode
/// from it.
fn copy_raw_geometry(
    frame: &mut Frame<'_>,
    ingestions: &[Ingestion<'_>],
) -> (wgpu::Buffer, Vec<Vec<ComponentIngest>>) {
    let mut copy = RawCopy::default();
    // Per component: its request for vertices, indices and opacity bytes.
    let mut asked = Vec::new();
    for (task, extents, ..) in ingestions {
        for (c, e) in task.input.components.iter().zip(extents.iter()) {
            let vertices = copy.request(&c.vertex_buffer.buffer, e.vertex_bytes);
            let indices = match (&c.index_buffer, e.index_bytes) {
                (Some(ib), Some(range)) => Some(copy.request(&ib.buffer, range)),
                _ => None,
            };
            let opacity = match (&c.opacity, e.opacity_bytes) {
                (Some(o), Some(range)) => Some(copy.request(opacity_source(o).0, range)),
                _ => None,
            };
            asked.push((vertices, indices, opacity));
        }
    }
    let (raw, offsets) = copy.record(frame.device, frame.encoder, &mut frame.ws.held);
    let mut asked = asked.into_iter();
    let mut plans = Vec::new();
    for (task, extents, ..) in ingestions {
        let mut comps = Vec::new();
        let mut prim_base = 0u32;
        for (c, e) in task.input.components.iter().zip(extents.iter()) {
            let Some((vertices, indices, opacity)) = asked.next() else {
                break;
            };
            let vb = &c.vertex_buffer;
            // Where a range's first byte landed, plus the field's distance from it.
            let raw_at = |request: usize, (start, _): (u64, u64), offset: u64| {
                offsets[request] + (offset - start)
            };
            let index = match (&c.index_buffer, e.index_bytes, indices) {
                (Some(ib), Some(range), Some(k)) => Some((raw_at(k, range, ib.offset), ib.format)),
                _ => None,
            };
            let opacity = match (&c.opacity, e.opacity_bytes, opacity) {
                (Some(o), Some(range), Some(k)) => {
                    Some(opacity_ingest(o, raw_at(k, range, opacity_source(o).1)))
                }
                _ => None,
            };
            comps.push(ComponentIngest {
                opacity,
                vertex_byte_offset: raw_at(vertices, e.vertex_bytes, vb.offset),
                vertex_stride: vb.stride,
                vertex_format: vb.format,
                vertex_count: vb.count,
                index,
                first_index: c.index_range.map_or(0, |(first, _)| first),
                triangle_count: e.triangles,
                transform: c.transform,
                primitive_base: prim_base,
            });
            prim_base += e.triangles;
        }
        plans.push(comps);
    }
    (raw, plans)
}

/// The buffer a component's opacity source reads (its coordinates, or its per-triangle flags)
/// and the byte offset of its first element.
fn opacity_source(o: &ComponentOpacity) -> (&wgpu::Buffer, u64) {
    match &o.source {
        OpacitySource::Texture { uvs, .. } => (&uvs.buffer, uvs.offset),
        OpacitySource::PerTriangle { buffer, offset } => (buffer, *offset),
    }
}

/// How the ingestion reads a component's opacity source, whose bytes start at `at` in the raw
/// copy.
fn opacity_ingest(o: &ComponentOpacity, at: u64) -> OpacityIngest {
    match &o.source {
        OpacitySource::Texture {
            texture,
            uvs,
            channel,
            factor,
            cutoff,
        } => {
            // The bind group of the bake keeps the view alive while the GPU reads it.
            OpacityIngest::Texture {
                texture: texture.clone(),
                uv_byte_offset: at,
                uv_stride: uvs.stride,
                uv_format: uvs.format,
                channel: *channel,
                factor: *factor,
                cutoff: *cutoff,
            }
        }
        OpacitySource::PerTriangle { .. } => OpacityIngest::PerTriangle { byte_offset: at },
    }
}

/// The read-back of the ingestions' dropped-triangle counters (two words each).
fn dropped_readback(device: &wgpu::Device, ingestions: &[Ingestion<'_>]) -> DroppedReadback {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("kickstart-rt ingestion counters read-back"),
        size: ingestions.len() as u64 * 8,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    DroppedReadback {
        buffer,
        mapped: Arc::new(AtomicBool::new(false)),
        geometries: ingestions
            .iter()
            .map(|(t, ..)| (t.handle, t.input.name.clone()))
            .collect(),
    }
}

/// The geometries' bookkeeping after their ingestion: new ones registered, and each queued for
/// a BLAS build or refit.
fn register_geometries(s: &mut State, ingestions: &[Ingestion<'_>], serial: u64) {
    let hardware = s.scene.hardware.is_some();
    for &(task, _, staged, triangles, maps) in ingestions {
        let Ok(slot) = s.geometries.get_mut(task.handle) else {
            continue;
        };
        slot.last_used = serial;
        let pending = geometry_task_work(slot.data.as_ref(), task, hardware);
        let data = slot.data.get_or_insert_with(|| GeometryData {
            name: task.input.name.clone(),
            allow_update: task.input.allow_update,
            strategy: BuildStrategy::of(task.input.build_hint, task.input.allow_update),
            triangles,
            gpu: GeometryGpu::default(),
            dropped: None,
            cache: crate::cache::CacheParams::of(&task.input),
            allow_light_transfer_target: task.input.allow_light_transfer_target,
        });
        data.gpu.triangles = triangles;
        data.gpu.staged = Some(staged);
        if data.gpu.opacity != maps {
            s.scene
                .note_cutout_geometry(data.gpu.opacity.is_some(), maps.is_some());
            if let Some(old) = data.gpu.opacity.take() {
                s.scene.triangles.free_after(old.range, serial);
            }
            data.gpu.opacity = maps;
        }
        if data.gpu.pending.is_none() {
            s.blas_queue.push_back(task.handle);
        }
        // A queued build stays a build (the refit needs a built tree).
        if data.gpu.pending != Some(PendingBvh::Build) {
            data.gpu.pending = Some(pending);
        }
        s.counts.geometry_tasks += 1;
    }
}

/// Step 5: BLAS builds and refits, at most `max_blas_build_count`, in queue order, into the
/// pool space the plan reserved for them. Returns the fused ingestions whose refit waits for a
/// later task.
fn build_blases(
    frame: &mut Frame<'_>,
    s: &mut State,
    plan: &FramePlan<'_>,
    mut deferred: HashMap<GeometryHandle, DeferredIngest>,
) -> HashMap<GeometryHandle, DeferredIngest> {
    let Some(build) = plan.build else {
        return deferred;
    };
    s.scene
        .reserve_blas(frame.encoder, &plan.reserved.blas_builds);
    // The work the plan reserved for, in order (compared in debug builds).
    let mut done_work = Vec::new();
    let serial = frame.serial;
    let mut headers = Uploads::default();
    let mut rec = frame.recorder("blas build");
    // Fast-trace builds: allocated in queue order, their passes recorded as one batch below.
    let mut batch = Vec::new();
    // Range refits, recorded as one batch below too.
    let mut refits = Vec::new();
    // The geometry and build stamp of each slot built, for the compactions' read-back.
    let mut built = HashMap::new();
    let mut done = 0;
    while done < build.max_blas_build_count {
        let Some(h) = s.blas_queue.pop_front() else {
            break;
        };
        let Ok(slot) = s.geometries.get_mut(h) else {
            continue; // destroyed while queued
        };
        let Some(d) = slot.data.as_mut() else {
            continue;
        };
        slot.last_used = serial;
        let pending = d.gpu.pending.take();
        if let Some(work) = pending {
            done_work.push((h, work));
        }
        match pending {
            Some(PendingBvh::Build) => {
                if let Some(old) = d.gpu.blas.take() {
                    let mut previous = GeometryGpu {
                        blas: Some(old),
                        ..Default::default()
                    };
                    previous.free_after(&mut s.scene, serial);
                }
                // register_geometries gives every geometry it queues for a build its staged
                // range, and only a build (of a static geometry) takes it away.
                let staged = d
                    .gpu
                    .staged
                    .expect("a geometry queued for a build is staged");
                let header = s.scene.build_blas(
                    &mut rec,
                    (h.index, staged),
                    &mut d.gpu,
                    d.allow_update,
                    d.strategy,
                    &mut batch,
                );
                headers.push(
                    &s.scene.geometry_table.buffer,
                    h.index as u64 * GEOMETRY_RECORD_SIZE,
                    bytemuck::bytes_of(&header),
                );
                if let Some(blas) = d.gpu.blas {
                    built.insert(h.index, (h, blas.stamp));
                }
                if let (Some(hw), Some(blas)) = (s.scene.hardware.as_mut(), d.gpu.blas) {
                    let cutout = d.gpu.opacity.is_some();
                    hw.build(
                        h.index,
                        blas.tris.start,
                        d.gpu.triangles,
                        (d.allow_update, cutout),
                    );
                }
                if !d.allow_update {
                    // Static geometry: its staged copy is not needed after the build.
                    if let Some(r) = d.gpu.staged.take() {
                        s.scene.staged.free_after(r, serial);
                    }
                }
                s.tlas_rebuild = true;
            }
            Some(PendingBvh::Refit) => {
                let fused = deferred.remove(&h);
                s.scene
                    .refit_blas(&mut rec, h.index, &d.gpu, fused, &mut refits);
                if let Some(hw) = s.scene.hardware.as_mut() {
                    hw.refit(h.index);
                }
                s.tlas_refit = true;
            }
            None => continue,
        }
        done += 1;
    }
    let counts = s.scene.record_batch(&mut rec, batch);
    s.scene.record_refit_batch(&mut rec, refits);
    frame.ws.node_counts = NodeCountReadback::record(
        frame.device,
        frame.encoder,
        counts,
        |slot| built.get(&slot).copied(),
        serial,
    );
    debug_assert_eq!(
        done_work, plan.reserved.blas,
        "the plan's prediction of step 5"
    );
    frame.flush(s, headers);
    deferred
}

/// Ingestions deferred for refits that step 5 left to a later task, in ingestion order (as
/// step 4 would have recorded them).
fn record_deferred_ingestions(
    frame: &mut Frame<'_>,
    s: &mut State,
    deferred: HashMap<GeometryHandle, DeferredIngest>,
) {
    if deferred.is_empty() {
        return;
    }
    let mut rec = frame.recorder("ingest");
    let mut rest: Vec<DeferredIngest> = deferred.into_values().collect();
    rest.sort_by_key(|d| d.ingestion);
    for d in rest {
        s.scene
            .record_ingest(&mut rec, &d.raw, &d.components, d.staged, d.ingestion);
    }
}

/// Step 6: the TLAS over every instance slot (its size checked by the plan), in every task that
/// changed something it depends on, unless a BvhBuildTask opts out with `build_tlas: false`.
fn update_tlas(frame: &mut Frame<'_>, s: &mut State, plan: &FramePlan<'_>) {
    let tlas_update = plan.build.map_or(Some(TlasUpdate::Auto), |b| {
        b.build_tlas.then_some(b.tlas_update)
    });
    let mode = tlas_update.filter(|_| s.tlas_rebuild || s.tlas_refit);
    debug_assert_eq!(mode.is_some(), plan.reserved.tlas, "the plan's prediction");
    let Some(mode) = mode else {
        return;
    };
    let slots = s.instances.slot_count();
    let refit = !s.tlas_rebuild
        && match mode {
            TlasUpdate::Rebuild => false,
            TlasUpdate::Refit => true,
            TlasUpdate::Auto => {
                s.scene.tlas_refits_since_rebuild() < TlasUpdate::AUTO_REBUILD_AFTER_REFITS
            }
        };
    let mut records = Uploads::default();
    for (slot, bytes) in std::mem::take(&mut s.pending_records) {
        if let Some(hw) = s.scene.hardware.as_mut() {
            hw.set_record(slot, &bytes);
        }
        records.push(
            &s.scene.instance_table.buffer,
            slot as u64 * INSTANCE_RECORD_SIZE,
            &bytes,
        );
    }
    frame.flush(s, records);
    let mut rec = frame.recorder("tlas build");
    s.scene.update_tlas(&mut rec, slots, refit);
    s.tlas_rebuild = false;
    s.tlas_refit = false;
}

/// Step 6b, hardware backend only: the driver's BLASes of the geometries built or refitted in
/// step 5 (from the triangle pool those builds wrote) and its TLAS over the instance records
/// step 6 uploaded. The driver's TLAS is rebuilt in every task that changed a BLAS, even when a
/// `BvhBuildTask` deferred the software TLAS: a driver TLAS must not keep instances of a BLAS
/// whose triangles moved or were replaced.
fn record_hardware_structures(frame: &mut Frame<'_>, s: &mut State) {
    if s.scene.hardware.is_none() {
        return;
    }
    let mut rec = frame.recorder("blas build");
    if let Some(hw) = s.scene.hardware.as_mut() {
        hw.record(&mut rec, s.scene.triangles.buffer());
    }
}

/// Instance bookkeeping (after the records are recorded): a new instance, or one given another
/// geometry, gets a new lighting cache (a move keeps it).
fn register_instances(s: &mut State, instances: &[&InstanceTask], serial: u64) {
    for t in instances {
        if let Ok(g) = s.geometries.get_mut(t.input.geometry) {
            g.last_used = serial;
        }
        if let Ok(slot) = s.instances.get_mut(t.handle) {
            let new_cache = slot
                .input
                .as_ref()
                .is_none_or(|o| o.geometry != t.input.geometry);
            slot.input = Some(t.input.clone());
            slot.last_used = serial;
            if new_cache {
                s.cache.register(t.handle.index, serial);
            }
        }
        s.any_instance = true;
        s.counts.instance_tasks += 1;
    }
}

/// The direct lighting cache: grows what a read-back asked for, and allocates the waiting
/// instances whose BLAS is built (headers and scratch checked by the plan).
fn allocate_caches(frame: &mut Frame<'_>, s: &mut State) {
    s.cache
        .prepare_task(frame.encoder, s.instances.slot_count(), frame.serial);
    let jobs = s.cache_jobs();
    if jobs.is_empty() {
        s.cache.give_back_idle_memory();
        return;
    }
    let serial = frame.serial;
    let mut rec = frame.recorder("cache allocation");
    s.cache
        .record_allocations(&mut rec, s.scene.triangles.buffer(), &jobs, serial);
}

/// Step 7: one render task, on its effect.
fn record_render_task(frame: &mut Frame<'_>, s: &mut State, route: &Route<'_>) {
    if let Route::RayBatch(t) = route {
        frame.ws.held.push(t.rays.clone());
        frame.ws.held.push(t.hits.clone());
    }
    // The target's geometry as this task left it (an instance update earlier in the container
    // may have given it another geometry).
    let transfer_triangles = match route {
        Route::Transfer(t) => s
            .instance_geometry(t.target)
            .ok()
            .flatten()
            .map_or(0, |d| d.triangles),
        _ => 0,
    };
    let tracing = matches!(
        route,
        Route::RayBatch(_) | Route::Injection(_) | Route::Trace(_)
    );
    if tracing && s.scene.leaf_test() == LeafTest::OpaqueOnly {
        s.counts.opaque_only_traces += 1;
    }
    let inputs = Inputs {
        scene: s.scene.scene_buffers(),
        cache: &mut s.cache,
        transfer_triangles,
        serial: frame.serial,
    };
    let queue = frame.queue;
    let mut rec = frame.recorder("");
    s.effects.record(&mut rec, queue, inputs, route);
}
