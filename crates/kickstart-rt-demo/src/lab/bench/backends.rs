//! Both traversal backends on the same rays: where the device has ray queries, `ksrt bench`
//! measures the scene with the backend `--backend` chose, then builds the same scene with the
//! other backend, traces the very same ray batches, and compares build time, rays per second and
//! every hit (instance, primitive, distance), ray by ray.

use kickstart_rt as ksrt;
use kickstart_rt_peer_vulkan as vkrt;

use super::harness::Bench;
use super::peer::{peer_hit, query_kind};
use super::rays::RayBatches;
pub use super::report::{BackendComparison, BackendRays, SceneReport};
use super::{attempt, Stats};
use kickstart_rt_renderer::scene::Scene;
use kickstart_rt_renderer::upload::UploadedMesh;

/// The share of a batch's rays on which the backends may disagree (a hit against a miss, or
/// another triangle beyond a tie) before the comparison counts as failed: rays grazing a shared
/// edge or lying in a triangle's plane, which each backend's triangle test may decide otherwise.
const MAX_DISAGREEMENT: f64 = 1e-4;

/// The backend a context made with `choice` on the bench's device takes.
pub(super) fn backend_of(
    bench: &Bench,
    choice: ksrt::BackendChoice,
) -> Option<ksrt::TraversalBackend> {
    match ksrt::ExecuteContext::new(
        bench.device,
        bench.queue,
        ksrt::InitSettings {
            backend: choice,
            ..Default::default()
        },
    ) {
        Ok(ctx) => Some(ctx.traversal_backend().backend),
        Err(_) => None,
    }
}

/// Measures the other backend on `scene` with the rays of `batches` (the measured backend's hits
/// in them), when the device has both; `None` when it has only the software one.
pub(super) fn compare(
    bench: &Bench,
    scene: &Scene,
    uploads: &[UploadedMesh],
    batches: &RayBatches,
    ours: &SceneReport,
) -> Option<BackendComparison> {
    let this = backend_of(bench, bench.backend.get())?;
    let (other, other_choice) = match this {
        ksrt::TraversalBackend::Software => (
            ksrt::TraversalBackend::HardwareRayQuery,
            ksrt::BackendChoice::HardwareRayQuery,
        ),
        ksrt::TraversalBackend::HardwareRayQuery => (
            ksrt::TraversalBackend::Software,
            ksrt::BackendChoice::Software,
        ),
    };
    // Only where the device can take the other backend too.
    backend_of(bench, other_choice)?;
    let mut report = BackendComparison {
        this: this.to_string(),
        other: other.to_string(),
        other_blas_build: None,
        this_tlas_build: None,
        other_tlas_build: None,
        rays: Vec::new(),
        errors: Vec::new(),
    };
    let mut errors = Vec::new();
    report.this_tlas_build = attempt(&mut errors, "TLAS build", || {
        bench.tlas_rebuild(scene, uploads)
    });
    let measured = bench.backend.replace(other_choice);
    report.other_blas_build = attempt(&mut errors, "other backend: BLAS build", || {
        Ok(bench.blas_build(scene, uploads, ksrt::BuildHint::Auto)?.0)
    });
    report.other_tlas_build = attempt(&mut errors, "other backend: TLAS build", || {
        bench.tlas_rebuild(scene, uploads)
    });
    if let Some((ctx, _)) = attempt(&mut errors, "other backend: registration", || {
        bench.registered(scene, uploads, false, true)
    }) {
        for ((kind, query, rays, this_hits), this_batch) in batches.batches.iter().zip(&ours.rays) {
            let Some((time, other_hits)) =
                attempt(&mut errors, &format!("other backend: {kind} rays"), || {
                    bench.trace(&ctx, rays, *query)
                })
            else {
                continue;
            };
            let this_hits: Vec<vkrt::Hit> = this_hits.iter().map(peer_hit).collect();
            let other_hits: Vec<vkrt::Hit> = other_hits.iter().map(peer_hit).collect();
            let agreement = vkrt::compare_hits(&this_hits, &other_hits, query_kind(*query));
            let max_relative_distance = this_hits
                .iter()
                .zip(&other_hits)
                .filter(|(a, b)| {
                    a.hit == 1
                        && b.hit == 1
                        && (a.instance, a.primitive) == (b.instance, b.primitive)
                })
                .map(|(a, b)| (a.t as f64 - b.t as f64).abs() / (a.t.abs() as f64).max(1.0))
                .fold(0.0, f64::max);
            if agreement.disagreement_fraction() > MAX_DISAGREEMENT {
                errors.push(format!(
                    "{kind} rays: the backends disagree on {} of {} rays (more than {} %)",
                    agreement.disagreements,
                    rays.len(),
                    MAX_DISAGREEMENT * 100.0
                ));
            }
            report.rays.push(BackendRays {
                kind,
                rays: rays.len() as u64,
                this_mrays_per_s: this_batch.mrays_per_s,
                other_mrays_per_s: rays.len() as f64 / (time.median_ms * 1e3),
                other_time: time,
                agreement: agreement.into(),
                max_relative_distance,
            });
        }
    }
    bench.backend.set(measured);
    report.errors = errors;
    Some(report)
}

/// Prints a comparison under its scene.
pub(super) fn print(c: &BackendComparison, ours: &SceneReport) {
    println!("  backends: {} (above) against {}", c.this, c.other);
    let ms = |s: Option<&Stats>| s.map_or("—".to_string(), |s| format!("{:.3} ms", s.median_ms));
    println!(
        "    BLAS build  {} / {}    TLAS build  {} / {}",
        ms(ours.blas_build.as_ref()),
        ms(c.other_blas_build.as_ref()),
        ms(c.this_tlas_build.as_ref()),
        ms(c.other_tlas_build.as_ref()),
    );
    for r in &c.rays {
        let a = &r.agreement;
        println!(
            "    {:<8} {:>8.1} / {:>8.1} Mrays/s   disagree {} of {} ({:.4} %; hit/miss {}, other triangle {}), ties {}, distances apart {}, largest distance difference {:.1e}",
            r.kind,
            r.this_mrays_per_s,
            r.other_mrays_per_s,
            a.disagreements,
            r.rays,
            a.disagreement_percent,
            a.hit_miss,
            a.different_triangle,
            a.ties,
            a.distance_mismatches,
            r.max_relative_distance
        );
    }
    for e in &c.errors {
        println!("    failed: {e}");
    }
}
