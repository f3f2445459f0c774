//! Ray tracing test helpers: meshes, registration, ray batches through `TraceRaysTask`, and the
//! CPU oracle (`kickstart_rt::cpu`) over the same instances, with the documented tie rule.

use super::*;
use glam::{Affine3A, Vec3};
use kickstart_rt::cpu::{intersect_triangle, CpuBvh, Ray};
use kickstart_rt::*;
use std::collections::HashMap;

/// A small deterministic PRNG (splitmix64) so failures reproduce from the seed.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn f(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }
    pub fn v(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
    pub fn unit(&mut self) -> Vec3 {
        loop {
            let v = self.v(-1.0, 1.0);
            let l = v.length();
            if l > 0.05 && l <= 1.0 {
                return v / l;
            }
        }
    }
    pub fn below(&mut self, n: u32) -> u32 {
        (self.next_u64() % n.max(1) as u64) as u32
    }
}

/// An indexed triangle mesh.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub indices: Vec<u32>,
}

impl Mesh {
    pub fn triangles(&self) -> Vec<[Vec3; 3]> {
        self.indices
            .chunks(3)
            .map(|t| {
                [
                    self.positions[t[0] as usize],
                    self.positions[t[1] as usize],
                    self.positions[t[2] as usize],
                ]
            })
            .collect()
    }

    /// Random triangles in a cube of side `size`, with exact duplicates and degenerate
    /// (collinear and zero-area) triangles mixed in.
    pub fn soup(rng: &mut Rng, triangles: u32, size: f32) -> Mesh {
        let mut m = Mesh::default();
        for t in 0..triangles {
            let i = m.positions.len() as u32;
            match t % 17 {
                // An exact duplicate of an earlier triangle.
                5 if t > 3 => {
                    let k = rng.below(t) as usize * 3;
                    let dup = [m.indices[k], m.indices[k + 1], m.indices[k + 2]];
                    m.indices.extend_from_slice(&dup);
                    continue;
                }
                // Collinear.
                9 => {
                    let a = rng.v(0.0, size);
                    let d = rng.v(-0.05, 0.05) * size;
                    m.positions.extend([a, a + d, a + 2.0 * d]);
                }
                // Zero area: a point.
                13 => {
                    let a = rng.v(0.0, size);
                    m.positions.extend([a, a, a]);
                }
                _ => {
                    let a = rng.v(0.0, size);
                    m.positions.extend([
                        a,
                        a + rng.v(-0.08, 0.08) * size,
                        a + rng.v(-0.08, 0.08) * size,
                    ]);
                }
            }
            m.indices.extend([i, i + 1, i + 2]);
        }
        m
    }

    /// A closed icosphere of radius 1 (shared vertices: watertight).
    pub fn icosphere(subdivisions: u32) -> Mesh {
        let t = (1.0 + 5f32.sqrt()) / 2.0;
        let mut p: Vec<Vec3> = [
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ]
        .iter()
        .map(|v| Vec3::from(*v).normalize())
        .collect();
        let mut f: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            let mut mid = HashMap::new();
            let mut next = Vec::new();
            for tri in &f {
                let mut m = [0u32; 3];
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    let key = (a.min(b), a.max(b));
                    m[k] = *mid.entry(key).or_insert_with(|| {
                        p.push(((p[a as usize] + p[b as usize]) * 0.5).normalize());
                        p.len() as u32 - 1
                    });
                }
                next.push([tri[0], m[0], m[2]]);
                next.push([tri[1], m[1], m[0]]);
                next.push([tri[2], m[2], m[1]]);
                next.push([m[0], m[1], m[2]]);
            }
            f = next;
        }
        Mesh {
            positions: p,
            indices: f.into_iter().flatten().collect(),
        }
    }

    /// An axis-aligned closed box from `lo` to `hi` (12 triangles, shared corners).
    pub fn cuboid(lo: Vec3, hi: Vec3) -> Mesh {
        let c = |i: u32| {
            Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        };
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let mut indices = Vec::new();
        for q in quads {
            indices.extend([q[0], q[1], q[2], q[0], q[2], q[3]]);
        }
        Mesh {
            positions: (0..8).map(c).collect(),
            indices,
        }
    }
}

