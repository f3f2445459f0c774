//! The peer on this machine's Vulkan: skipped (Unavailable) without ray tracing, traced with it.
//!
//! The tracing tests need a device with ray-tracing pipelines, which the software Vulkan of CI's
//! test passes (Mesa 22's lavapipe) lacks: they are `#[ignore]`d there, so they are counted as
//! ignored rather than as passes. CI runs them in a step of their own on Mesa 25's lavapipe
//! (`--include-ignored`, `KSRT_REQUIRE_RT_PEER=1`), where a missing device fails them; so does the
//! GPU machine.

use kickstart_rt_peer_vulkan::{
    BuildPreference, Hit, Instance, Mesh, PeerError, Query, Ray, Timing, VulkanRtPeer,
};

fn required() -> bool {
    std::env::var_os("KSRT_REQUIRE_RT_PEER").is_some_and(|v| !v.is_empty() && v != "0")
}

/// The peer; a test that asks for it was run on purpose (`--ignored`), so no device fails it.
fn peer() -> VulkanRtPeer {
    VulkanRtPeer::new(None)
        .unwrap_or_else(|e| panic!("this test needs a ray-tracing Vulkan device: {e}"))
}

/// One Vulkan device as the loader reports it, read here without the peer: the oracle of what
/// the peer must say.
struct Device {
    name: String,
    /// Of the ray-tracing extensions the peer needs, those the device does not offer.
    lacks: Vec<&'static str>,
    /// Vulkan 1.2, the extensions, and the features the peer enables.
    ray_tracing: bool,
}

/// The devices of this machine's Vulkan, or `None` without a loader (of Vulkan 1.2 at least).
fn devices() -> Option<Vec<Device>> {
    use ash::{khr, vk};
    // SAFETY: loading the system's Vulkan loader, as the peer does.
    let entry = unsafe { ash::Entry::load() }.ok()?;
    // SAFETY: entry is a loaded loader.
    let version = unsafe { entry.try_enumerate_instance_version() }
        .expect("vkEnumerateInstanceVersion")
        .unwrap_or(vk::API_VERSION_1_0);
    if version < vk::API_VERSION_1_2 {
        // The peer needs a 1.2 loader: as good as none.
        return None;
    }
    let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_2);
    // SAFETY: valid create info without layers or extensions.
    let instance = unsafe {
        entry.create_instance(
            &vk::InstanceCreateInfo::default().application_info(&app),
            None,
        )
    }
    .expect("vkCreateInstance");
    // SAFETY: a live instance.
    let pds = unsafe { instance.enumerate_physical_devices() }.expect("physical devices");
    let wanted = [
        khr::acceleration_structure::NAME,
        khr::ray_tracing_pipeline::NAME,
        khr::deferred_host_operations::NAME,
    ];
    let mut out = Vec::new();
    for pd in pds {
        // SAFETY: pd is one of the instance's devices.
        let props = unsafe { instance.get_physical_device_properties(pd) };
        // SAFETY: as above.
        let exts = unsafe { instance.enumerate_device_extension_properties(pd) }.expect("exts");
        let lacks: Vec<&'static str> = wanted
            .iter()
            .filter(|w| !exts.iter().any(|e| e.extension_name_as_c_str() == Ok(**w)))
            .map(|w| w.to_str().expect("ASCII"))
            .collect();
        let mut ray_tracing = lacks.is_empty() && props.api_version >= vk::API_VERSION_1_2;
        if ray_tracing {
            let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
            let mut fas = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default();
            let mut frt = vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default();
            let mut f2 = vk::PhysicalDeviceFeatures2::default()
                .push_next(&mut f12)
                .push_next(&mut fas)
                .push_next(&mut frt);
            // SAFETY: a valid chain of feature structs; the extensions exist.
            unsafe { instance.get_physical_device_features2(pd, &mut f2) };
            ray_tracing = f12.buffer_device_address == vk::TRUE
                && fas.acceleration_structure == vk::TRUE
                && frt.ray_tracing_pipeline == vk::TRUE;
        }
        out.push(Device {
            name: props
                .device_name_as_c_str()
                .expect("device name")
                .to_string_lossy()
                .into_owned(),
            lacks,
            ray_tracing,
        });
    }
    // SAFETY: nothing was created from the instance.
    unsafe { instance.destroy_instance(None) };
    Some(out)
}

