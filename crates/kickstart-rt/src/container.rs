//! Task containers: what one GPU task will do, filled on any thread.

use crate::tasks::{BvhTask, RenderTask};

/// The tasks of one GPU task, in scheduling order. Create with
/// [`crate::ExecuteContext::create_task_container`], fill (on any thread: it is `Send`, and
/// scheduling takes `&mut self`), then hand to [`crate::ExecuteContext::build_gpu_task`].
///
/// Scheduling never fails: every field is validated by `build_gpu_task`, before it records anything.
#[derive(Debug)]
pub struct TaskContainer {
    pub(crate) context: u32,
    pub(crate) bvh_tasks: Vec<BvhTask>,
    pub(crate) render_tasks: Vec<RenderTask>,
}

impl TaskContainer {
    pub(crate) fn new(context: u32) -> Self {
        TaskContainer {
            context,
            bvh_tasks: Vec::new(),
            render_tasks: Vec::new(),
        }
    }

    /// Adds a geometry, instance or BVH build task. BVH tasks run before render tasks.
    pub fn schedule_bvh_task(&mut self, task: impl Into<BvhTask>) {
        self.bvh_tasks.push(task.into());
    }

    /// Adds a render task; render tasks run in the order scheduled.
    pub fn schedule_render_task(&mut self, task: RenderTask) {
        self.render_tasks.push(task);
    }

    /// Number of BVH tasks scheduled.
    pub fn bvh_task_count(&self) -> usize {
        self.bvh_tasks.len()
    }

    /// Number of render tasks scheduled.
    pub fn render_task_count(&self) -> usize {
        self.render_tasks.len()
    }

    /// Whether nothing is scheduled.
    pub fn is_empty(&self) -> bool {
        self.bvh_tasks.is_empty() && self.render_tasks.is_empty()
    }
}