/// The mesh's geometry input (Float32x3, u32 indices; buffers with COPY_SRC).
pub fn mesh_input(name: &str, m: &Mesh, allow_update: bool) -> GeometryInput {
    let p: Vec<[f32; 3]> = m.positions.iter().map(|v| v.to_array()).collect();
    let vb = buffer(bytemuck::cast_slice(&p), wgpu::BufferUsages::COPY_SRC);
    let ib = buffer(
        bytemuck::cast_slice(&m.indices),
        wgpu::BufferUsages::COPY_SRC,
    );
    GeometryInput {
        name: name.into(),
        components: vec![GeometryComponent {
            vertex_buffer: VertexBufferInput {
                buffer: vb,
                offset: 0,
                stride: 12,
                count: m.positions.len() as u32,
                format: VertexFormat::Float32x3,
            },
            index_buffer: Some(IndexBufferInput {
                buffer: ib,
                offset: 0,
                count: m.indices.len() as u32,
                format: IndexFormat::Uint32,
            }),
            transform: None,
            index_range: None,
            opacity: None,
        }],
        allow_update,
        ..Default::default()
    }
}

pub fn schedule_mesh(c: &mut TaskContainer, h: GeometryHandle, name: &str, m: &Mesh) {
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: h,
        input: mesh_input(name, m, false),
    });
}

/// Builds every queued BLAS and the TLAS.
pub fn build_all(ctx: &ExecuteContext) {
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 1000,
        ..Default::default()
    });
    build_submit_complete(ctx, c);
}

/// Traces `rays` through the SDK and reads the hits back.
pub fn trace(
    ctx: &ExecuteContext,
    rays: &[GpuRay],
    query: RayQuery,
    mask: InstanceInclusionMask,
) -> Vec<GpuHit> {
    if rays.is_empty() {
        return Vec::new();
    }
    let mut c = ctx.create_task_container();
    let hb = schedule_trace(&mut c, rays, query, mask);
    build_submit_complete(ctx, c);
    bytemuck::pod_collect_to_vec(&read_buffer(&hb))
}

/// Schedules a trace of `rays` into `c`; returns the hit buffer (32 bytes a ray) to read once the
/// container's task has completed.
pub fn schedule_trace(
    c: &mut TaskContainer,
    rays: &[GpuRay],
    query: RayQuery,
    mask: InstanceInclusionMask,
) -> wgpu::Buffer {
    let rb = buffer(bytemuck::cast_slice(rays), wgpu::BufferUsages::STORAGE);
    let hb = gpu().device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("hits"),
        size: rays.len() as u64 * 32,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    c.schedule_render_task(RenderTask::TraceRays(TraceRaysTask {
        query,
        instance_mask: mask,
        ..TraceRaysTask::new(rb, rays.len() as u32, hb.clone())
    }));
    hb
}

pub fn closest(ctx: &ExecuteContext, rays: &[GpuRay]) -> Vec<GpuHit> {
    trace(
        ctx,
        rays,
        RayQuery::ClosestHit,
        InstanceInclusionMask::VISIBLE_IN_RT,
    )
}

pub fn ray(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> GpuRay {
    GpuRay {
        origin: origin.to_array(),
        t_min,
        dir: dir.to_array(),
        t_max,
    }
}

struct OracleGeometry {
    tris: Vec<[Vec3; 3]>,
    bvh: CpuBvh,
}

struct OracleInstance {
    index: u32,
    geometry: u32,
    world_to_object: Affine3A,
    mask: u32,
    participating: bool,
}

/// The CPU answer for a scene: per instance, the ray in object space (as the GPU transforms it)
/// against the geometry's CPU BVH.
#[derive(Default)]
pub struct Oracle {
    geometries: HashMap<u32, OracleGeometry>,
    instances: Vec<OracleInstance>,
}

/// The CPU's answer for one ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OracleHit {
    pub t: f32,
    pub instance: u32,
    pub primitive: u32,
}

impl Oracle {
    pub fn geometry(&mut self, h: GeometryHandle, m: &Mesh) {
        let tris = m.triangles();
        let bvh = CpuBvh::build(&tris);
        self.geometries
            .insert(h.index(), OracleGeometry { tris, bvh });
    }

    pub fn instance(&mut self, h: InstanceHandle, input: &InstanceInput) {
        self.instances.retain(|i| i.index != h.index());
        self.instances.push(OracleInstance {
            index: h.index(),
            geometry: input.geometry.index(),
            world_to_object: input.transform.inverse(),
            mask: input.inclusion_mask.0,
            participating: input.participating_in_tlas,
        });
    }

    pub fn remove_instance(&mut self, h: InstanceHandle) {
        self.instances.retain(|i| i.index != h.index());
    }

