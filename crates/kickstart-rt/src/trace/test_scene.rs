//! Test helper: packs a CPU-built scene into the GPU layouts of docs/ray-tracing-core.md (BVH2
//! nodes, triangle soup, geometry and instance tables, TLAS), so traversal is tested without the
//! GPU builder; and the CPU oracle over instances (brute force with `cpu::intersect_triangle`
//! and the documented tie rule).

use crate::cpu::{intersect_triangle, CpuBvh, Ray, TriangleHit};
use crate::gpu::testing;
use crate::scene::traversal::SceneBuffers;
use bytemuck::{Pod, Zeroable};
use glam::{Affine3A, Vec3};

/// Leaf bit of a child ref.
const LEAF: u32 = 0x8000_0000;

/// A triangle, vertices in geometry space.
pub(crate) type Tri = [Vec3; 3];

/// One instance of a test scene.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TestInstance {
    /// Index into the scene's geometries.
    pub geometry: u32,
    /// Object to world.
    pub transform: Affine3A,
    /// Inclusion mask.
    pub mask: u32,
    /// Flags bit 0 (live and participating).
    pub live: bool,
}

impl TestInstance {
    /// A live instance visible to every mask.
    pub fn new(geometry: u32, transform: Affine3A) -> Self {
        TestInstance {
            geometry,
            transform,
            mask: 0xff,
            live: true,
        }
    }
}

/// A CPU oracle hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct OracleHit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
    pub instance: u32,
    pub primitive: u32,
}

#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy)]
struct GeometryRecord {
    node_base: u32,
    tri_base: u32,
    tri_count: u32,
    flags: u32,
    bounds_min: [f32; 4],
    bounds_max: [f32; 4],
    /// Opaque: no opacity micro-maps.
    opacity: [u32; 4],
}

#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy)]
struct InstanceRecord {
    object_to_world: [[f32; 4]; 3],
    world_to_object: [[f32; 4]; 3],
    geometry: u32,
    mask: u32,
    flags: u32,
    pad: u32,
    pad2: [u32; 4],
}

/// The three rows of an affine transform (row r = (m_r0, m_r1, m_r2, t_r)).
fn rows(a: &Affine3A) -> [[f32; 4]; 3] {
    let m = a.matrix3;
    let t = a.translation;
    std::array::from_fn(|r| [m.x_axis[r], m.y_axis[r], m.z_axis[r], t[r]])
}

fn dot_row(r: &[f32; 4], p: Vec3, w: f32) -> f32 {
    r[0] * p.x + r[1] * p.y + r[2] * p.z + r[3] * w
}

/// A node entry quadruple of f32 bits: (xyz, w bits).
fn entry(p: Vec3, w: u32) -> [u32; 4] {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits(), w]
}

/// A TLAS input: (instance index, world min, world max).
type Item = (u32, Vec3, Vec3);

/// A child: (ref, min, max).
type Child = (u32, Vec3, Vec3);
const EMPTY_CHILD: Child = (LEAF, Vec3::splat(1e30), Vec3::splat(-1e30));

fn push_node(out: &mut Vec<[u32; 4]>, l: Child, r: Child) {
    out.push(entry(l.1, l.0));
    out.push(entry(l.2, r.0));
    out.push(entry(r.1, 0));
    out.push(entry(r.2, 0));
}

/// BVH2 nodes of a BLAS (4 entries per node); leaf refs index `bvh.primitive_indices` slots,
/// which is the order the triangles are stored in.
fn pack_blas(bvh: &CpuBvh) -> Vec<[u32; 4]> {
    let nodes = &bvh.nodes;
    let mut out = Vec::new();
    if bvh.primitive_indices.is_empty() {
        push_node(&mut out, EMPTY_CHILD, EMPTY_CHILD);
        return out;
    }
    let leaf_ref = |i: usize| LEAF | ((nodes[i].count - 1) << 28) | nodes[i].first;
    if nodes[0].count > 0 {
        push_node(
            &mut out,
            (leaf_ref(0), nodes[0].min, nodes[0].max),
            EMPTY_CHILD,
        );
        return out;
    }
    let mut gpu_index = vec![u32::MAX; nodes.len()];
    let mut order = Vec::new();
    let mut stack = vec![0usize];
    while let Some(n) = stack.pop() {
        gpu_index[n] = order.len() as u32;
        order.push(n);
        for c in [nodes[n].first as usize, nodes[n].first as usize + 1] {
            if nodes[c].count == 0 {
                stack.push(c);
            }
        }
    }
    for &n in &order {
        let child = |c: usize| -> Child {
            let r = if nodes[c].count > 0 {
                leaf_ref(c)
            } else {
                gpu_index[c]
            };
            (r, nodes[c].min, nodes[c].max)
        };
        let f = nodes[n].first as usize;
        push_node(&mut out, child(f), child(f + 1));
    }
    out
}

