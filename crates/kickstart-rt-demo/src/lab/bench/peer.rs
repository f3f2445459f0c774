//! `ksrt bench --peer vulkan-rt`: the GPU driver's own hardware-API ray tracing
//! (`kickstart-rt-peer-vulkan`) on the same meshes and the very same rays as our batches, on the
//! same GPU, with ours, theirs and the ratio of each figure and the rays on which the two
//! tracers disagree.
//!
//! Ratios are **our speed over theirs**: above 1 we are faster (for times: their time / ours;
//! for rays/s: ours / theirs).

use std::time::Duration;

use kickstart_rt_peer_vulkan as vkrt;

use super::harness::Bench;
use super::rays::RayBatches;
pub use super::report::{
    AgreementReport, PeerReport, RateComparison, RayComparison, SceneReport, TimeComparison,
};
use super::{attempt, Stats};
use kickstart_rt_renderer::scene::Scene;
use kickstart_rt_renderer::sdk_glue::{GpuHit, Query};
use kickstart_rt_renderer::upload::UploadedMesh;

/// The peers `ksrt bench --peer` knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PeerKind {
    /// The Vulkan driver's ray tracing (acceleration structures + ray-tracing pipelines).
    VulkanRt,
}

/// The peer of a bench run: opened once, used for every scene.
pub enum PeerState {
    /// Ready to measure.
    Ready(Box<vkrt::VulkanRtPeer>),
    /// Unavailable here, and why (printed with each scene and kept in the report).
    Skipped(String),
}

/// Opens `kind` on the GPU of the bench's wgpu adapter (`info`).
pub fn open(kind: PeerKind, info: &wgpu::AdapterInfo) -> PeerState {
    match kind {
        PeerKind::VulkanRt => {
            let hint = vkrt::DeviceHint {
                vendor_id: info.vendor,
                device_id: info.device,
                name: info.name.clone(),
            };
            match vkrt::VulkanRtPeer::new(Some(&hint)) {
                Ok(p) => {
                    println!("peer vulkan-rt: {} ({})", p.device_name(), p.driver());
                    PeerState::Ready(Box::new(p))
                }
                Err(e) => {
                    println!("peer vulkan-rt skipped: {e}");
                    PeerState::Skipped(e.to_string())
                }
            }
        }
    }
}

impl TimeComparison {
    fn new(ours_ms: Option<f64>, theirs: vkrt::Samples) -> TimeComparison {
        let theirs = Stats::new(theirs.0);
        TimeComparison {
            ours_ms,
            ratio: ours_ms.map(|o| theirs.median_ms / o),
            theirs,
        }
    }
}

impl From<vkrt::Agreement> for AgreementReport {
    fn from(a: vkrt::Agreement) -> Self {
        AgreementReport {
            disagreements: a.disagreements,
            disagreement_percent: a.disagreement_fraction() * 100.0,
            hit_miss: a.hit_miss,
            different_triangle: a.different_triangle,
            ties: a.ties,
            distance_mismatches: a.distance_mismatches,
        }
    }
}

impl PeerReport {
    fn empty() -> PeerReport {
        PeerReport {
            peer: "vulkan-rt",
            device: None,
            driver: None,
            skipped: None,
            blas_build_fast_trace: None,
            blas_build_fast_build: None,
            blas_bytes_fast_trace: None,
            blas_compacted_bytes_fast_trace: None,
            ours_blas_bytes: None,
            blas_triangles: 0,
            tlas_build: None,
            rays: Vec::new(),
            workload: None,
            errors: Vec::new(),
        }
    }
}

/// The comparison rule of a query: closest hits must be the same triangle, any-hit queries only
/// agree on hit or miss.
pub(super) fn query_kind(query: Query) -> vkrt::QueryKind {
    match query {
        Query::Closest => vkrt::QueryKind::Closest,
        Query::Any => vkrt::QueryKind::Any,
    }
}

/// Our hit record as the peer's (the hit flag from [`GpuHit::is_hit`]).
pub(super) fn peer_hit(h: &GpuHit) -> vkrt::Hit {
    vkrt::Hit {
        t: h.t,
        u: h.u,
        v: h.v,
        instance: h.instance,
        primitive: h.primitive,
        hit: u32::from(h.is_hit()),
        _pad: [0; 2],
    }
}