    fn object_ray(i: &OracleInstance, r: &GpuRay) -> Ray {
        Ray {
            origin: i.world_to_object.transform_point3(Vec3::from(r.origin)),
            dir: i.world_to_object.transform_vector3(Vec3::from(r.dir)),
            t_min: r.t_min,
            t_max: r.t_max,
        }
    }

    fn visible(&self, mask: u32) -> impl Iterator<Item = (&OracleInstance, &OracleGeometry)> {
        self.instances
            .iter()
            .filter(move |i| i.participating && i.mask & mask != 0)
            .filter_map(|i| self.geometries.get(&i.geometry).map(|g| (i, g)))
    }

    /// Closest hit; equal `t` goes to the lowest instance, then primitive.
    pub fn closest(&self, r: &GpuRay, mask: u32) -> Option<OracleHit> {
        let mut best: Option<OracleHit> = None;
        for (i, g) in self.visible(mask) {
            if let Some(h) = g.bvh.closest_hit(&g.tris, &Self::object_ray(i, r)) {
                let cand = OracleHit {
                    t: h.t,
                    instance: i.index,
                    primitive: h.primitive,
                };
                let better = match best {
                    None => true,
                    Some(b) => {
                        (cand.t, cand.instance, cand.primitive) < (b.t, b.instance, b.primitive)
                    }
                };
                if better {
                    best = Some(cand);
                }
            }
        }
        best
    }

    pub fn any(&self, r: &GpuRay, mask: u32) -> bool {
        self.visible(mask)
            .any(|(i, g)| g.bvh.any_hit(&g.tris, &Self::object_ray(i, r)))
    }

    /// Ray `r` in the object space of `instance`, and that instance's triangle `primitive`.
    fn object_triangle(
        &self,
        r: &GpuRay,
        instance: u32,
        primitive: u32,
    ) -> Option<(Ray, [Vec3; 3])> {
        let i = self.instances.iter().find(|i| i.index == instance)?;
        let tri = *self
            .geometries
            .get(&i.geometry)?
            .tris
            .get(primitive as usize)?;
        Some((Self::object_ray(i, r), tri))
    }

    /// The smallest barycentric coordinate where the ray crosses the plane of triangle
    /// (`instance`, `primitive`): ≈ 0 means the ray grazes an edge or vertex, where f32 rounding
    /// legitimately decides either way.
    pub fn edge_distance(&self, r: &GpuRay, instance: u32, primitive: u32) -> f32 {
        let Some((ray, [a, b, c])) = self.object_triangle(r, instance, primitive) else {
            return f32::INFINITY;
        };
        let n = (b - a).cross(c - a);
        let denom = n.dot(ray.dir);
        if denom == 0.0 || n.length_squared() == 0.0 {
            return 0.0;
        }
        let t = n.dot(a - ray.origin) / denom;
        let p = ray.origin + ray.dir * t;
        let area = n.length();
        let w0 = (c - b).cross(p - b).dot(n) / (area * area);
        let w1 = (a - c).cross(p - c).dot(n) / (area * area);
        let w2 = 1.0 - w0 - w1;
        w0.abs().min(w1.abs()).min(w2.abs())
    }

    /// |cos| of the angle between the ray and the normal of (`instance`, `primitive`), in the
    /// instance's space: near 0 the ray grazes the triangle's plane, where its distance is
    /// ill-conditioned (a rounding of the plane moves it by about rounding / cos).
    pub fn incidence_cos(&self, r: &GpuRay, instance: u32, primitive: u32) -> f32 {
        let Some((ray, [a, b, c])) = self.object_triangle(r, instance, primitive) else {
            return 1.0;
        };
        let n = (b - a).cross(c - a).normalize_or_zero();
        n.dot(ray.dir.normalize_or_zero()).abs()
    }

