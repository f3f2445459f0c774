//! A benchmark **peer** for kickstart-rt: the GPU driver's own hardware-API ray tracing
//! (Vulkan `VK_KHR_acceleration_structure` + `VK_KHR_ray_tracing_pipeline`) on the same meshes and
//! the same rays as our WGSL tracer, so `ksrt bench --peer vulkan-rt` can print side-by-side
//! ratios measured in one run on one GPU.
//!
//! The peer is deliberately minimal: one BLAS per geometry (one triangle geometry each, opaque),
//! one TLAS, and a ray-generation shader that reads a batch of rays and writes one hit record per
//! ray, laid out as kickstart-rt's `GpuRay` / `GpuHit`. GPU times come from timestamp queries
//! around the builds and around `vkCmdTraceRaysKHR` only.
//!
//! Where no Vulkan device has hardware ray tracing (Mesa's lavapipe before 25, or no Vulkan
//! loader at all) [`VulkanRtPeer::new`] returns [`PeerError::Unavailable`] naming the devices
//! and what each lacks: the bench prints that and skips the peer.
//!
//! ## Running the peer on a CPU (Mesa 25's lavapipe)
//!
//! Debian bookworm's lavapipe (Mesa 22.3) has no ray tracing; bookworm-backports' Mesa 25 has.
//! It can be used without replacing the system Mesa:
//!
//! ```sh
//! # once: add bookworm-backports to apt's sources (pinned low, so nothing upgrades by itself)
//! mkdir -p /opt/mesa25/debs && cd /opt/mesa25/debs
//! apt-get download mesa-vulkan-drivers/bookworm-backports libdrm2/bookworm-backports \
//!     libdrm-amdgpu1/bookworm-backports
//! for d in *.deb; do dpkg -x "$d" /opt/mesa25; done
//! sed 's#"libvulkan_lvp.so"#"/opt/mesa25/usr/lib/x86_64-linux-gnu/libvulkan_lvp.so"#' \
//!     /opt/mesa25/usr/share/vulkan/icd.d/lvp_icd.json > /opt/mesa25/lvp_icd.json
//! # then, for any command (Mesa 25 uses the system's libllvm15)
//! export VK_DRIVER_FILES=/opt/mesa25/lvp_icd.json
//! export LD_LIBRARY_PATH=/opt/mesa25/usr/lib/x86_64-linux-gnu
//! KSRT_REQUIRE_RT_PEER=1 cargo test -p kickstart-rt-peer-vulkan -- --include-ignored
//! cargo test -p kickstart-rt-demo peer -- --include-ignored
//! ```
//!
//! The tests that trace with the peer are `#[ignore]`d in CI's test passes (their Mesa 22
//! lavapipe has no ray tracing, and a test that returned early there would count as a pass);
//! `.ci/run` runs them in a step of their own on Mesa 25's lavapipe, which has it
//! (`.ci/lavapipe-rt`). Run with `--include-ignored`, they fail when no
//! ray-tracing device is found. `KSRT_REQUIRE_RT_PEER` makes the skip-path test fail too.

#![warn(missing_docs)]

mod compare;
mod select;
mod vulkan;

pub use compare::{
    classify, compare_hits, Agreement, Outcome, QueryKind, DISTANCE_REL_TOLERANCE,
    TIE_REL_TOLERANCE,
};
pub use select::{choose_device, DeviceCandidate, DeviceHint, REQUIRED_EXTENSIONS};
pub use vulkan::VulkanRtPeer;

/// Everything that can go wrong in the peer. None of them is a panic: the bench reports the text
/// and carries on with its own measurements.
#[derive(Debug, thiserror::Error)]
pub enum PeerError {
    /// No usable ray-tracing device (or no Vulkan loader): the peer is skipped. The text names the
    /// devices seen and what each lacks.
    #[error("Vulkan ray tracing unavailable: {0}")]
    Unavailable(String),
    /// A Vulkan call failed.
    #[error("Vulkan: {what}: {result}")]
    Vulkan {
        /// The call, and what it was for.
        what: &'static str,
        /// Its result code.
        result: ash::vk::Result,
    },
    /// An input the peer cannot take (an index out of range, too many rays for a buffer, …).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// No device memory type fits a buffer's needs.
    #[error("no memory type for {0}")]
    NoMemoryType(&'static str),
    /// The call needs an earlier step (meshes before BLASes, BLASes before the TLAS, …).
    #[error("{0}")]
    Order(&'static str),
}

/// A `Result` with [`PeerError`].
pub type Result<T> = std::result::Result<T, PeerError>;

/// One ray: kickstart-rt's `GpuRay` layout (32 bytes), so batches can be shared byte for byte.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Ray {
    /// Origin, world space.
    pub origin: [f32; 3],
    /// Smallest accepted hit distance (negative values are traced from 0: the API's minimum).
    pub t_min: f32,
    /// Direction (need not be unit length; t is in units of it).
    pub dir: [f32; 3],
    /// Largest accepted hit distance (may be +∞).
    pub t_max: f32,
}

/// One ray's result, kickstart-rt's `GpuHit` layout with the hit flag in the first padding word.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Hit {
    /// Ray parameter of the hit; −1 on a miss.
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the third vertex.
    pub v: f32,
    /// The instance's index (what [`Instance::index`] gave); `u32::MAX` on a miss.
    pub instance: u32,
    /// Triangle index within the instance's mesh; `u32::MAX` on a miss.
    pub primitive: u32,
    /// 1 on a hit, 0 on a miss.
    pub hit: u32,
    /// Padding to 32 bytes.
    pub _pad: [u32; 2],
}