/// The peer's outcome is the one this machine's Vulkan implies: with a ray-tracing device, a peer
/// on one; without, `Unavailable` naming every device and each ray-tracing extension it lacks.
#[test]
fn unavailable_names_the_device_and_missing_extension() {
    let result = VulkanRtPeer::new(None);
    let Some(devices) = devices() else {
        match result {
            Err(PeerError::Unavailable(why)) => {
                assert!(!required(), "KSRT_REQUIRE_RT_PEER is set: {why}");
                assert!(why.contains("Vulkan loader"), "{why}");
                return;
            }
            Ok(p) => panic!(
                "no Vulkan 1.2 loader here, yet a peer on {}",
                p.device_name()
            ),
            Err(e) => panic!("no Vulkan 1.2 loader: expected Unavailable, got: {e}"),
        }
    };
    for d in &devices {
        eprintln!(
            "{}: lacks {:?}, ray tracing: {}",
            d.name, d.lacks, d.ray_tracing
        );
    }
    let usable: Vec<&str> = devices
        .iter()
        .filter(|d| d.ray_tracing)
        .map(|d| d.name.as_str())
        .collect();
    match result {
        Ok(p) => assert!(
            usable.contains(&p.device_name()),
            "the peer runs on {}, not one of the ray-tracing devices {usable:?}",
            p.device_name()
        ),
        Err(PeerError::Unavailable(why)) => {
            assert!(
                usable.is_empty(),
                "{usable:?} can trace rays, yet the peer is unavailable: {why}"
            );
            assert!(
                !required(),
                "KSRT_REQUIRE_RT_PEER is set but no device traces rays: {why}"
            );
            if devices.is_empty() {
                assert!(why.contains("no Vulkan physical device"), "{why}");
            }
            for d in &devices {
                // This device's part of the message: "NAME lacks A, B" up to the next "; ".
                let at = why
                    .find(&format!("{} lacks ", d.name))
                    .unwrap_or_else(|| panic!("the message does not name {}: {why}", d.name));
                let part = why[at..].split("; ").next().unwrap_or_default();
                for ext in &d.lacks {
                    assert!(
                        part.contains(ext),
                        "{} lacks {ext}, not said: {why}",
                        d.name
                    );
                }
            }
            eprintln!("unavailable: {why}");
        }
        Err(e) => panic!("expected Unavailable or a peer, got: {e}"),
    }
}

const TIMING: Timing = Timing {
    iterations: 1,
    warm_up: std::time::Duration::ZERO,
};

fn ray(origin: [f32; 3], dir: [f32; 3], t_min: f32, t_max: f32) -> Ray {
    Ray {
        origin,
        t_min,
        dir,
        t_max,
    }
}