    /// Whether the ray crosses the plane of (`instance`, `primitive`) nearer one of its edges
    /// than `f32` rounding can place that edge. Each vertex is known to a few ulps of its own
    /// coordinates (the triangle test first moves it relative to the ray's origin and shears
    /// it, rounding at that magnitude), so an edge's position where the ray passes is uncertain
    /// by the same interpolation of its two ends' magnitudes. An edge between two vertices far
    /// out (±1e6) crossing the unit cube is uncertain by about 0.1 there: whether the driver's
    /// JIT fuses multiply-adds decides hit or miss for every ray that close. Near a vertex in
    /// the unit cube the band is a few 1e-7, as for any triangle.
    pub fn grazes_within_rounding(&self, r: &GpuRay, instance: u32, primitive: u32) -> bool {
        let Some((ray, [a, b, c])) = self.object_triangle(r, instance, primitive) else {
            return false;
        };
        let n = (b - a).cross(c - a);
        let denom = n.dot(ray.dir);
        if denom == 0.0 || n.length_squared() == 0.0 {
            return true;
        }
        let p = ray.origin + ray.dir * (n.dot(a - ray.origin) / denom);
        let magnitude = |q: Vec3| q.abs().max_element();
        let within = |from: Vec3, to: Vec3| {
            let e = to - from;
            let len2 = e.length_squared().max(f32::MIN_POSITIVE);
            let s = ((p - from).dot(e) / len2).clamp(0.0, 1.0);
            let distance = (p - from).cross(e).length() / len2.sqrt();
            let uncertainty = magnitude(from) * (1.0 - s)
                + magnitude(to) * s
                + magnitude(p)
                + magnitude(ray.origin);
            distance <= 8.0 * f32::EPSILON * uncertainty
        };
        within(a, b) || within(b, c) || within(c, a)
    }

    /// Whether two distances `ts` along the ray to (`instance`, `primitive`) differ by less
    /// than the rounding of the triangle's plane can move the hit: the plane is known to a few
    /// ulps of the largest coordinate involved (in object space), which moves the hit along the
    /// ray by that much divided by the cosine of incidence. A triangle reaching 1e6 out, met at
    /// a grazing angle 1000 units away, puts its hit anywhere within a few units.
    pub fn distance_within_rounding(
        &self,
        r: &GpuRay,
        instance: u32,
        primitive: u32,
        ts: (f32, f32),
    ) -> bool {
        let Some((ray, [a, b, c])) = self.object_triangle(r, instance, primitive) else {
            return false;
        };
        let n = (b - a).cross(c - a).normalize_or_zero();
        let along = n.dot(ray.dir).abs();
        let hit = ray.origin + ray.dir * ts.0;
        let scale = [a, b, c, hit, ray.origin]
            .iter()
            .fold(0.0_f32, |m, p| m.max(p.abs().max_element()));
        along > 0.0 && (ts.0 - ts.1).abs() * along <= 16.0 * f32::EPSILON * scale
    }

    /// Whether the ray starts on the plane of (`instance`, `primitive`) to within `f32` precision
    /// of the triangle's coordinates: its start point (at `t_min`, in object space) is nearer the
    /// plane than a millionth of the largest coordinate involved. Whether such a ray hits the
    /// triangle at `t ≈ t_min` or passes it by depends on the rounding of the plane distance,
    /// which differs between our triangle test, the oracle's and the JIT of a software driver
    /// (it may fuse multiply-adds on one CPU and not on another).
    pub fn starts_on_plane(&self, r: &GpuRay, instance: u32, primitive: u32) -> bool {
        let Some((ray, [a, b, c])) = self.object_triangle(r, instance, primitive) else {
            return false;
        };
        let start = ray.origin + ray.dir * ray.t_min;
        let n = (b - a).cross(c - a).normalize_or_zero();
        let scale = [a, b, c, start]
            .iter()
            .fold(0.0_f32, |m, p| m.max(p.abs().max_element()));
        (start - a).dot(n).abs() <= 1e-6 * scale
    }

    /// Whether the CPU's triangle test hits (`instance`, `primitive`) at about `t`.
    pub fn hits_at(&self, r: &GpuRay, instance: u32, primitive: u32, t: f32) -> bool {
        let Some((ray, [a, b, c])) = self.object_triangle(r, instance, primitive) else {
            return false;
        };
        let ray = Ray {
            t_min: f32::NEG_INFINITY,
            t_max: f32::INFINITY,
            ..ray
        };
        intersect_triangle(&ray, a, b, c).is_some_and(|h| close(h.t, t))
            || self.edge_distance(r, instance, primitive) < 1e-4
    }
}

/// The documented tolerance of `t` between the GPU and the CPU oracle.
pub fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-4 * a.abs().max(b.abs()).max(1.0)
}