/// A TLAS subtree over `items` (instance index, world min, world max): median split on the
/// widest centroid axis; a set of consecutive instance indices (≤ 8) becomes one leaf, so
/// multi-instance leaves are exercised too.
fn tlas_subtree(items: &mut [Item], out: &mut Vec<[u32; 4]>) -> Child {
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for it in items.iter() {
        lo = lo.min(it.1);
        hi = hi.max(it.2);
    }
    let mut ids: Vec<u32> = items.iter().map(|i| i.0).collect();
    ids.sort_unstable();
    if ids.len() <= 8 && ids.windows(2).all(|w| w[1] == w[0] + 1) {
        return (LEAF | ((ids.len() as u32 - 1) << 28) | ids[0], lo, hi);
    }
    let index = out.len() as u32 / 4;
    out.extend([[0; 4]; 4]);
    let (l, r) = split(items);
    let lc = tlas_subtree(l, out);
    let rc = tlas_subtree(r, out);
    let mut node = Vec::new();
    push_node(&mut node, lc, rc);
    out[index as usize * 4..index as usize * 4 + 4].copy_from_slice(&node);
    (index, lo, hi)
}

fn split(items: &mut [Item]) -> (&mut [Item], &mut [Item]) {
    let c = |i: &Item| i.1 + i.2;
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for it in items.iter() {
        lo = lo.min(c(it));
        hi = hi.max(c(it));
    }
    let e = hi - lo;
    let axis = if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    };
    items.sort_by(|a, b| c(a)[axis].total_cmp(&c(b)[axis]).then(a.0.cmp(&b.0)));
    let mid = items.len() / 2;
    items.split_at_mut(mid)
}

fn pack_tlas(mut items: Vec<Item>) -> Vec<[u32; 4]> {
    let mut out = vec![[0u32; 4]; 4];
    let (l, r) = match items.len() {
        0 => (EMPTY_CHILD, EMPTY_CHILD),
        1 => (tlas_subtree(&mut items, &mut out), EMPTY_CHILD),
        _ => {
            let (a, b) = split(&mut items);
            (tlas_subtree(a, &mut out), tlas_subtree(b, &mut out))
        }
    };
    let mut node = Vec::new();
    push_node(&mut node, l, r);
    out[..4].copy_from_slice(&node);
    out
}

/// The TLAS node buffer as the traversal reads it: `nodes` (4 `vec4` each; leaves name instance
/// slots) padded to C node slots, then C ref-table entries, entry i = (slot i, BLAS root 0): each
/// instance is one ref, as the SDK's TLAS at one ref per instance.
fn with_ref_table(mut nodes: Vec<[u32; 4]>, slots: usize) -> Vec<[u32; 4]> {
    let c = (nodes.len() / 4).max(slots).max(1);
    nodes.resize(4 * c, [0; 4]);
    nodes.extend((0..c as u32).map(|i| [i, 0, 0, 0]));
    nodes
}

/// A scene uploaded in the GPU layouts, with its CPU description for the oracle.
pub(crate) struct TestScene {
    /// Triangles per geometry (index = primitive index).
    pub geometries: Vec<Vec<Tri>>,
    /// Instances (index = instance slot).
    pub instances: Vec<TestInstance>,
    world_to_object: Vec<[[f32; 4]; 3]>,
    /// The TLAS buffer's contents (nodes, then the ref table).
    tlas: Vec<[u32; 4]>,
    tlas_nodes: wgpu::Buffer,
    instance_buf: wgpu::Buffer,
    geometry_buf: wgpu::Buffer,
    blas_nodes: wgpu::Buffer,
    triangles: wgpu::Buffer,
    /// The driver's BLASes and TLAS over the same triangles and instance records, on the
    /// hardware test pass (`testing::backend()`).
    hardware: Option<crate::scene::hardware::HardwareScene>,
}

