//! `ksrt bench --cpu-peers`: our GPU BLAS builder against CPU builders on the same triangles:
//! our CPU binned-SAH builder (`kickstart_rt::cpu::CpuBvh`, one thread) and the `obvhs` crate's
//! PLOC builder (all cores, three presets). For each: build time and the SAH cost of the tree,
//! all with the cost formula and constants of `CpuBvh::sah_cost`.

use kickstart_rt_renderer::upload;
use std::path::Path;
use std::time::Instant;

use glam::{Affine3A, Vec3};
use serde::{Deserialize, Serialize};

use crate::lab::bench::harness::Bench;
use crate::lab::bench::{attempt, Stats};
use crate::lab::obvhs_peer::{self, Preset};
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::scene::{Mesh, Scene};
use kickstart_rt_renderer::sdk_glue as glue;

/// Scenes of the comparison.
pub const CPU_PEER_SCENES: [&str; 3] = ["cornell-obj", "apartment", "statue"];

/// Timed CPU repetitions stop once they have taken this long (at least one runs).
const CPU_BUDGET_S: f64 = 15.0;

/// The whole `--cpu-peers` result.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct CpuPeersReport {
    /// Logical CPU cores (what obvhs's thread pool uses).
    pub cpu_threads: usize,
    /// The CPU, as `/proc/cpuinfo` names it.
    pub cpu_model: String,
    /// Per mesh.
    pub meshes: Vec<PeerMesh>,
    /// Measurements that failed, and why.
    pub errors: Vec<String>,
}

/// One mesh built by every builder.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct PeerMesh {
    /// The scene.
    pub scene: String,
    /// The mesh: a geometry's name, or `whole scene` (every instance's triangles in world
    /// space as one mesh).
    pub mesh: String,
    /// Triangles.
    pub triangles: usize,
    /// One per builder.
    pub builds: Vec<PeerBuild>,
}

/// One builder on one mesh.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PeerBuild {
    /// `kickstart-rt GPU`, `kickstart-rt CPU binned SAH` or `obvhs <preset>`.
    pub builder: String,
    /// `gpu` or `cpu`.
    pub device: String,
    /// CPU threads the builder uses (0 for the GPU).
    pub threads: usize,
    /// Build time: GPU timestamps (`ingest` + `blas build`) or CPU wall clock of the build
    /// call.
    pub time: Stats,
    /// Triangles / median time, millions per second.
    pub mtri_per_s: f64,
    /// SAH cost (relative to the root box; traversal and intersection cost 1).
    pub sah_cost: f64,
    /// SAH cost / our CPU binned-SAH builder's on the same mesh (1 = as good; lower is better).
    pub sah_vs_cpu_binned: Option<f64>,
}

/// The CPU's model name, or `unknown`.
fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}

