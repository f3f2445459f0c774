//! The plan phase of `build_gpu_task`: every check a container must pass, run against the
//! context's state without changing it, producing the [`FramePlan`] the record phase carries
//! out. A container refused here leaves the context exactly as it was.

use std::collections::HashSet;

use super::effects::Route;
use super::state::{GeometryData, GeometrySlot, State};
use super::validate::{self, ComponentExtent};
use crate::cache::inject::Injector;
use crate::container::TaskContainer;
use crate::denoise;
use crate::error::{Error, Result};
use crate::handles::*;
use crate::scene::gpu_scene::PendingBvh;
use crate::tasks::*;
use crate::trace::debug_view::DebugView;
use crate::trace::tasks::TracePasses;

/// What one container asks for, checked: the record phase carries it out in this order.
pub(super) struct FramePlan<'c> {
    /// Skinning tasks, recorded before everything else.
    pub skins: Vec<&'c SkinningTask>,
    /// Geometry registrations and updates, with each component's byte extents.
    pub geometries: Vec<(&'c GeometryTask, Vec<ComponentExtent>)>,
    /// Instance registrations and updates.
    pub instances: Vec<&'c InstanceTask>,
    /// The last BVH build task of the container (it decides).
    pub build: Option<BvhBuildTask>,
    /// The render tasks in the order scheduled.
    pub render: Vec<Route<'c>>,
    /// What the record phase allocates, checked against the device's limits (filled in by the
    /// reserve module's check, which runs after this plan).
    pub reserved: Reserved,
}

/// What the check predicted of the record phase; it asserts the same in debug builds, so that
/// a record step changed without its simulation here fails the tests.
#[derive(Debug, Default, PartialEq, Eq)]
pub(super) struct Reserved {
    /// Step 5's BVH work in order: each geometry and whether it is (re)built or refitted.
    pub blas: Vec<(GeometryHandle, PendingBvh)>,
    /// Step 5's BLAS builds (not refits), `(triangles, keep_for_refit)` each: what the pools
    /// make room for before them.
    pub blas_builds: Vec<(u32, bool)>,
    /// Step 1's staged allocations, triangles in all.
    pub staged_triangles: u64,
    /// Whether step 6 updates the TLAS.
    pub tlas: bool,
}

/// Checks every task of `c` against the context's state `s` and the device's `limits`.
pub(super) fn plan<'c>(
    s: &State,
    c: &'c TaskContainer,
    limits: &wgpu::Limits,
) -> Result<FramePlan<'c>> {
    let mut plan = FramePlan {
        skins: Vec::new(),
        geometries: Vec::new(),
        instances: Vec::new(),
        build: None,
        render: Vec::new(),
        reserved: Reserved::default(),
    };
    let mut geometries_here = HashSet::new();
    let mut instances_here = HashSet::new();
    for task in &c.bvh_tasks {
        match task {
            BvhTask::Geometry(t) => {
                let extents = geometry_task(s, t, &geometries_here)?;
                check_driver_blas(s, &extents, limits)?;
                geometries_here.insert(t.handle);
                plan.geometries.push((t, extents));
            }
            BvhTask::Instance(t) => {
                instance_task(s, t, &instances_here, &geometries_here)?;
                check_driver_tlas(s, t, limits)?;
                instances_here.insert(t.handle);
                plan.instances.push(t);
            }
            BvhTask::Build(t) => {
                validate::bvh_build(t)?;
                plan.build = Some(*t);
            }
            BvhTask::Skin(t) => {
                validate::skinning_task(t, limits)?;
                plan.skins.push(t);
            }
        }
    }
    let mut unsupported = None;
    for task in &c.render_tasks {
        validate::render_task(task, limits)?;
        match route(s, task, limits)? {
            Some(r) => plan.render.push(r),
            None => {
                unsupported.get_or_insert(task.name());
            }
        }
    }
    match unsupported {
        Some(task) => Err(Error::Unsupported { task }),
        None => Ok(plan),
    }
}