/// A storage buffer with `data`.
/// Padded to one instance record (128 bytes): a binding must hold at least one element.
fn upload(data: &[u8]) -> wgpu::Buffer {
    if data.len() < 128 {
        let mut padded = data.to_vec();
        padded.resize(128, 0);
        testing::buffer_with(&padded)
    } else {
        testing::buffer_with(data)
    }
}

/// The triangle soup's buffer: also a BLAS input on the hardware pass, where the driver builds
/// its BLASes from it.
fn upload_triangles(data: &[u8], blas_input: bool) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    let mut usage =
        wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
    if blas_input {
        usage |= wgpu::BufferUsages::BLAS_INPUT;
    }
    let mut padded = data.to_vec();
    padded.resize(data.len().max(128), 0);
    testing::gpu()
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("test triangles"),
            contents: &padded,
            usage,
        })
}

/// The driver's acceleration structures over the packed scene: a BLAS per geometry from its
/// triangles in the soup, and a TLAS over the instance records, built as the context's
/// hardware backend builds them (the same `HardwareScene`).
fn driver_scene(
    geometries: &[GeometryRecord],
    instances: &[InstanceRecord],
    triangles: &wgpu::Buffer,
) -> crate::scene::hardware::HardwareScene {
    let mut hw = crate::scene::hardware::HardwareScene::new(&testing::gpu().device, 0);
    for (slot, g) in geometries.iter().enumerate() {
        hw.build(slot as u32, g.tri_base, g.tri_count, (false, false));
    }
    for (slot, record) in instances.iter().enumerate() {
        hw.set_record(slot as u32, bytemuck::bytes_of(record));
    }
    testing::run(|rec| hw.record(rec, triangles));
    hw
}

impl TestScene {
    /// Builds each geometry's BLAS with `CpuBvh`, a TLAS over the instances' world boxes, and
    /// uploads everything.
    pub fn new(geometries: Vec<Vec<Tri>>, instances: Vec<TestInstance>) -> Self {
        Self::new_on(testing::backend(), geometries, instances)
    }

    /// As [`TestScene::new`], for the software traversal whatever the test pass: for tests of
    /// its own exact rules (watertight edges, the tie rule, the inclusive `t` range), which the
    /// driver's triangle test does not promise.
    pub fn software(geometries: Vec<Vec<Tri>>, instances: Vec<TestInstance>) -> Self {
        Self::new_on(
            crate::device::TraversalBackend::Software,
            geometries,
            instances,
        )
    }

    /// The scene, with the driver's acceleration structures too when `backend` is the hardware
    /// one.
    fn new_on(
        backend: crate::device::TraversalBackend,
        geometries: Vec<Vec<Tri>>,
        instances: Vec<TestInstance>,
    ) -> Self {
        let mut blas = Vec::new();
        let mut soup: Vec<[u32; 4]> = Vec::new();
        let mut geo_records = Vec::new();
        for tris in &geometries {
            let bvh = CpuBvh::build(tris);
            let node_base = blas.len() as u32 / 4;
            let tri_base = soup.len() as u32 / 3;
            blas.extend(pack_blas(&bvh));
            for &p in &bvh.primitive_indices {
                let [a, b, c] = tris[p as usize];
                soup.push(entry(a, p));
                soup.push(entry(b, 0));
                soup.push(entry(c, 0));
            }
            let root = bvh.nodes[0];
            geo_records.push(GeometryRecord {
                node_base,
                tri_base,
                tri_count: bvh.primitive_indices.len() as u32,
                flags: 1,
                bounds_min: root.min.extend(0.0).to_array(),
                bounds_max: root.max.extend(0.0).to_array(),
                opacity: crate::scene::opacity::OPAQUE_RECORD,
            });
        }
        let mut items = Vec::new();
        let mut inst_records = Vec::new();
        let mut world_to_object = Vec::new();
        for (i, inst) in instances.iter().enumerate() {
            let w2o = rows(&inst.transform.inverse());
            world_to_object.push(w2o);
            inst_records.push(InstanceRecord {
                object_to_world: rows(&inst.transform),
                world_to_object: w2o,
                geometry: inst.geometry,
                mask: inst.mask,
                flags: inst.live as u32,
                pad: 0,
                pad2: [0; 4],
            });
            if !inst.live {
                continue;
            }
            let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
            for t in &geometries[inst.geometry as usize] {
                if t.iter().all(|v| v.is_finite()) {
                    for v in t {
                        let w = inst.transform.transform_point3(*v);
                        lo = lo.min(w);
                        hi = hi.max(w);
                    }
                }
            }
            if lo.x <= hi.x {
                // World boxes from transformed vertices may be an ulp short of where the
                // object-space test finds the surface: widen a little.
                let eps = 1e-5 * (1.0 + lo.abs().max(hi.abs()).max_element());
                items.push((i as u32, lo - eps, hi + eps));
            }
        }
        let tlas = with_ref_table(pack_tlas(items), instances.len());
        let hardware_pass = backend == crate::device::TraversalBackend::HardwareRayQuery;
        let triangles = upload_triangles(bytemuck::cast_slice(&soup), hardware_pass);
        let hardware = hardware_pass.then(|| driver_scene(&geo_records, &inst_records, &triangles));
        TestScene {
            geometries,
            instances,
            world_to_object,
            tlas_nodes: upload(bytemuck::cast_slice(&tlas)),
            tlas,
            instance_buf: upload(bytemuck::cast_slice(&inst_records)),
            geometry_buf: upload(bytemuck::cast_slice(&geo_records)),
            blas_nodes: upload(bytemuck::cast_slice(&blas)),
            triangles,
            hardware,
        }
    }