/// How GPU hits compare with the oracle.
#[derive(Debug, Default)]
pub struct Agreement {
    pub rays: usize,
    pub hits: usize,
    /// Equal-`t` ties resolved to another triangle sharing the hit point.
    pub ties: usize,
    /// Hit/miss disagreements on a triangle whose edge the ray grazes (|barycentric| < 1e-4):
    /// the ray's only hit, or the nearer of two different hits.
    pub edge_grazes: usize,
    /// Disagreements within the rounding of the triangle's own coordinates: an edge graze (as
    /// above) closer than `f32` can place the edge (see [`Oracle::grazes_within_rounding`]), or
    /// the same triangle hit at distances closer than `f32` can place its plane (see
    /// [`Oracle::distance_within_rounding`]). Not rate-limited: near a triangle reaching far out
    /// they are as common as the rays that pass it.
    pub rounding_grazes: usize,
    /// The first few edge grazes (rate-limited ones), described for a failure message.
    pub graze_examples: Vec<String>,
    /// Hit/miss disagreements on a triangle whose plane the ray starts on (see
    /// [`Oracle::starts_on_plane`]): the nearer of the two hits, or the only one.
    pub plane_starts: usize,
    /// Real disagreements (described).
    pub mismatches: Vec<String>,
}

/// Compares closest hits with the oracle under the documented tie rule.
pub fn compare(oracle: &Oracle, rays: &[GpuRay], hits: &[GpuHit], mask: u32) -> Agreement {
    let mut a = Agreement {
        rays: rays.len(),
        ..Default::default()
    };
    for (k, (r, h)) in rays.iter().zip(hits).enumerate() {
        let cpu = oracle.closest(r, mask);
        match (cpu, h.is_hit()) {
            (None, false) => {}
            (Some(c), true) => {
                a.hits += 1;
                if c.instance == h.instance && c.primitive == h.primitive && close(c.t, h.t) {
                    continue;
                }
                // The same triangle, at distances that differ by less than the rounding of its
                // plane: triangles reaching far out, met at a grazing angle.
                if c.instance == h.instance
                    && c.primitive == h.primitive
                    && oracle.distance_within_rounding(r, c.instance, c.primitive, (c.t, h.t))
                {
                    a.rounding_grazes += 1;
                    continue;
                }
                // The same triangle at a grazing angle, where the distance is ill-conditioned:
                // the driver's triangle test (hardware backend) rounds the plane otherwise than
                // ours does.
                if c.instance == h.instance
                    && c.primitive == h.primitive
                    && super::backend() == TraversalBackend::HardwareRayQuery
                    && oracle.incidence_cos(r, c.instance, c.primitive) < 0.02
                {
                    a.edge_grazes += 1;
                    if a.graze_examples.len() < 5 {
                        a.graze_examples.push(format!(
                            "ray {k} {r:?}: grazing the plane of the same triangle, cpu {c:?}, gpu {h:?}"
                        ));
                    }
                    continue;
                }
                if close(c.t, h.t) && oracle.hits_at(r, h.instance, h.primitive, h.t) {
                    a.ties += 1;
                    continue;
                }
                // The nearer of the two triangles grazed at its edge: one side hit it and the
                // other missed it (the GPU may fuse multiply-adds in the edge functions), the
                // documented hit/miss disagreement, on one triangle instead of the whole ray.
                let (inst, prim) = if h.t < c.t {
                    (h.instance, h.primitive)
                } else {
                    (c.instance, c.primitive)
                };
                if count_graze(&mut a, oracle, r, inst, prim) {
                    continue;
                }
                if oracle.starts_on_plane(r, inst, prim) {
                    a.plane_starts += 1;
                    continue;
                }
                a.mismatches
                    .push(format!("ray {k} {r:?}: cpu {c:?}, gpu {h:?}"));
            }
            (Some(c), false) => {
                if count_graze(&mut a, oracle, r, c.instance, c.primitive) {
                    continue;
                }
                if oracle.starts_on_plane(r, c.instance, c.primitive) {
                    a.plane_starts += 1;
                } else {
                    a.mismatches
                        .push(format!("ray {k} {r:?}: cpu {c:?}, gpu missed"));
                }
            }
            (None, true) => {
                if count_graze(&mut a, oracle, r, h.instance, h.primitive) {
                    continue;
                }
                if oracle.starts_on_plane(r, h.instance, h.primitive) {
                    a.plane_starts += 1;
                } else {
                    a.mismatches
                        .push(format!("ray {k} {r:?}: cpu missed, gpu {h:?}"));
                }
            }
        }
    }
    a
}