/// Checks a geometry task's handle, operation and input; returns its component extents.
fn geometry_task(
    s: &State,
    t: &GeometryTask,
    registered_here: &HashSet<GeometryHandle>,
) -> Result<Vec<ComponentExtent>> {
    const TASK: &str = "GeometryTask";
    let slot: &GeometrySlot = s.geometries.get(t.handle)?;
    let extents = validate::geometry_input(&t.input)?;
    let refuse = |why: String| Err(Error::input(TASK, "operation", t.operation, why));
    match (t.operation, &slot.data) {
        (TaskOperation::Register, data)
            if data.is_some() || registered_here.contains(&t.handle) =>
        {
            refuse("this geometry is already registered; use TaskOperation::Update".into())
        }
        (TaskOperation::Update, None) => refuse("the geometry was never registered".into()),
        (TaskOperation::Update, Some(d)) if !d.allow_update => refuse(format!(
            "geometry `{}` was registered without allow_update",
            d.name
        )),
        (TaskOperation::Update, Some(d)) => {
            let n: u32 = extents.iter().map(|e| e.triangles).sum();
            if n != d.triangles {
                return Err(Error::input(
                    TASK,
                    "input.components",
                    format!("{n} triangles"),
                    format!(
                        "an Update of geometry `{}` must keep its {} triangles (its BVH is refitted); register a new geometry to change the topology",
                        d.name, d.triangles
                    ),
                ));
            }
            Ok(extents)
        }
        _ => Ok(extents),
    }
}

/// On the hardware backend, a geometry's triangles must fit one driver BLAS: its three vertices
/// a triangle within the device's `max_blas_primitive_count` (software Vulkan allows 2^24 − 1).
/// wgpu 30 checks a BLAS's vertex count, not its triangle count, against that limit, and the
/// driver BLAS lists each triangle's three vertices (no index buffer).
fn check_driver_blas(s: &State, extents: &[ComponentExtent], limits: &wgpu::Limits) -> Result<()> {
    let n: u64 = extents.iter().map(|e| e.triangles as u64).sum();
    let limit = limits.max_blas_primitive_count as u64;
    if s.scene.hardware.is_some() && 3 * n > limit {
        return Err(Error::input(
            "GeometryTask",
            "input.components",
            format!("{n} triangles"),
            format!(
                "the hardware ray-query backend builds one driver BLAS per geometry, of 3 vertices a triangle, and the device's max_blas_primitive_count is {limit} (wgpu counts vertices against it): split the mesh, or use BackendChoice::Software"
            ),
        ));
    }
    Ok(())
}

/// On the hardware backend, an instance's slot must fit the driver's TLAS: below the device's
/// `max_tlas_instance_count`.
fn check_driver_tlas(s: &State, t: &InstanceTask, limits: &wgpu::Limits) -> Result<()> {
    let limit = limits.max_tlas_instance_count;
    if s.scene.hardware.is_some() && t.handle.index() >= limit {
        return Err(Error::input(
            "InstanceTask",
            "handle",
            t.handle.index(),
            format!(
                "the hardware ray-query backend's TLAS holds the device's max_tlas_instance_count ({limit}) instance slots"
            ),
        ));
    }
    Ok(())
}

/// Checks an instance task's handles, operation and input.
fn instance_task(
    s: &State,
    t: &InstanceTask,
    instances_here: &HashSet<InstanceHandle>,
    geometries_here: &HashSet<GeometryHandle>,
) -> Result<()> {
    const TASK: &str = "InstanceTask";
    let slot = s.instances.get(t.handle)?;
    let known = slot.input.is_some() || instances_here.contains(&t.handle);
    match t.operation {
        TaskOperation::Register if known => {
            return Err(Error::input(
                TASK,
                "operation",
                t.operation,
                "this instance is already registered; use TaskOperation::Update",
            ));
        }
        TaskOperation::Update if !known => {
            return Err(Error::input(
                TASK,
                "operation",
                t.operation,
                "the instance was never registered",
            ));
        }
        _ => {}
    }
    let g = s.geometries.get(t.input.geometry)?;
    if g.data.is_none() && !geometries_here.contains(&t.input.geometry) {
        return Err(Error::input(
            TASK,
            "input.geometry",
            t.input.geometry,
            "the geometry has no registered mesh: schedule its GeometryTask first",
        ));
    }
    validate::instance_input(&t.input)
}

