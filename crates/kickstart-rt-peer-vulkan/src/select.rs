//! Which physical device the peer uses (pure logic, testable without Vulkan).

use crate::PeerError;

/// Device extensions the peer needs. Buffer device address is core in Vulkan 1.2 (its feature
/// is checked as [`DeviceCandidate::missing`] "bufferDeviceAddress").
pub const REQUIRED_EXTENSIONS: [&str; 3] = [
    "VK_KHR_acceleration_structure",
    "VK_KHR_ray_tracing_pipeline",
    "VK_KHR_deferred_host_operations",
];

/// Which GPU the comparison should run on: the bench passes its wgpu adapter's, so both tracers
/// are measured on the same GPU.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DeviceHint {
    /// PCI vendor id (0: any).
    pub vendor_id: u32,
    /// PCI device id (0: any).
    pub device_id: u32,
    /// Device name as the driver reports it (empty: any).
    pub name: String,
}

impl DeviceHint {
    /// Whether `c` is the hinted GPU: same vendor and device id where both are given, else the
    /// same name.
    pub fn matches(&self, c: &DeviceCandidate) -> bool {
        if self.vendor_id != 0 && self.device_id != 0 {
            return self.vendor_id == c.vendor_id && self.device_id == c.device_id;
        }
        !self.name.is_empty() && self.name == c.name
    }
}

/// What the peer learned about one physical device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceCandidate {
    /// Device name.
    pub name: String,
    /// PCI vendor id.
    pub vendor_id: u32,
    /// PCI device id.
    pub device_id: u32,
    /// Whether it is a discrete GPU (preferred when nothing is hinted).
    pub discrete: bool,
    /// What it lacks for the peer: extensions, features ("rayTracingPipeline", …), "Vulkan 1.2",
    /// "a compute queue with timestamps". Empty: usable.
    pub missing: Vec<String>,
}

/// Picks the device: among the usable ones, the hinted GPU; without a hint (or when no device
/// is the hinted one) a discrete GPU first, else the first usable. When the hinted GPU is there
/// but lacks ray tracing, the peer is unavailable rather than measured on another GPU: ratios
/// across two GPUs would mislead.
///
/// The error names every device and what it lacks, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) lacks
/// VK_KHR_acceleration_structure, VK_KHR_ray_tracing_pipeline`.
pub fn choose_device(
    candidates: &[DeviceCandidate],
    hint: Option<&DeviceHint>,
) -> Result<usize, PeerError> {
    let usable = |c: &DeviceCandidate| c.missing.is_empty();
    let describe = |cs: &mut dyn Iterator<Item = &DeviceCandidate>| -> String {
        cs.map(|c| format!("{} lacks {}", c.name, c.missing.join(", ")))
            .collect::<Vec<_>>()
            .join("; ")
    };
    if candidates.is_empty() {
        return Err(PeerError::Unavailable(
            "no Vulkan physical device found".to_string(),
        ));
    }
    if let Some(h) = hint {
        if candidates.iter().any(|c| h.matches(c)) {
            return candidates
                .iter()
                .position(|c| h.matches(c) && usable(c))
                .ok_or_else(|| {
                    PeerError::Unavailable(format!(
                        "the benchmarked GPU has no hardware ray tracing: {}",
                        describe(&mut candidates.iter().filter(|c| h.matches(c)))
                    ))
                });
        }
    }
    candidates
        .iter()
        .position(|c| usable(c) && c.discrete)
        .or_else(|| candidates.iter().position(usable))
        .ok_or_else(|| {
            PeerError::Unavailable(format!(
                "no Vulkan device with ray tracing: {}",
                describe(&mut candidates.iter())
            ))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cand(
        name: &str,
        vendor: u32,
        device: u32,
        discrete: bool,
        missing: &[&str],
    ) -> DeviceCandidate {
        DeviceCandidate {
            name: name.to_string(),
            vendor_id: vendor,
            device_id: device,
            discrete,
            missing: missing.iter().map(|s| s.to_string()).collect(),
        }
    }

    #[test]
    fn without_ray_tracing_the_error_names_device_and_extensions() {
        let lvp = cand(
            "llvmpipe (LLVM 15.0.6, 256 bits)",
            0x10005,
            0,
            false,
            &[
                "VK_KHR_acceleration_structure",
                "VK_KHR_ray_tracing_pipeline",
            ],
        );
        let e = choose_device(&[lvp], None).unwrap_err();
        let text = e.to_string();
        assert!(matches!(e, PeerError::Unavailable(_)));
        assert!(
            text.contains("llvmpipe (LLVM 15.0.6, 256 bits) lacks"),
            "{text}"
        );
        assert!(text.contains("VK_KHR_ray_tracing_pipeline"), "{text}");
        assert!(matches!(
            choose_device(&[], None),
            Err(PeerError::Unavailable(_))
        ));
    }

    #[test]
    fn prefers_the_hinted_gpu_then_a_discrete_one() {
        let cs = [
            cand("igpu", 0x8086, 1, false, &[]),
            cand("dgpu a", 0x10de, 0x2330, true, &[]),
            cand("dgpu b", 0x1002, 7, true, &[]),
        ];
        assert_eq!(choose_device(&cs, None).ok(), Some(1));
        let hint = DeviceHint {
            vendor_id: 0x1002,
            device_id: 7,
            name: String::new(),
        };
        assert_eq!(choose_device(&cs, Some(&hint)).ok(), Some(2));
        let by_name = DeviceHint {
            name: "igpu".to_string(),
            ..DeviceHint::default()
        };
        assert_eq!(choose_device(&cs, Some(&by_name)).ok(), Some(0));
        // A hint that matches nothing falls back to the usual choice.
        let none = DeviceHint {
            name: "elsewhere".to_string(),
            ..DeviceHint::default()
        };
        assert_eq!(choose_device(&cs, Some(&none)).ok(), Some(1));
    }

    #[test]
    fn hinted_gpu_without_ray_tracing_is_not_replaced_by_another() {
        let cs = [
            cand("software", 0x10005, 0, false, &[]),
            cand("old gpu", 0x10de, 5, true, &["VK_KHR_ray_tracing_pipeline"]),
        ];
        let hint = DeviceHint {
            vendor_id: 0x10de,
            device_id: 5,
            name: "old gpu".to_string(),
        };
        let e = choose_device(&cs, Some(&hint)).unwrap_err().to_string();
        assert!(
            e.contains("old gpu lacks VK_KHR_ray_tracing_pipeline"),
            "{e}"
        );
    }
}
