//! The traversal as the passes that trace rays see it: the scene's buffers bound at
//! `@group(0)`, the WGSL traversal module they import (`#import scene/traversal`, see
//! [`crate::gpu::compose`]), and the name of its stack. This is the one seam between the scene and
//! every tracing pass (ray batches, debug views, trace tasks, the lighting cache's injection), so
//! another traversal backend can stand in its place: a module of the same name and functions, and
//! the buffers it binds. The hardware backend is exactly that: `scene/traversal_ray_query`
//! composed in place of `scene/traversal` ([`library`]), binding the TLAS the driver built.

use std::sync::OnceLock;

use crate::device::TraversalBackend;
use crate::gpu::compose::ShaderLibrary;
use crate::gpu::layout::BoundLayout;
use crate::gpu::reflect::{named_entries, ReflectedShader, ShaderBinding};

/// The traversal module every tracing pass imports.
const TRAVERSAL_MODULE: &str = "scene/traversal";
/// The hardware backend's module of the same interface.
const RAY_QUERY_MODULE: &str = "scene/traversal_ray_query";

/// The module that says whether the software leaf loop tests opacity micro-maps.
const CUTOUT_TEST_MODULE: &str = "scene/cutout_test";
/// Its stand-in for scenes without cutout geometry (the test compiled away).
const CUTOUT_TEST_OFF_MODULE: &str = "scene/cutout_test_off";

/// Which build of the traversal a tracing pass binds. Opaque geometry must pay nothing for
/// cutouts: while the scene holds no cutout geometry, the software backend traces with a leaf
/// loop compiled without the opacity test ([`LeafTest::OpaqueOnly`]). The hardware backend has
/// one build: the driver confirms only triangles its BLAS marks non-opaque.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum LeafTest {
    /// Tests cutout geometry's opacity micro-maps (correct for every scene).
    WithCutouts,
    /// No opacity test (correct only while the scene holds no cutout geometry).
    OpaqueOnly,
}

impl LeafTest {
    /// The build that traces a scene with (`cutouts`) or without cutout geometry on `backend`.
    pub fn of(backend: TraversalBackend, cutouts: bool) -> Self {
        match backend {
            TraversalBackend::Software if !cutouts => LeafTest::OpaqueOnly,
            _ => LeafTest::WithCutouts,
        }
    }

    /// The builds a pass on `backend` may bind.
    pub fn all(backend: TraversalBackend) -> &'static [LeafTest] {
        match backend {
            TraversalBackend::Software => &[LeafTest::WithCutouts, LeafTest::OpaqueOnly],
            TraversalBackend::HardwareRayQuery => &[LeafTest::WithCutouts],
        }
    }

    /// `library` with this build's leaf test behind `#import scene/cutout_test`.
    pub fn apply(self, library: &mut ShaderLibrary) {
        if self == LeafTest::OpaqueOnly {
            library.substitute(CUTOUT_TEST_MODULE, CUTOUT_TEST_OFF_MODULE);
        }
    }
}

/// One value per traversal build (a pass's pipeline), each made on first use.
pub(crate) struct PerLeafTest<T>([OnceLock<T>; 2]);

impl<T> Default for PerLeafTest<T> {
    fn default() -> Self {
        PerLeafTest([OnceLock::new(), OnceLock::new()])
    }
}

impl<T> PerLeafTest<T> {
    /// The value of build `leaf`, made by `make` if there is none yet.
    pub fn get_or_init(&self, leaf: LeafTest, make: impl FnOnce() -> T) -> &T {
        self.0[leaf as usize].get_or_init(make)
    }

    /// The value of build `leaf`, if made.
    #[cfg_attr(not(test), allow(dead_code))]
    pub fn get(&self, leaf: LeafTest) -> Option<&T> {
        self.0[leaf as usize].get()
    }
}

/// The SDK's shader modules with `backend`'s traversal behind `#import scene/traversal`, testing
/// cutouts (see [`LeafTest`] for the build without).
pub(crate) fn library(backend: TraversalBackend) -> ShaderLibrary {
    let mut library = ShaderLibrary::builtin();
    if backend == TraversalBackend::HardwareRayQuery {
        library.substitute(TRAVERSAL_MODULE, RAY_QUERY_MODULE);
    }
    library
}