/// The effect that records `task`, after the checks that need the context's state; `None` for a
/// task this version does not support (it was fully validated, and is refused as unsupported).
fn route<'c>(s: &State, task: &'c RenderTask, limits: &wgpu::Limits) -> Result<Option<Route<'c>>> {
    let route = match task {
        RenderTask::TraceRays(t) => Route::RayBatch(t),
        RenderTask::DirectLightingInjection(t) => {
            Injector::check_fits(t, s.cache.planned_capacity(), limits)?;
            Route::Injection(t)
        }
        RenderTask::DirectLightTransfer(t) => {
            check_transfer(s, t)?;
            Route::Transfer(t)
        }
        t => match (t.denoise_common(), t.trace_common()) {
            (Some(c), _) => {
                let Some(job) = denoise::route(t) else {
                    return Ok(None);
                };
                denoise::check_task(t, &job, &s.denoisers.get(c.context)?.input)?;
                Route::Denoise(job)
            }
            (None, Some((common, output))) => return trace_route(t, common, output),
            (None, None) => return Ok(None),
        },
    };
    Ok(Some(route))
}

/// The route of a trace task: its pass for the default output, or the primary-ray debug view
/// it asks for (`None` for a view this version does not write).
fn trace_route<'c>(
    task: &'c RenderTask,
    common: &'c TraceTaskCommon,
    output: &'c TextureInput,
) -> Result<Option<Route<'c>>> {
    let kind = common.debug_parameters.debug_output_type;
    if kind == DebugOutputType::Default {
        let Some(job) = TracePasses::job(task) else {
            return Ok(None);
        };
        TracePasses::check(&job)?;
        return Ok(Some(Route::Trace(job)));
    }
    let size = output.texture().size();
    let vp = common.viewport.unwrap_or(Viewport {
        x: 0,
        y: 0,
        width: size.width,
        height: size.height,
    });
    let view = DebugView::new(kind, (vp.x, vp.y, vp.width, vp.height))?;
    Ok(view.map(|view| Route::DebugView {
        common,
        output,
        view,
    }))
}

/// Checks a transfer: both instances registered (in an earlier task), distinct, the target's
/// geometry allows transfer, and both geometries have the same triangle count.
fn check_transfer(s: &State, t: &DirectLightTransferTask) -> Result<()> {
    const TASK: &str = "DirectLightTransferTask";
    let geometry = |h: InstanceHandle, field: &'static str| -> Result<&GeometryData> {
        s.instance_geometry(h)?.ok_or_else(|| {
            Error::input(
                TASK,
                field,
                h,
                "the instance must be registered by an earlier GPU task",
            )
        })
    };
    let src = geometry(t.source, "source")?;
    let dst = geometry(t.target, "target")?;
    if t.source == t.target {
        return Err(Error::input(
            TASK,
            "target",
            t.target,
            "must differ from the source",
        ));
    }
    if !dst.allow_light_transfer_target {
        return Err(Error::input(
            TASK,
            "target",
            t.target,
            format!(
                "geometry `{}` was registered without allow_light_transfer_target",
                dst.name
            ),
        ));
    }
    if src.triangles != dst.triangles {
        return Err(Error::input(
            TASK,
            "target",
            t.target,
            format!(
                "the target's geometry has {} triangles, the source's {}: transfer maps primitive i to primitive i, so both need the same triangles in the same order",
                dst.triangles, src.triangles
            ),
        ));
    }
    Ok(())
}