    /// One identity instance of one geometry.
    /// Rewrites every ref of the TLAS's ref table as one made for another build of its BLAS
    /// (stamp 7, the geometries' stamps being 0) whose entry is the leaf of triangle slot 0 only:
    /// a traversal that trusted the entry would miss the rest of each instance.
    pub fn make_refs_stale(&mut self) {
        let c = self.tlas.len() / 5;
        for e in &mut self.tlas[4 * c..] {
            e[1] = 0x8000_0000;
            e[2] = 7;
        }
        self.tlas_nodes = upload(bytemuck::cast_slice(&self.tlas));
    }

    pub fn single(tris: Vec<Tri>) -> Self {
        TestScene::new(vec![tris], vec![TestInstance::new(0, Affine3A::IDENTITY)])
    }

    /// [`TestScene::single`] on the software traversal (see [`TestScene::software`]).
    pub fn single_software(tris: Vec<Tri>) -> Self {
        TestScene::software(vec![tris], vec![TestInstance::new(0, Affine3A::IDENTITY)])
    }

    /// The scene bindings.
    pub fn buffers(&self) -> SceneBuffers<'_> {
        SceneBuffers {
            tlas_nodes: &self.tlas_nodes,
            instances: &self.instance_buf,
            geometries: &self.geometry_buf,
            blas_nodes: &self.blas_nodes,
            triangles: &self.triangles,
            tlas: self.hardware.as_ref().map(|h| h.tlas()),
            // Every test scene is opaque.
            cutouts: false,
        }
    }

    /// `ray` in instance `i`'s object space, transformed by the same f32 rows the GPU reads.
    pub fn object_ray(&self, i: usize, ray: &Ray) -> Ray {
        let m = &self.world_to_object[i];
        Ray {
            origin: Vec3::new(
                dot_row(&m[0], ray.origin, 1.0),
                dot_row(&m[1], ray.origin, 1.0),
                dot_row(&m[2], ray.origin, 1.0),
            ),
            dir: Vec3::new(
                dot_row(&m[0], ray.dir, 0.0),
                dot_row(&m[1], ray.dir, 0.0),
                dot_row(&m[2], ray.dir, 0.0),
            ),
            ..*ray
        }
    }

    /// Whether instance `i` is traced with `mask`.
    pub fn visible(&self, i: usize, mask: u32) -> bool {
        let inst = &self.instances[i];
        inst.live && inst.mask & mask != 0
    }

    /// Where `ray` meets primitive `prim` of instance `i` (CPU).
    pub fn hit_triangle(&self, i: usize, prim: u32, ray: &Ray) -> Option<TriangleHit> {
        let o = self.object_ray(i, ray);
        let [a, b, c] = *self
            .geometries
            .get(self.instances[i].geometry as usize)?
            .get(prim as usize)?;
        intersect_triangle(&o, a, b, c)
    }

    /// The CPU oracle: closest hit among visible instances, ties to the lowest instance, then
    /// the lowest primitive.
    pub fn closest_hit(&self, ray: &Ray, mask: u32) -> Option<OracleHit> {
        let mut best: Option<OracleHit> = None;
        for (i, inst) in self.instances.iter().enumerate() {
            if !self.visible(i, mask) {
                continue;
            }
            let o = self.object_ray(i, ray);
            for (p, [a, b, c]) in self.geometries[inst.geometry as usize].iter().enumerate() {
                if let Some(h) = intersect_triangle(&o, *a, *b, *c) {
                    // Instances and primitives are visited in increasing order: strict `<`
                    // keeps the lowest index among equal t.
                    if best.is_none_or(|b| h.t < b.t) {
                        best = Some(OracleHit {
                            t: h.t,
                            u: h.u,
                            v: h.v,
                            instance: i as u32,
                            primitive: p as u32,
                        });
                    }
                }
            }
        }
        best
    }
}