impl Hit {
    /// The record of a miss.
    pub const MISS: Hit = Hit {
        t: -1.0,
        u: 0.0,
        v: 0.0,
        instance: u32::MAX,
        primitive: u32::MAX,
        hit: 0,
        _pad: [0; 2],
    };

    /// A hit at `t` on `primitive` of `instance` (barycentrics 0).
    pub fn at(t: f32, instance: u32, primitive: u32) -> Hit {
        Hit {
            t,
            instance,
            primitive,
            hit: 1,
            ..Hit::MISS
        }
    }

    /// Whether the ray hit something.
    pub fn is_hit(&self) -> bool {
        self.hit != 0
    }
}

/// A triangle mesh: one BLAS.
#[derive(Debug, Clone, Copy)]
pub struct Mesh<'a> {
    /// Vertex positions (object space).
    pub positions: &'a [[f32; 3]],
    /// Triangle-list indices into `positions` (a multiple of 3).
    pub indices: &'a [u32],
}

/// One TLAS instance.
#[derive(Debug, Clone, Copy)]
pub struct Instance {
    /// Index of its mesh in the slice given to [`VulkanRtPeer::upload_meshes`].
    pub mesh: usize,
    /// Object-to-world transform, 3×4 row-major (Vulkan's `VkTransformMatrixKHR`).
    pub transform: [f32; 12],
    /// Visibility mask (rays are traced with mask 0xff).
    pub mask: u8,
    /// Reported as [`Hit::instance`] (24 bits: at most 0xff_ffff). The bench gives our instance
    /// slot index, so hit records compare directly.
    pub index: u32,
}

impl Instance {
    /// The 3×4 row-major transform of a glam affine transform (column vectors).
    pub fn row_major(transform: glam::Affine3A) -> [f32; 12] {
        let m = glam::Mat4::from(transform).transpose().to_cols_array();
        // After the transpose, the columns are the original rows: take the first three rows.
        let mut out = [0.0; 12];
        out.copy_from_slice(&m[..12]);
        out
    }
}

/// BLAS build preference (`VK_BUILD_ACCELERATION_STRUCTURE_PREFER_FAST_*`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BuildPreference {
    /// `PREFER_FAST_TRACE`: what a static scene uses.
    FastTrace,
    /// `PREFER_FAST_BUILD`: what dynamic geometry uses.
    FastBuild,
}

/// Which hit a ray batch asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Query {
    /// The closest hit.
    Closest,
    /// The first hit found (`gl_RayFlagsTerminateOnFirstHitEXT`): occlusion.
    Any,
}

/// How a measurement repeats.
#[derive(Debug, Clone, Copy)]
pub struct Timing {
    /// Timed repetitions (at least 1).
    pub iterations: u32,
    /// Untimed repetitions run first for at least this long, so GPU clocks are up (the bench
    /// does the same for ours: one short run leaves them low).
    pub warm_up: std::time::Duration,
}

impl Default for Timing {
    fn default() -> Self {
        Timing {
            iterations: 5,
            warm_up: std::time::Duration::from_millis(500),
        }
    }
}

/// GPU times of the timed repetitions, milliseconds, in order.
#[derive(Debug, Clone, PartialEq)]
pub struct Samples(pub Vec<f64>);

impl Samples {
    /// The median (NaN when empty).
    pub fn median(&self) -> f64 {
        let mut s = self.0.clone();
        s.sort_by(f64::total_cmp);
        let n = s.len();
        match n {
            0 => f64::NAN,
            _ if n % 2 == 1 => s[n / 2],
            _ => (s[n / 2 - 1] + s[n / 2]) / 2.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_match_kickstart_rt() {
        assert_eq!(std::mem::size_of::<Ray>(), 32);
        assert_eq!(std::mem::size_of::<Hit>(), 32);
    }

    #[test]
    fn row_major_transform() {
        let a = glam::Affine3A::from_translation(glam::Vec3::new(1.0, 2.0, 3.0))
            * glam::Affine3A::from_scale(glam::Vec3::new(2.0, 3.0, 4.0));
        let m = Instance::row_major(a);
        assert_eq!(
            m,
            [2.0, 0.0, 0.0, 1.0, 0.0, 3.0, 0.0, 2.0, 0.0, 0.0, 4.0, 3.0]
        );
        let r = glam::Affine3A::from_rotation_z(0.5);
        let m = Instance::row_major(r);
        let p = glam::Vec3::new(0.3, -0.7, 1.1);
        let q = r.transform_point3(p);
        for (row, want) in [q.x, q.y, q.z].into_iter().enumerate() {
            let got =
                m[row * 4] * p.x + m[row * 4 + 1] * p.y + m[row * 4 + 2] * p.z + m[row * 4 + 3];
            assert!((got - want).abs() < 1e-6);
        }
    }

    #[test]
    fn median_of_samples() {
        assert_eq!(Samples(vec![3.0, 1.0, 2.0]).median(), 2.0);
        assert_eq!(Samples(vec![4.0, 1.0, 2.0, 3.0]).median(), 2.5);
        assert!(Samples(vec![]).median().is_nan());
    }
}