/// A tracing pass's modules `roots` composed for `backend` with the leaf test `leaf` (see
/// [`library`]).
pub(crate) fn compose(
    backend: TraversalBackend,
    leaf: LeafTest,
    roots: &[&str],
    params: &[(&str, &str)],
) -> ReflectedShader {
    let mut library = library(backend);
    leaf.apply(&mut library);
    ReflectedShader::compose_in(&library, roots, params)
}

/// The private arrays a traversal pass of `backend` never reads before writing (the software
/// stack, [`TRAVERSAL_STACK`]), whose zero fill its pipeline may drop.
pub(crate) fn uninitialized(backend: TraversalBackend) -> &'static [&'static str] {
    match backend {
        TraversalBackend::Software => &[TRAVERSAL_STACK],
        TraversalBackend::HardwareRayQuery => &[],
    }
}

/// The `@group(0)` bindings of `backend`'s traversal module, as it declares them.
fn scene_bindings(backend: TraversalBackend) -> &'static [ShaderBinding] {
    static SOFTWARE: OnceLock<Vec<ShaderBinding>> = OnceLock::new();
    static HARDWARE: OnceLock<Vec<ShaderBinding>> = OnceLock::new();
    let cell = match backend {
        TraversalBackend::Software => &SOFTWARE,
        TraversalBackend::HardwareRayQuery => &HARDWARE,
    };
    cell.get_or_init(|| {
        compose(backend, LeafTest::WithCutouts, &[TRAVERSAL_MODULE], &[])
            .reflection()
            .group_bindings(0)
    })
}

/// The scene as the traversal module binds it at `@group(0)` (layouts in
/// docs/ray-tracing-core.md).
#[derive(Clone, Copy)]
pub(crate) struct SceneBuffers<'a> {
    /// TLAS nodes (`rt_tlas_nodes`).
    pub tlas_nodes: &'a wgpu::Buffer,
    /// Instance table (`rt_instances`).
    pub instances: &'a wgpu::Buffer,
    /// Geometry table (`rt_geometries`).
    pub geometries: &'a wgpu::Buffer,
    /// BLAS node pool (`rt_blas_nodes`).
    pub blas_nodes: &'a wgpu::Buffer,
    /// Triangle pool (`rt_triangles`).
    pub triangles: &'a wgpu::Buffer,
    /// The driver's TLAS (`rt_tlas`) on the hardware backend; `None` on the software one.
    pub tlas: Option<&'a wgpu::Tlas>,
    /// Whether some geometry of the scene is cutout geometry (has opacity micro-maps).
    pub cutouts: bool,
}

impl SceneBuffers<'_> {
    /// The backend these buffers are for: the hardware one when they carry a TLAS.
    pub fn backend(&self) -> TraversalBackend {
        match self.tlas {
            Some(_) => TraversalBackend::HardwareRayQuery,
            None => TraversalBackend::Software,
        }
    }

    /// The traversal build that traces these buffers correctly and fastest.
    pub fn leaf_test(&self) -> LeafTest {
        LeafTest::of(self.backend(), self.cutouts)
    }

    /// The explicit layout of the `@group(0)` scene bindings, as the traversal module declares
    /// them, for pipelines built with explicit layouts.
    pub fn layout(device: &wgpu::Device, backend: TraversalBackend) -> BoundLayout {
        let entries: Vec<_> = scene_bindings(backend)
            .iter()
            .map(ShaderBinding::layout_entry)
            .collect();
        BoundLayout::new(device, "kickstart-rt scene", &entries)
    }

    /// The `@group(0)` bind group of a pipeline that imports the traversal module, each buffer
    /// at the binding the module declares for it.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        pipeline: &wgpu::ComputePipeline,
    ) -> wgpu::BindGroup {
        let mut resources = vec![
            ("rt_tlas_nodes", self.tlas_nodes.as_entire_binding()),
            ("rt_instances", self.instances.as_entire_binding()),
            ("rt_geometries", self.geometries.as_entire_binding()),
            ("rt_blas_nodes", self.blas_nodes.as_entire_binding()),
            ("rt_triangles", self.triangles.as_entire_binding()),
        ];
        if let Some(tlas) = self.tlas {
            resources.push(("rt_tlas", tlas.as_binding()));
        }
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("kickstart-rt scene"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &named_entries(
                "kickstart-rt scene",
                scene_bindings(self.backend()),
                &resources,
            ),
        })
    }
}

/// The traversal module's stack (`var<private> rt_stack`): written before it is read, so the
/// passes that include the module may drop its zero fill ([`traversal_pipeline`]).
pub(crate) const TRAVERSAL_STACK: &str = "rt_stack";