/// A unit quad (two triangles sharing the diagonal) in z = 0, instanced twice: at z = 0
/// (index 5) and moved to z = -2 (index 9).
#[test]
#[ignore = "needs a ray-tracing Vulkan device: .ci/run runs it on Mesa 25 lavapipe (--include-ignored)"]
fn traces_our_hit_rules_on_a_quad() {
    let mut peer = peer();
    let positions = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    let indices = [0, 1, 2, 0, 2, 3];
    peer.upload_meshes(&[
        Mesh {
            positions: &positions,
            indices: &indices,
        },
        Mesh {
            positions: &[],
            indices: &[],
        },
    ])
    .expect("upload");
    assert_eq!(peer.blas_compacted_bytes(), None, "no BLAS built yet");
    // Fast-build between two fast-trace builds: it must not keep the first one's size.
    use BuildPreference::{FastBuild, FastTrace};
    for pref in [FastTrace, FastBuild, FastTrace] {
        let t = peer.build_blases(pref, TIMING).expect("BLAS build");
        assert!(t.median() >= 0.0);
        let (bytes, compacted) = (peer.blas_bytes(), peer.blas_compacted_bytes());
        eprintln!("{pref:?}: BLAS {bytes} bytes, compacted {compacted:?}");
        match pref {
            // Built without ALLOW_COMPACTION: nothing to query.
            FastBuild => assert_eq!(compacted, None),
            // Compaction never grows a BLAS, and a BLAS over two triangles is not empty.
            FastTrace => {
                assert!(
                    compacted.is_some_and(|c| c > 0 && c <= bytes),
                    "{compacted:?} of {bytes}"
                )
            }
        }
    }
    let moved = glam::Affine3A::from_translation(glam::Vec3::new(0.0, 0.0, -2.0));
    peer.build_tlas(
        &[
            Instance {
                mesh: 0,
                transform: Instance::row_major(glam::Affine3A::IDENTITY),
                mask: 0xff,
                index: 5,
            },
            Instance {
                mesh: 0,
                transform: Instance::row_major(moved),
                mask: 0xff,
                index: 9,
            },
            // An instance of the empty mesh: left out, nothing to hit.
            Instance {
                mesh: 1,
                transform: Instance::row_major(glam::Affine3A::IDENTITY),
                mask: 0xff,
                index: 1,
            },
        ],
        TIMING,
    )
    .expect("TLAS build");
    let down = [0.0, 0.0, -1.0];
    let rays = [
        // Lower-right triangle (primitive 0) of the first instance, at t = 1.
        ray([0.75, 0.25, 1.0], down, 0.0, f32::INFINITY),
        // Upper-left triangle (primitive 1).
        ray([0.25, 0.75, 1.0], down, 0.0, f32::INFINITY),
        // Outside the quad: miss.
        ray([1.5, 0.5, 1.0], down, 0.0, f32::INFINITY),
        // From behind (no culling): hits the moved instance's back face at t = 1.
        ray([0.75, 0.25, -3.0], [0.0, 0.0, 1.0], 0.0, 1.5),
        // t range excludes the first instance: hits the second at t = 3.
        ray([0.75, 0.25, 1.0], down, 1.5, f32::INFINITY),
        // t_max short of the quad: miss.
        ray([0.75, 0.25, 1.0], down, 0.0, 0.5),
        // Non-finite direction: a miss, not undefined behaviour.
        ray([0.5, 0.5, 1.0], [f32::NAN, 0.0, -1.0], 0.0, f32::INFINITY),
    ];
    let (time, hits) = peer.trace(&rays, Query::Closest, 4, TIMING).expect("trace");
    assert_eq!(time.0.len(), 1);
    assert_eq!(hits.len(), rays.len());
    let expect = |h: &Hit, t: f32, instance: u32, primitive: u32| {
        assert!(h.is_hit(), "{h:?}");
        assert!((h.t - t).abs() < 1e-5, "{h:?}");
        assert_eq!((h.instance, h.primitive), (instance, primitive), "{h:?}");
    };
    expect(&hits[0], 1.0, 5, 0);
    expect(&hits[1], 1.0, 5, 1);
    assert!(!hits[2].is_hit(), "{:?}", hits[2]);
    assert_eq!(hits[2].instance, u32::MAX);
    expect(&hits[3], 1.0, 9, 0);
    expect(&hits[4], 3.0, 9, 0);
    assert!(!hits[5].is_hit());
    assert!(!hits[6].is_hit());
    // Barycentrics: weights of the second and third vertex, as ours. Ray 0 hits (0.75, 0.25)
    // on triangle (0,0)-(1,0)-(1,1): u = 0.5, v = 0.25.
    assert!(
        (hits[0].u - 0.5).abs() < 1e-5 && (hits[0].v - 0.25).abs() < 1e-5,
        "{:?}",
        hits[0]
    );
    let (_, any) = peer
        .trace(&rays, Query::Any, 64, TIMING)
        .expect("any-hit trace");
    let flags: Vec<bool> = any.iter().map(Hit::is_hit).collect();
    assert_eq!(flags, [true, true, false, true, true, false, false]);
}