/// Measures the peer on `scene` with the rays of `batches` (our hits in them) and compares
/// with our figures in `ours`. Never fails: what failed is listed in the report's `errors`.
pub fn compare(
    bench: &Bench,
    state: &mut PeerState,
    scene: &Scene,
    uploads: &[UploadedMesh],
    batches: Option<&RayBatches>,
    ours: &SceneReport,
) -> PeerReport {
    let mut report = PeerReport::empty();
    let peer = match state {
        PeerState::Ready(p) => p,
        PeerState::Skipped(why) => {
            report.skipped = Some(why.clone());
            return report;
        }
    };
    // The peer builds opaque BLASes only: on cutouts it would disagree on every ray through a
    // hole, and time another workload than ours.
    if scene.has_cutouts() {
        report.skipped = Some("the peer has no cutouts (alpha-tested meshes) to trace".into());
        return report;
    }
    report.device = Some(peer.device_name().to_string());
    report.driver = Some(peer.driver().to_string());
    let timing = vkrt::Timing {
        iterations: bench.iterations,
        warm_up: Duration::from_millis(500),
    };
    let mut errors = Vec::new();
    let meshes = peer_meshes(scene);
    let ours_blas = ours.blas_build.as_ref().map(|s| s.median_ms);
    let uploaded = attempt(&mut errors, "peer mesh upload", || {
        Ok(peer.upload_meshes(&meshes)?)
    });
    // Fast-build first, then fast-trace: the BLASes the rays are traced against.
    report.blas_build_fast_build = uploaded.and_then(|()| {
        attempt(&mut errors, "peer BLAS build (fast build)", || {
            let t = peer.build_blases(vkrt::BuildPreference::FastBuild, timing)?;
            Ok(TimeComparison::new(ours_blas, t))
        })
    });
    report.blas_build_fast_trace = uploaded.and_then(|()| {
        attempt(&mut errors, "peer BLAS build (fast trace)", || {
            let t = peer.build_blases(vkrt::BuildPreference::FastTrace, timing)?;
            Ok(TimeComparison::new(ours_blas, t))
        })
    });
    if report.blas_build_fast_trace.is_some() {
        report.blas_bytes_fast_trace = Some(peer.blas_bytes());
        report.blas_compacted_bytes_fast_trace = peer.blas_compacted_bytes();
        report.blas_triangles = ours.geometry_triangles;
        report.ours_blas_bytes = ours.blas_memory.as_ref().map(|m| m.total());
    }
    let instances = peer_instances(scene, batches);
    if report.blas_build_fast_trace.is_some() {
        let ours_tlas = attempt(&mut errors, "our TLAS build", || {
            bench.tlas_rebuild(scene, uploads)
        })
        .map(|s| s.median_ms);
        report.tlas_build = attempt(&mut errors, "peer TLAS build", || {
            let t = peer.build_tlas(&instances, timing)?;
            Ok(TimeComparison::new(ours_tlas, t))
        });
    }
    if let (Some(b), Some(_)) = (batches, &report.tlas_build) {
        for (kind, query, rays, our_hits) in &b.batches {
            let r = attempt(&mut errors, &format!("peer {kind} rays"), || {
                let q = match query {
                    Query::Closest => vkrt::Query::Closest,
                    Query::Any => vkrt::Query::Any,
                };
                let (t, theirs) = peer.trace(bytemuck::cast_slice(rays), q, b.width, timing)?;
                let mine: Vec<vkrt::Hit> = our_hits.iter().map(peer_hit).collect();
                let agreement = vkrt::compare_hits(&mine, &theirs, query_kind(*query));
                let time = Stats::new(t.0);
                let theirs_mrays = rays.len() as f64 / (time.median_ms * 1e3);
                let ours_mrays = ours
                    .rays
                    .iter()
                    .find(|o| o.kind == *kind)
                    .map(|o| o.mrays_per_s);
                Ok(RayComparison {
                    kind,
                    rays: rays.len() as u64,
                    ours_mrays_per_s: ours_mrays,
                    theirs_mrays_per_s: theirs_mrays,
                    ratio: ours_mrays.map(|o| o / theirs_mrays),
                    theirs_time: time,
                    theirs_misses: theirs.iter().filter(|h| !h.is_hit()).count() as u64,
                    agreement: agreement.into(),
                })
            });
            report.rays.extend(r);
        }
        // The workload of the issue: every pixel's primary ray plus one diffuse ray per primary
        // hit, over the two batches' times.
        let find = |k: &str| report.rays.iter().find(|r| r.kind == k);
        let primary = b.batches.iter().find(|x| x.0 == "primary");
        if let (Some(p), Some(d), Some(rays)) = (find("primary"), find("diffuse"), primary) {
            let pixels = rays.2.len() as f64;
            let hits = rays.3.iter().filter(|h| h.is_hit()).count() as f64;
            let theirs =
                (pixels + hits) / ((p.theirs_time.median_ms + d.theirs_time.median_ms) * 1e3);
            report.workload = Some(RateComparison {
                ours: ours.peer_mrays_per_s,
                theirs,
                ratio: ours.peer_mrays_per_s.map(|o| o / theirs),
            });
        }
    }
    report.errors = errors;
    report
}

