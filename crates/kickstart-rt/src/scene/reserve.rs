//! The scene's pool allocations of one GPU task, simulated by `build_gpu_task`'s plan on copies
//! of the pools' ledgers: the same allocations, of the same sizes, in the same order as the
//! record phase makes them ([`GpuScene::alloc_staged`], [`GpuScene::build_blas`]). A task whose
//! allocations would exceed the device's binding size is refused here, before anything changed,
//! with the error the record phase used to return midway; the record phase then cannot fail.

use crate::error::{Error, Result};
use crate::scene::gpu_scene::{BlasTotals, GpuScene, NODE_BYTES, TRIANGLE_BYTES};
use crate::scene::lbvh::Lbvh;
use crate::scene::pool::{Ledger, Pool, Range};

/// Copies of the scene pools' ledgers, advanced by the allocations a task will make.
pub(crate) struct SceneReservation {
    max: u64,
    staged: Ledger,
    triangles: Ledger,
    nodes: Ledger,
    orders: Ledger,
    topologies: Ledger,
}

impl SceneReservation {
    /// The pools as the record phase will find them: with the ranges no task from
    /// `oldest_in_flight` on reads released (its first step, [`GpuScene::collect`]).
    pub fn of(scene: &GpuScene, oldest_in_flight: u64) -> Self {
        let copy = |pool: &Pool| {
            let mut ledger = pool.ledger().clone();
            ledger.collect(oldest_in_flight);
            ledger
        };
        SceneReservation {
            max: scene.max_binding(),
            staged: copy(&scene.staged),
            triangles: copy(&scene.triangles),
            nodes: copy(&scene.nodes),
            orders: copy(&scene.orders),
            topologies: copy(&scene.topologies),
        }
    }

    /// What [`GpuScene::reserve_staged`] does before a task's staged allocations of `triangles`
    /// in all.
    pub fn reserve_staged(&mut self, triangles: u64) {
        self.staged.reserve(triangles, self.max);
    }

    /// What [`GpuScene::reserve_blas`] does before a task's BLAS builds (`(triangles,
    /// keep_for_refit)` each).
    pub fn reserve_blas(&mut self, builds: &[(u32, bool)]) {
        let totals = BlasTotals::of(builds);
        self.triangles.reserve(totals.triangles, self.max);
        self.nodes.reserve(totals.nodes, self.max);
        self.orders.reserve(totals.orders, self.max);
        self.topologies.reserve(totals.topology_words, self.max);
    }

    /// What [`GpuScene::alloc_staged`] allocates for `triangles` ingested triangles of geometry
    /// `name`.
    pub fn staged(&mut self, triangles: u32, name: &str) -> Result<Range> {
        let what = || format!("staged triangles of geometry `{name}`");
        reserve(&mut self.staged, triangles, self.max, what, TRIANGLE_BYTES)
    }

    /// What [`GpuScene::alloc_opacity`] allocates for `elements` elements of opacity
    /// micro-maps of geometry `name`.
    pub fn opacity(&mut self, elements: u32, name: &str) -> Result<Range> {
        let what = || format!("opacity micro-maps of geometry `{name}`");
        reserve(
            &mut self.triangles,
            elements,
            self.max,
            what,
            TRIANGLE_BYTES,
        )
    }

    /// What [`GpuScene::build_blas`] allocates for a BLAS of `n` triangles of geometry `name`
    /// (in `GpuScene::alloc_blas`'s order).
    pub fn blas(&mut self, n: u32, keep_for_refit: bool, name: &str) -> Result<()> {
        let max = self.max;
        let what = |part: &'static str| move || format!("{part} of geometry `{name}`");
        reserve(
            &mut self.triangles,
            n,
            max,
            what("BLAS triangles"),
            TRIANGLE_BYTES,
        )?;
        let nodes = Lbvh::node_count(n);
        reserve(&mut self.nodes, nodes, max, what("BLAS nodes"), NODE_BYTES)?;
        // The build's scratch is bound whole too (a batch of builds is split to fit; one
        // build cannot be).
        let scratch = Lbvh::largest_build_binding_bytes(n);
        if scratch > max {
            return Err(Error::OutOfDeviceMemory {
                what: what("BLAS build scratch")(),
                bytes: scratch,
                limit: max,
            });
        }
        if keep_for_refit {
            reserve(&mut self.orders, n, max, what("sort order"), 4)?;
            let words = Lbvh::topology_words(n);
            reserve(&mut self.topologies, words, max, what("refit topology"), 4)?;
        }
        Ok(())
    }
}

/// `len` elements of `ledger`, or the error that names `what` and the bytes the pool would
/// need (`element` bytes each).
fn reserve(
    ledger: &mut Ledger,
    len: u32,
    max: u64,
    what: impl FnOnce() -> String,
    element: u64,
) -> Result<Range> {
    ledger
        .alloc(len, max)
        .ok_or_else(|| Error::OutOfDeviceMemory {
            what: what(),
            bytes: ledger.used_bytes() + len as u64 * element,
            limit: max,
        })
}