/// Runs `one` once untimed, then up to `iterations` times timed within [`CPU_BUDGET_S`]
/// (at least once). Returns the statistics and the last result.
pub fn cpu_repeat<T>(
    iterations: u32,
    mut one: impl FnMut() -> AnyResult<T>,
) -> AnyResult<(Stats, T)> {
    let mut last = one()?;
    let mut samples = Vec::new();
    let budget = Instant::now();
    while samples.len() < iterations.max(1) as usize
        && (samples.is_empty() || budget.elapsed().as_secs_f64() < CPU_BUDGET_S)
    {
        let t = Instant::now();
        last = one()?;
        samples.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok((Stats::new(samples), last))
}

/// The meshes compared from one scene: the whole scene in world space as one mesh, and its
/// largest geometry when the scene has several and it is not tiny.
pub fn targets(scene: &Scene) -> Vec<Mesh> {
    let mut out = Vec::new();
    let (world, _) = scene.world_triangles();
    let positions: Vec<[f32; 3]> = world.iter().flatten().map(|v| v.to_array()).collect();
    let indices: Vec<u32> = (0..positions.len() as u32).collect();
    if let Ok(m) = Mesh::new("whole scene", positions, indices, Vec3::ONE) {
        out.push(m);
    }
    if scene.meshes.len() > 1 {
        if let Some(m) = scene
            .meshes
            .iter()
            .max_by_key(|m| m.triangle_count())
            .filter(|m| m.triangle_count() >= 1000)
        {
            out.push(m.clone());
        }
    }
    out
}

/// Builds every builder's tree over `mesh` and times it.
fn compare(bench: &Bench, scene_name: &str, mesh: &Mesh, errors: &mut Vec<String>) -> PeerMesh {
    let tris: Vec<[Vec3; 3]> = mesh.triangles(Affine3A::IDENTITY).collect();
    let n = tris.len();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut out = PeerMesh {
        scene: scene_name.to_string(),
        mesh: mesh.name.clone(),
        triangles: n,
        builds: Vec::new(),
    };
    let label = format!("{scene_name} / {}", mesh.name);
    let mtri = |s: &Stats| n as f64 / (s.median_ms * 1e3);
    let single = Scene {
        name: label.clone(),
        meshes: vec![mesh.clone()],
        ..Default::default()
    };
    if let Some(b) = attempt(errors, &format!("{label}: GPU build"), || {
        let uploads = upload::upload_scene(bench.device, bench.queue, &single);
        let (time, ctx, h) = bench.blas_build(&single, &uploads, kickstart_rt::BuildHint::Auto)?;
        let sah = glue::blas_sah_cost(&ctx, h.geometries[0])?;
        Ok(PeerBuild {
            builder: "kickstart-rt GPU".into(),
            device: "gpu".into(),
            threads: 0,
            mtri_per_s: mtri(&time),
            time,
            sah_cost: sah,
            sah_vs_cpu_binned: None,
        })
    }) {
        out.builds.push(b);
    }
    if let Some(b) = attempt(errors, &format!("{label}: CPU binned SAH"), || {
        let (time, bvh) = cpu_repeat(bench.iterations, || {
            Ok(kickstart_rt::cpu::CpuBvh::build(&tris))
        })?;
        if bvh.nodes.is_empty() {
            return Err("no finite triangle to build over".into());
        }
        Ok(PeerBuild {
            builder: "kickstart-rt CPU binned SAH".into(),
            device: "cpu".into(),
            threads: 1,
            mtri_per_s: mtri(&time),
            time,
            sah_cost: bvh.sah_cost() as f64,
            sah_vs_cpu_binned: Some(1.0),
        })
    }) {
        out.builds.push(b);
    }
    // obvhs's triangle layout is made outside the timed build (a user of obvhs has it already).
    let theirs = obvhs_peer::to_obvhs(&tris);
    for preset in Preset::ALL {
        if let Some(b) = attempt(errors, &format!("{label}: {}", preset.name()), || {
            let (time, bvh) = cpu_repeat(bench.iterations, || {
                obvhs_peer::build(&theirs, preset).map_err(Into::into)
            })?;
            Ok(PeerBuild {
                builder: preset.name().into(),
                device: "cpu".into(),
                threads,
                mtri_per_s: mtri(&time),
                time,
                sah_cost: obvhs_peer::sah_cost(&bvh),
                sah_vs_cpu_binned: None,
            })
        }) {
            out.builds.push(b);
        }
    }
    let reference = out
        .builds
        .iter()
        .find(|b| b.builder == "kickstart-rt CPU binned SAH")
        .map(|b| b.sah_cost);
    if let Some(r) = reference.filter(|r| *r > 0.0) {
        for b in &mut out.builds {
            b.sah_vs_cpu_binned = Some(b.sah_cost / r);
        }
    }
    out
}

fn print_mesh(m: &PeerMesh) {
    println!("  {} / {} ({} triangles)", m.scene, m.mesh, m.triangles);
    println!(
        "    {:<30} {:<4} {:>7}  {:>28}  {:>9}  {:>8}  {:>9}",
        "builder", "on", "threads", "build (median, min..max)", "Mtri/s", "SAH", "vs CPU"
    );
    for b in &m.builds {
        println!(
            "    {:<30} {:<4} {:>7}  {:>28}  {:>9.1}  {:>8.2}  {:>9}",
            b.builder,
            b.device,
            b.threads,
            b.time.show(),
            b.mtri_per_s,
            b.sah_cost,
            b.sah_vs_cpu_binned
                .map_or("—".to_string(), |r| format!("{r:.3}"))
        );
    }
}

/// Scenes of `--cpu-peers --quick` (a smoke test).
pub const QUICK_SCENES: [&str; 2] = ["cornell-obj", "cornell-gltf"];

/// `--cpu-peers` over `scenes`; a scene that fails to load is an error in the report, the others
/// still run.
pub(in crate::lab::bench) fn run(
    bench: &Bench,
    scenes_dir: &Path,
    scenes: &[&str],
) -> CpuPeersReport {
    let mut report = CpuPeersReport {
        cpu_threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        cpu_model: cpu_model(),
        ..Default::default()
    };
    println!(
        "  CPU: {} ({} threads); obvhs runs on all of them, our CPU builder on one",
        report.cpu_model, report.cpu_threads
    );
    for &name in scenes {
        let Some(scene) = attempt(&mut report.errors, &format!("load {name}"), || {
            super::load(name, scenes_dir)
        }) else {
            continue;
        };
        for mesh in targets(&scene) {
            println!(
                "  building {name} / {} ({} triangles) with each builder…",
                mesh.name,
                mesh.triangle_count()
            );
            let m = compare(bench, name, &mesh, &mut report.errors);
            print_mesh(&m);
            report.meshes.push(m);
        }
    }
    for e in &report.errors {
        println!("  failed: {e}");
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use kickstart_rt_renderer::scene::Instance;

    #[test]
    fn targets_are_the_world_mesh_and_a_large_geometry() {
        let quad = |n: usize| {
            let mut p = Vec::new();
            let mut i = Vec::new();
            for k in 0..n {
                let x = k as f32;
                p.extend([[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]);
                i.extend([3 * k as u32, 3 * k as u32 + 1, 3 * k as u32 + 2]);
            }
            Mesh::new(format!("m{n}"), p, i, Vec3::ONE).unwrap()
        };
        let scene = Scene {
            meshes: vec![quad(2), quad(1200)],
            instances: vec![
                Instance {
                    mesh: 0,
                    transform: Affine3A::from_translation(Vec3::new(0.0, 5.0, 0.0)),
                },
                Instance {
                    mesh: 0,
                    transform: Affine3A::IDENTITY,
                },
                Instance {
                    mesh: 1,
                    transform: Affine3A::IDENTITY,
                },
            ],
            ..Default::default()
        };
        let t = targets(&scene);
        assert_eq!(t.len(), 2);
        assert_eq!(t[0].name, "whole scene");
        // Instanced twice: counted twice, placed in the world.
        assert_eq!(t[0].triangle_count(), 2 + 2 + 1200);
        assert_eq!(t[0].positions[1], [1.0, 5.0, 0.0]);
        assert_eq!(t[1].name, "m1200");
        // One small geometry: the whole scene only.
        let small = Scene {
            meshes: vec![quad(3)],
            instances: vec![Instance {
                mesh: 0,
                transform: Affine3A::IDENTITY,
            }],
            ..Default::default()
        };
        assert_eq!(targets(&small).len(), 1);
    }

    /// GPU (lavapipe: the 32-triangle Cornell box): every builder builds, the GPU's SAH is read
    /// back, and each cost is compared with our CPU builder's. On a device without timestamp
    /// queries (CI's `Features::empty()` pass) the GPU build cannot be timed: it must say so, and
    /// the CPU builders must still be measured.
    #[test]
    fn every_builder_builds_the_cornell_box() {
        let (device, queue) = crate::app::testing::device();
        let timed = device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let bench = Bench::new(device, queue, 1);
        let scene = kickstart_rt_renderer::scene::builtin::cornell_box();
        let mesh = targets(&scene).remove(0);
        let mut errors = Vec::new();
        let m = compare(&bench, "cornell", &mesh, &mut errors);
        let mut expected = vec![
            "kickstart-rt GPU",
            "kickstart-rt CPU binned SAH",
            "obvhs fastest_build",
            "obvhs medium_build",
            "obvhs very_slow_build",
        ];
        if timed {
            assert!(errors.is_empty(), "{errors:?}");
        } else {
            assert_eq!(errors.len(), 1, "{errors:?}");
            assert!(
                errors[0].starts_with("cornell / whole scene: GPU build")
                    && errors[0].contains("timings"),
                "{errors:?}"
            );
            expected.remove(0);
        }
        assert_eq!(m.triangles, scene.triangle_count());
        let names: Vec<&str> = m.builds.iter().map(|b| b.builder.as_str()).collect();
        assert_eq!(names, expected);
        for b in &m.builds {
            // The root alone costs 1; no sane tree over 32 triangles costs their count twice.
            assert!(b.sah_cost >= 1.0 && b.sah_cost < 64.0, "{b:?}");
            let r = b.sah_vs_cpu_binned.expect("ratio");
            assert!(r > 0.3 && r < 3.0, "{b:?}");
            assert!(b.time.median_ms >= 0.0);
        }
        let cpu = m
            .builds
            .iter()
            .find(|b| b.builder == "kickstart-rt CPU binned SAH")
            .expect("our CPU build");
        assert_eq!(cpu.sah_vs_cpu_binned, Some(1.0));
    }

    #[test]
    fn cpu_repeat_times_at_least_once_and_keeps_the_last_result() {
        let mut calls = 0;
        let (stats, last) = cpu_repeat(3, || {
            calls += 1;
            Ok(calls)
        })
        .unwrap();
        assert_eq!(calls, 4, "one warm-up and three timed");
        assert_eq!(last, 4);
        assert_eq!(stats.samples_ms.len(), 3);
        let err = cpu_repeat(3, || -> AnyResult<()> { Err("boom".into()) });
        assert!(err.is_err());
    }
}