/// The peer's view of `scene`'s meshes.
fn peer_meshes(scene: &Scene) -> Vec<vkrt::Mesh<'_>> {
    scene
        .meshes
        .iter()
        .map(|m| vkrt::Mesh {
            positions: &m.positions,
            indices: &m.indices,
        })
        .collect()
}

/// The peer's instances of `scene`, each with our instance's slot index (what the hits report)
/// where `batches` has them, else its place in the scene.
fn peer_instances(scene: &Scene, batches: Option<&RayBatches>) -> Vec<vkrt::Instance> {
    let slots: Vec<u32> = match batches {
        Some(b) => b.slots.clone(),
        None => (0..scene.instances.len() as u32).collect(),
    };
    scene
        .instances
        .iter()
        .zip(&slots)
        .map(|(i, &index)| vkrt::Instance {
            mesh: i.mesh,
            transform: vkrt::Instance::row_major(i.transform),
            mask: 0xff,
            index,
        })
        .collect()
}

/// `12.3 MiB` (`KiB` below one MiB: the small test scenes' BLASes are a few KiB).
fn size(bytes: u64) -> String {
    const MIB: f64 = 1048576.0;
    let b = bytes as f64;
    if b >= MIB {
        format!("{:.1} MiB", b / MIB)
    } else {
        format!("{:.1} KiB", b / 1024.0)
    }
}

/// Our fast-trace BLASes' bytes once compacted, and the driver's storage for them, uncompacted
/// and compacted, each with its bytes per triangle of the BLASes (left out when the count is 0, i.e. unknown); `None` when the
/// fast-trace build did not run.
fn blas_size_line(r: &PeerReport) -> Option<String> {
    let triangles = r.blas_triangles;
    let with_per_tri = |bytes: u64| {
        if triangles == 0 {
            size(bytes)
        } else {
            format!(
                "{} ({:.1} B/tri)",
                size(bytes),
                bytes as f64 / triangles as f64
            )
        }
    };
    let bytes = r.blas_bytes_fast_trace?;
    let compacted = r
        .blas_compacted_bytes_fast_trace
        .map_or("—".to_string(), with_per_tri);
    let ours = r.ours_blas_bytes.map_or("—".to_string(), with_per_tri);
    Some(format!(
        "BLAS memory (fast trace): ours {ours} compacted; driver {}, compacted {compacted}",
        with_per_tri(bytes)
    ))
}