/// Counts a hit/miss disagreement on (`instance`, `primitive`) as an edge graze, within the
/// triangle's rounding or not, when the ray passes within 1e-4 (barycentric) of an edge.
fn count_graze(
    a: &mut Agreement,
    oracle: &Oracle,
    r: &GpuRay,
    instance: u32,
    primitive: u32,
) -> bool {
    let barycentric = oracle.edge_distance(r, instance, primitive);
    if barycentric >= 1e-4 {
        return false;
    }
    if oracle.grazes_within_rounding(r, instance, primitive) {
        a.rounding_grazes += 1;
    } else {
        a.edge_grazes += 1;
        if a.graze_examples.len() < 5 {
            a.graze_examples.push(format!(
                "{r:?} by instance {instance} primitive {primitive} (barycentric {barycentric:e})"
            ));
        }
    }
    true
}

/// Asserts agreement: no real mismatch, and edge grazes are rare (≤ 1 in 500 rays).
pub fn assert_agrees(a: &Agreement, what: &str) {
    assert!(
        a.mismatches.is_empty(),
        "{what}: {} of {} rays disagree with the CPU oracle, e.g.\n{}",
        a.mismatches.len(),
        a.rays,
        a.mismatches
            .iter()
            .take(5)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
    assert!(
        a.edge_grazes * 500 <= a.rays,
        "{what}: {} edge-grazing disagreements in {} rays, e.g.\n{}",
        a.edge_grazes,
        a.rays,
        a.graze_examples.join("\n")
    );
    assert!(
        a.plane_starts * 200 <= a.rays,
        "{what}: {} disagreements on rays starting on a triangle's plane in {} rays",
        a.plane_starts,
        a.rays
    );
}

/// Texels a side of the cutout tests' checkerboard.
pub const CHECKER: u32 = 8;

/// An `Rgba8Unorm` checkerboard of `CHECKER`² texels: alpha 255 where `(x + y)` is even, 0
/// elsewhere (colour channels 128 everywhere).
pub fn checkerboard_alpha() -> wgpu::TextureView {
    let g = gpu();
    let size = wgpu::Extent3d {
        width: CHECKER,
        height: CHECKER,
        depth_or_array_layers: 1,
    };
    let texture = g.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("checkerboard alpha"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8Unorm,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    let texels: Vec<u8> = (0..CHECKER * CHECKER)
        .flat_map(|i| {
            let (x, y) = (i % CHECKER, i / CHECKER);
            [128, 128, 128, if (x + y) % 2 == 0 { 255 } else { 0 }]
        })
        .collect();
    g.queue.write_texture(
        texture.as_image_copy(),
        &texels,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(4 * CHECKER),
            rows_per_image: None,
        },
        size,
    );
    texture.create_view(&Default::default())
}

/// The CPU oracle's alpha test of the checkerboard at `uv` (the texel it falls in, repeating).
pub fn checker_opaque(uv: glam::Vec2) -> bool {
    let texel = (uv - uv.floor()) * CHECKER as f32;
    (texel.x as u32 + texel.y as u32).is_multiple_of(2)
}

/// A unit card in the plane z = 0 over x, y in [0, 1] (two triangles), its texture coordinates
/// its x and y.
pub fn card() -> (Mesh, Vec<[f32; 2]>) {
    let corners = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let mesh = Mesh {
        positions: corners.iter().map(|&[x, y]| Vec3::new(x, y, 0.0)).collect(),
        indices: vec![0, 1, 2, 0, 2, 3],
    };
    (mesh, corners.to_vec())
}

/// The checkerboard card, its coordinates in `format` (each format vertex pulling decodes).
pub fn checker_card(card_mesh: &Mesh, uvs: &[[f32; 2]], format: UvFormat) -> GeometryInput {
    let bytes: Vec<u8> = match format {
        UvFormat::Float32x2 => bytemuck::cast_slice(uvs).to_vec(),
        UvFormat::Float16x2 => uvs
            .iter()
            .flatten()
            // The card's coordinates are 0 and 1: f16 0x0000 and 0x3c00.
            .flat_map(|&x| (if x == 1.0 { 0x3c00u16 } else { 0 }).to_le_bytes())
            .collect(),
        UvFormat::Unorm16x2 => uvs
            .iter()
            .flatten()
            .flat_map(|&x| ((x * 65535.0) as u16).to_le_bytes())
            .collect(),
    };
    let mut input = mesh_input("checker card", card_mesh, false);
    input.components[0].opacity = Some(ComponentOpacity {
        micromap_level: 5,
        ..ComponentOpacity::texture(
            checkerboard_alpha(),
            UvBufferInput {
                buffer: buffer(&bytes, wgpu::BufferUsages::COPY_SRC),
                offset: 0,
                stride: format.size(),
                format,
            },
            1.0,
            0.5,
        )
    });
    input
}