/// Small seeded PRNG (xorshift64) for reproducible random tests.
pub(crate) struct Rng(pub u64);

impl Rng {
    /// Uniform in [0, 1).
    pub fn f(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    /// Uniform in [-1, 1)³.
    pub fn v(&mut self) -> Vec3 {
        Vec3::new(self.f(), self.f(), self.f()) * 2.0 - 1.0
    }
    /// Uniform integer in 0..n.
    pub fn below(&mut self, n: u32) -> u32 {
        ((self.f() * n as f32) as u32).min(n - 1)
    }
}

/// A closed cube [-1, 1]³ of `n`×`n` quads per face (2 triangles each), consistently wound.
pub(crate) fn cube(n: u32) -> Vec<Tri> {
    let mut tris = Vec::new();
    let step = 2.0 / n as f32;
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            for i in 0..n {
                for j in 0..n {
                    let p = |a: u32, b: u32| {
                        let mut v = [0.0; 3];
                        v[axis] = sign;
                        v[(axis + 1) % 3] = -1.0 + a as f32 * step;
                        v[(axis + 2) % 3] = -1.0 + b as f32 * step;
                        Vec3::from(v)
                    };
                    let (q0, q1, q2, q3) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
                    if sign > 0.0 {
                        tris.push([q0, q1, q2]);
                        tris.push([q0, q2, q3]);
                    } else {
                        tris.push([q0, q2, q1]);
                        tris.push([q0, q3, q2]);
                    }
                }
            }
        }
    }
    tris
}

/// Traces `rays` on the GPU with the ray batch pass; returns the hit records.
pub(crate) fn gpu_trace(
    scene: &TestScene,
    rays: &[super::rays::GpuRay],
    query: super::rays::RayQuery,
    mask: u32,
) -> Vec<super::rays::GpuHit> {
    use super::rays::RayTracer;
    use crate::device::TraversalBackend;
    use std::sync::OnceLock;
    static SOFTWARE: OnceLock<RayTracer> = OnceLock::new();
    static HARDWARE: OnceLock<RayTracer> = OnceLock::new();
    // The scene's own backend: software-only scenes trace in software on the hardware pass too.
    let backend = scene.buffers().backend();
    let tracer = match backend {
        TraversalBackend::Software => &SOFTWARE,
        TraversalBackend::HardwareRayQuery => &HARDWARE,
    }
    .get_or_init(|| RayTracer::new(&testing::gpu().device, backend));
    let ray_buf = upload(bytemuck::cast_slice(rays));
    let size = (rays.len().max(1) * 32) as u64;
    let hit_buf = testing::buffer(size);
    testing::run(|rec| {
        tracer.record(
            rec,
            &scene.buffers(),
            (&ray_buf, 0),
            (&hit_buf, 0),
            rays.len() as u32,
            query,
            mask,
        )
    });
    let bytes = testing::read_back(&hit_buf, 0, size);
    let mut hits: Vec<super::rays::GpuHit> = bytemuck::pod_collect_to_vec(&bytes);
    hits.truncate(rays.len());
    hits
}

/// The GPU record of a CPU ray.
pub(crate) fn gpu_ray(r: &Ray) -> super::rays::GpuRay {
    super::rays::GpuRay {
        origin: r.origin.to_array(),
        t_min: r.t_min,
        dir: r.dir.to_array(),
        t_max: r.t_max,
    }
}