/// Prints one scene's peer figures.
pub fn print(r: &PeerReport) {
    if let Some(why) = &r.skipped {
        println!("  peer {}: skipped: {why}", r.peer);
        return;
    }
    println!(
        "  peer {} on {} ({}), ratio = our speed / theirs:",
        r.peer,
        r.device.as_deref().unwrap_or("?"),
        r.driver.as_deref().unwrap_or("?")
    );
    let ms = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.3} ms"));
    let ratio = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.2}x"));
    for (what, t) in [
        ("BLAS build (their fast-trace)", &r.blas_build_fast_trace),
        ("BLAS build (their fast-build)", &r.blas_build_fast_build),
        ("TLAS build", &r.tlas_build),
    ] {
        match t {
            Some(t) => println!(
                "    {what:<30} ours {:>10}  theirs {:>10}  ratio {}",
                ms(t.ours_ms),
                ms(Some(t.theirs.median_ms)),
                ratio(t.ratio)
            ),
            None => println!("    {what:<30} —"),
        }
    }
    if let Some(line) = blas_size_line(r) {
        println!("    {line}");
    }
    let rate = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.1}"));
    for k in &r.rays {
        let a = &k.agreement;
        println!(
            "    {:<8} {:>9} rays  ours {:>8} Mrays/s  theirs {:>8} Mrays/s  ratio {}  \
             disagree {} ({:.4} %: {} hit/miss, {} other triangle; {} ties, {} distance mismatches)",
            k.kind,
            k.rays,
            rate(k.ours_mrays_per_s),
            rate(Some(k.theirs_mrays_per_s)),
            ratio(k.ratio),
            a.disagreements,
            a.disagreement_percent,
            a.hit_miss,
            a.different_triangle,
            a.ties,
            a.distance_mismatches
        );
    }
    if let Some(w) = &r.workload {
        println!(
            "    peer workload            ours {:>8} Mrays/s  theirs {:>8} Mrays/s  ratio {}",
            rate(w.ours),
            rate(Some(w.theirs)),
            ratio(w.ratio)
        );
    }
    for e in &r.errors {
        println!("    peer failed: {e}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lab::bench::rays::{primary_rays, rays, secondary_rays, Surface};
    use glam::Vec3;
    use kickstart_rt_renderer::rng::Rng;
    use kickstart_rt_renderer::scene;

    #[test]
    fn primary_rays_are_one_unit_ray_per_pixel_from_the_eye() {
        let cam = scene::parse_camera("0,1,5,0,1,0,60").expect("camera");
        let (dirs, rays) = primary_rays(&cam, (16, 9));
        assert_eq!((dirs.len(), rays.len()), (144, 144));
        for (d, r) in dirs.iter().zip(&rays) {
            assert!((d.length() - 1.0).abs() < 1e-5);
            assert_eq!(r.origin, cam.eye.to_array());
            assert_eq!(r.dir, d.to_array());
            assert_eq!((r.t_min, r.t_max), (0.0, f32::INFINITY));
        }
        // Row-major from the top left: the first ray looks left and up, the last right and down.
        let fwd = (cam.at - cam.eye).normalize();
        assert!(dirs[0].y > 0.0 && dirs[143].y < 0.0 && dirs[0].x < 0.0 && dirs[143].x > 0.0);
        assert!(dirs[0].dot(fwd) > 0.0);
        // Deterministic.
        assert_eq!(primary_rays(&cam, (16, 9)).1, rays);
    }

    #[test]
    fn secondary_rays_leave_the_surface_into_its_hemisphere() {
        let surfaces: Vec<Surface> = (0..500)
            .map(|i| {
                let n =
                    Vec3::new((i as f32 * 0.37).sin(), 1.0, (i as f32 * 0.11).cos()).normalize();
                Surface {
                    point: Vec3::new(i as f32, 0.0, 0.0),
                    normal: n,
                }
            })
            .collect();
        let offset = 1e-3;
        let a = secondary_rays(&surfaces, offset, &mut Rng(42), 1.0);
        assert_eq!(a.len(), surfaces.len());
        for (r, s) in a.iter().zip(&surfaces) {
            let o = Vec3::from(r.origin);
            assert!((o - (s.point + s.normal * offset)).length() < 1e-6);
            let d = Vec3::from(r.dir);
            assert!((d.length() - 1.0).abs() < 1e-4);
            assert!(d.dot(s.normal) >= 0.0);
            assert_eq!((r.t_min, r.t_max), (0.0, 1.0));
        }
        assert_eq!(secondary_rays(&surfaces, offset, &mut Rng(42), 1.0), a);
        assert_ne!(secondary_rays(&surfaces, offset, &mut Rng(43), 1.0), a);
    }

    #[test]
    fn our_hits_convert_with_their_hit_flag() {
        let miss = GpuHit {
            t: -1.0,
            u: 0.0,
            v: 0.0,
            instance: GpuHit::MISS,
            primitive: u32::MAX,
            _pad: [0; 3],
        };
        assert!(!peer_hit(&miss).is_hit());
        let hit = GpuHit {
            t: 2.0,
            instance: 3,
            primitive: 4,
            ..miss
        };
        assert_eq!(
            peer_hit(&hit),
            vkrt::Hit {
                u: 0.0,
                ..vkrt::Hit::at(2.0, 3, 4)
            }
        );
    }

    #[test]
    fn blas_sizes_print_with_bytes_per_triangle() {
        let mut r = PeerReport::empty();
        r.blas_triangles = 1024;
        assert_eq!(blas_size_line(&r), None, "no fast-trace build, no line");
        r.blas_bytes_fast_trace = Some(3 * 1048576);
        r.blas_compacted_bytes_fast_trace = Some(1536);
        r.ours_blas_bytes = Some(2048);
        assert_eq!(
            blas_size_line(&r).as_deref(),
            Some("BLAS memory (fast trace): ours 2.0 KiB (2.0 B/tri) compacted; driver 3.0 MiB (3072.0 B/tri), compacted 1.5 KiB (1.5 B/tri)")
        );
        r.blas_triangles = 0;
        assert_eq!(
            blas_size_line(&r).as_deref(),
            Some("BLAS memory (fast trace): ours 2.0 KiB compacted; driver 3.0 MiB, compacted 1.5 KiB")
        );
        r.blas_compacted_bytes_fast_trace = None;
        r.ours_blas_bytes = None;
        assert_eq!(
            blas_size_line(&r).as_deref(),
            Some("BLAS memory (fast trace): ours — compacted; driver 3.0 MiB, compacted —")
        );
    }

    #[test]
    fn skipped_peer_reports_why_and_measures_nothing() {
        let (device, queue) = crate::app::testing::device();
        let bench = Bench::new(device, queue, 1);
        let scene = scene::builtin::cornell_box();
        let camera = scene.camera_or_default(None);
        let r = SceneReport::new("cornell", &scene, &camera);
        let mut state = PeerState::Skipped("no ray tracing here".to_string());
        let p = compare(&bench, &mut state, &scene, &[], None, &r);
        assert_eq!(p.skipped.as_deref(), Some("no ray tracing here"));
        assert!(p.rays.is_empty() && p.blas_build_fast_trace.is_none() && p.errors.is_empty());
    }

    /// The peer against our tracer on the Cornell box, every ray kind of the bench: at most
    /// 0.01 % disagreement. It needs a ray-tracing Vulkan device, which CI's software Vulkan
    /// lacks, so it is ignored (never counted as a pass there) and run with `--ignored` where one
    /// exists; run so, a missing device fails it.
    #[test]
    #[ignore = "needs a ray-tracing Vulkan device: .ci/run runs it on Mesa 25 lavapipe (--include-ignored)"]
    fn peer_agrees_with_our_tracer_on_the_cornell_box() {
        let peer = vkrt::VulkanRtPeer::new(None)
            .unwrap_or_else(|e| panic!("this test needs a ray-tracing Vulkan device: {e}"));
        let (device, queue) = crate::app::testing::device();
        let bench = Bench::new(device, queue, 1);
        let scene = scene::builtin::cornell_box();
        let camera = scene.camera_or_default(None);
        let uploads = kickstart_rt_renderer::upload::upload_scene(device, queue, &scene);
        let mut ours = SceneReport::new("cornell", &scene, &camera);
        let batches =
            rays(&bench, &scene, &uploads, &camera, (96, 64), &mut ours).expect("our rays");
        let mut state = PeerState::Ready(Box::new(peer));
        let r = compare(&bench, &mut state, &scene, &uploads, Some(&batches), &ours);
        print(&r);
        assert!(r.errors.is_empty(), "{:?}", r.errors);
        assert!(r.blas_build_fast_build.is_some() && r.tlas_build.is_some());
        // The driver's compacted size of the fast-trace BLASes: some bytes, never more than the
        // uncompacted ones.
        let bytes = r.blas_bytes_fast_trace.expect("fast-trace BLAS bytes");
        let compacted = r.blas_compacted_bytes_fast_trace;
        assert!(
            compacted.is_some_and(|c| c > 0 && c <= bytes),
            "compacted {compacted:?} of {bytes} bytes"
        );
        let kinds: Vec<&str> = r.rays.iter().map(|k| k.kind).collect();
        assert_eq!(kinds, ["primary", "ao", "diffuse"]);
        for k in &r.rays {
            assert!(k.rays > 1000, "{} rays: {}", k.kind, k.rays);
            assert!(
                k.agreement.disagreements as f64 <= 1e-4 * k.rays as f64,
                "{}: {:?}",
                k.kind,
                k.agreement
            );
        }
        assert!(r.workload.is_some());
    }
}
