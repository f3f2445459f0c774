//! The plan's last check: the device memory a task's record phase will allocate. The pools,
//! tables, TLAS and lighting cache grow while the task records; each growth that would exceed
//! the device's binding size is found here first, by running the record phase's allocations
//! (same order, same sizes) on copies of the bookkeeping, and refused with the
//! [`crate::Error::OutOfDeviceMemory`] the record phase used to return midway, after earlier
//! steps had changed the context. What this check proves is what lets the record phase be
//! infallible.

use std::collections::hash_map::{Entry, HashMap};

use super::plan::{FramePlan, Reserved};
use super::state::{geometry_task_work, State};
use crate::error::Result;
use crate::handles::GeometryHandle;
use crate::scene::gpu_scene::PendingBvh;
use crate::scene::opacity::{elements as opacity_elements, geometry_level};
use crate::scene::reserve::SceneReservation;
use crate::tasks::*;

/// A geometry as step 5 will find it: its pending BVH work and what a build allocates for it.
#[derive(Clone, Copy)]
struct Queued<'a> {
    handle: GeometryHandle,
    /// The pending work (taken, as step 5 takes it, when the step is predicted).
    pending: Option<PendingBvh>,
    triangles: u32,
    allow_update: bool,
    name: &'a str,
}

/// One BVH step of step 5.
struct BlasStep<'a> {
    handle: GeometryHandle,
    work: PendingBvh,
    triangles: u32,
    allow_update: bool,
    name: &'a str,
}

/// Refuses `plan` when an allocation of its record phase would exceed the device's limit;
/// otherwise returns what the record phase will do that allocates.
pub(super) fn check(s: &State, plan: &FramePlan<'_>) -> Result<Reserved> {
    let (geometry_slots, instance_slots) = (s.geometries.slot_count(), s.instances.slot_count());
    s.scene.check_tables(geometry_slots, instance_slots)?;
    let oldest = s.oldest_in_flight();
    let mut pools = SceneReservation::of(&s.scene, oldest);
    // `record::allocate_staged`: an update reuses its geometry's range; room for all of them is
    // made first.
    let mut staged = Vec::new();
    for (task, extents) in &plan.geometries {
        let Ok(slot) = s.geometries.get(task.handle) else {
            continue;
        };
        let reuses = matches!(
            (&slot.data, task.operation),
            (Some(d), TaskOperation::Update) if d.gpu.staged.is_some()
        );
        if !reuses {
            let triangles: u32 = extents.iter().map(|e| e.triangles).sum();
            staged.push((triangles, task.input.name.as_str()));
        }
    }
    let staged_triangles = staged.iter().map(|(t, _)| u64::from((*t).max(1))).sum();
    pools.reserve_staged(staged_triangles);
    for (triangles, name) in staged {
        pools.staged(triangles, name)?;
    }
    // `record::allocate_staged`: cutout geometry's micro-maps, reused where the size matches.
    for (task, extents) in &plan.geometries {
        let (Ok(slot), Some(level)) = (s.geometries.get(task.handle), geometry_level(&task.input))
        else {
            continue;
        };
        let triangles: u32 = extents.iter().map(|e| e.triangles).sum();
        let need = opacity_elements(triangles, level);
        let existing = slot.data.as_ref().and_then(|d| d.gpu.opacity);
        if !existing.is_some_and(|m| m.level == level && m.range.len == need) {
            pools.opacity(need, &task.input.name)?;
        }
    }
    let blas = blas_work(s, plan);
    let blas_builds: Vec<(u32, bool)> = blas
        .iter()
        .filter(|q| q.work == PendingBvh::Build)
        .map(|q| (q.triangles, q.allow_update))
        .collect();
    pools.reserve_blas(&blas_builds);
    for q in &blas {
        if q.work == PendingBvh::Build {
            pools.blas(q.triangles, q.allow_update, q.name)?;
        }
    }
    let tlas = tlas_updates(s, plan, !blas.is_empty());
    if tlas {
        s.scene.check_tlas(instance_slots)?;
    }
    s.cache.check_headers(instance_slots, oldest)?;
    for t in &plan.instances {
        if let Some(triangles) = instance_triangles(s, plan, t) {
            s.cache.check_allocation(triangles)?;
        }
    }
    Ok(Reserved {
        blas: blas.iter().map(|q| (q.handle, q.work)).collect(),
        blas_builds,
        staged_triangles,
        tlas,
    })
}

/// Step 5's BVH work, predicted: the geometries' pending work after this task's ingestions
/// (`record::register_geometries`), then the queue taken in order up to
/// `max_blas_build_count` (`record::build_blases`).
fn blas_work<'a>(s: &'a State, plan: &'a FramePlan<'_>) -> Vec<BlasStep<'a>> {
    let Some(build) = plan.build else {
        return Vec::new();
    };
    let known = |h: GeometryHandle| {
        let d = s.geometries.get(h).ok()?.data.as_ref()?;
        Some(Queued {
            handle: h,
            pending: d.gpu.pending,
            triangles: d.gpu.triangles,
            allow_update: d.allow_update,
            name: &d.name,
        })
    };
    let mut queued: HashMap<GeometryHandle, Queued<'a>> = HashMap::new();
    let mut queue: Vec<GeometryHandle> = s.blas_queue.iter().copied().collect();
    for (task, extents) in &plan.geometries {
        let Ok(slot) = s.geometries.get(task.handle) else {
            continue;
        };
        let work = geometry_task_work(slot.data.as_ref(), task, s.scene.hardware.is_some());
        let fresh = Queued {
            handle: task.handle,
            pending: None,
            triangles: extents.iter().map(|e| e.triangles).sum(),
            allow_update: task.input.allow_update,
            name: &task.input.name,
        };
        // A registered geometry keeps its name and update flag; its triangles are the
        // ingestion's.
        let q = queued
            .entry(task.handle)
            .or_insert_with(|| known(task.handle).unwrap_or(fresh));
        q.triangles = fresh.triangles;
        if q.pending.is_none() {
            queue.push(task.handle);
        }
        // A queued build stays a build (the refit needs a built tree).
        if q.pending != Some(PendingBvh::Build) {
            q.pending = Some(work);
        }
    }
    let mut steps = Vec::new();
    for h in queue {
        if steps.len() as u32 >= build.max_blas_build_count {
            break;
        }
        // A geometry not ingested in this task is as the state has it (none for a destroyed
        // one, or one without data: step 5 skips those).
        let q = match queued.entry(h) {
            Entry::Occupied(e) => e.into_mut(),
            Entry::Vacant(e) => match known(h) {
                Some(q) => e.insert(q),
                None => continue,
            },
        };
        if let Some(work) = q.pending.take() {
            steps.push(step(q, work));
        }
    }
    steps
}

/// The step that does `work` on `q`.
fn step<'a>(q: &Queued<'a>, work: PendingBvh) -> BlasStep<'a> {
    BlasStep {
        handle: q.handle,
        work,
        triangles: q.triangles,
        allow_update: q.allow_update,
        name: q.name,
    }
}

/// Whether step 6 updates the TLAS: the build task (or its absence) asks for it, and something
/// it depends on changed before or in this task (`record::clear_dead_slots`,
/// `record::queue_instance_records`, `record::build_blases`).
fn tlas_updates(s: &State, plan: &FramePlan<'_>, bvh_work: bool) -> bool {
    let asked = plan.build.is_none_or(|b| b.build_tlas);
    let dead_instances = !s.dead_instance_slots.is_empty()
        || (!s.dead_geometry_slots.is_empty() && !s.instances_of_dead_geometry().is_empty());
    asked
        && (s.tlas_rebuild
            || s.tlas_refit
            || dead_instances
            || !plan.instances.is_empty()
            || bvh_work)
}

/// Triangles of the geometry an instance task gives its instance: registered in this task, or
/// earlier.
fn instance_triangles(s: &State, plan: &FramePlan<'_>, t: &InstanceTask) -> Option<u32> {
    let here = plan
        .geometries
        .iter()
        .find(|(g, _)| g.handle == t.input.geometry);
    match here {
        Some((_, extents)) => Some(extents.iter().map(|e| e.triangles).sum()),
        None => Some(
            s.geometries
                .get(t.input.geometry)
                .ok()?
                .data
                .as_ref()?
                .triangles,
        ),
    }
}
