//! shader-stats' own small Vulkan setup: instance, device choice, a device with the features
//! wgpu 30 enables that change code generation (robustness, zero-initialised workgroup memory,
//! subgroup size control, f16/int64) plus `pipelineExecutableInfo`, and one compute pipeline per
//! entry point created with `CAPTURE_STATISTICS | CAPTURE_INTERNAL_REPRESENTATIONS`.

use std::ffi::{c_char, CStr};
use std::time::Instant;

use ash::khr;
use ash::vk;

use crate::compile::{DescriptorKind, EntryModule, Target};

/// The extension the statistics come from.
pub const EXEC_PROPS_EXTENSION: &CStr = khr::pipeline_executable_properties::NAME;

fn vkerr(what: &'static str) -> impl Fn(vk::Result) -> String {
    move |result| format!("{what} failed: {result}")
}

fn c_str_lossy(r: Result<&CStr, std::ffi::FromBytesUntilNulError>) -> String {
    r.map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|_| "?".to_string())
}

/// A fixed-size C string field (NUL-terminated within its array) as text.
fn fixed_str(chars: &[c_char]) -> String {
    let bytes: Vec<u8> = chars
        .iter()
        .take_while(|&&c| c != 0)
        .map(|&c| c as u8)
        .collect();
    String::from_utf8_lossy(&bytes).into_owned()
}

/// `major.minor.patch` of a Vulkan API version.
pub fn api_string(v: u32) -> String {
    format!(
        "{}.{}.{}",
        vk::api_version_major(v),
        vk::api_version_minor(v),
        vk::api_version_patch(v)
    )
}

/// What the tool prints about a physical device.
#[derive(Debug, Clone)]
pub struct DeviceSummary {
    /// Device name.
    pub name: String,
    /// Device type.
    pub kind: vk::PhysicalDeviceType,
    /// PCI vendor id.
    pub vendor_id: u32,
    /// PCI device id.
    pub device_id: u32,
    /// Vulkan API version the device reports.
    pub api_version: u32,
    /// Vendor-encoded driver version.
    pub driver_version: u32,
    /// `VkPhysicalDeviceDriverProperties::driverName` (Vulkan 1.2+), else empty.
    pub driver_name: String,
    /// `VkPhysicalDeviceDriverProperties::driverInfo` (Vulkan 1.2+), else empty.
    pub driver_info: String,
}

impl DeviceSummary {
    /// "discrete GPU", "CPU", …
    pub fn kind_name(&self) -> &'static str {
        match self.kind {
            vk::PhysicalDeviceType::DISCRETE_GPU => "discrete GPU",
            vk::PhysicalDeviceType::INTEGRATED_GPU => "integrated GPU",
            vk::PhysicalDeviceType::VIRTUAL_GPU => "virtual GPU",
            vk::PhysicalDeviceType::CPU => "CPU",
            _ => "other",
        }
    }

    /// The driver version as the vendor encodes it (NVIDIA: 10.8.8.6 bits).
    pub fn driver_version_string(&self) -> String {
        let v = self.driver_version;
        if self.vendor_id == 0x10de {
            format!(
                "{}.{}.{}.{}",
                v >> 22 & 0x3ff,
                v >> 14 & 0xff,
                v >> 6 & 0xff,
                v & 0x3f
            )
        } else {
            format!("{} (0x{v:08x})", api_string(v))
        }
    }
}

/// The first discrete or integrated GPU, else device 0 (e.g. lavapipe, a CPU device).
pub fn default_device(devices: &[DeviceSummary]) -> usize {
    devices
        .iter()
        .position(|d| {
            matches!(
                d.kind,
                vk::PhysicalDeviceType::DISCRETE_GPU | vk::PhysicalDeviceType::INTEGRATED_GPU
            )
        })
        .unwrap_or(0)
}

/// The loader and an instance.
pub struct Vk {
    _entry: ash::Entry,
    instance: ash::Instance,
    /// Instance API version requested (≤ 1.3, as wgpu 30).
    instance_version: u32,
    physical: Vec<vk::PhysicalDevice>,
    /// One per physical device.
    pub devices: Vec<DeviceSummary>,
}

impl Vk {
    /// Opens the loader, creates an instance (API 1.3 at most, as wgpu 30) and lists devices.
    pub fn load() -> Result<Vk, String> {
        // SAFETY: loading the system's Vulkan loader; trusted as every Vulkan application does.
        let entry = unsafe { ash::Entry::load() }
            .map_err(|e| format!("cannot load the Vulkan loader: {e}"))?;
        // SAFETY: entry is a loaded loader.
        let loader = unsafe { entry.try_enumerate_instance_version() }
            .map_err(vkerr("vkEnumerateInstanceVersion"))?
            .unwrap_or(vk::API_VERSION_1_0);
        if loader < vk::API_VERSION_1_1 {
            return Err(format!(
                "the Vulkan loader is {} (1.1 or newer is needed)",
                api_string(loader)
            ));
        }
        let instance_version = loader.min(vk::API_VERSION_1_3);
        let app = vk::ApplicationInfo::default()
            .application_name(c"kickstart-rt shader-stats")
            .api_version(instance_version);
        // SAFETY: valid create info without layers or extensions.
        let instance = unsafe {
            entry.create_instance(
                &vk::InstanceCreateInfo::default().application_info(&app),
                None,
            )
        }
        .map_err(vkerr("vkCreateInstance"))?;
        let mut vk = Vk {
            _entry: entry,
            instance,
            instance_version,
            physical: Vec::new(),
            devices: Vec::new(),
        };
        // SAFETY: a live instance.
        vk.physical = unsafe { vk.instance.enumerate_physical_devices() }
            .map_err(vkerr("vkEnumeratePhysicalDevices"))?;
        for &pd in &vk.physical {
            vk.devices.push(vk.summary(pd));
        }
        Ok(vk)
    }

    fn summary(&self, pd: vk::PhysicalDevice) -> DeviceSummary {
        // SAFETY: pd is one of this instance's devices.
        let props = unsafe { self.instance.get_physical_device_properties(pd) };
        let (mut driver_name, mut driver_info) = (String::new(), String::new());
        if props.api_version >= vk::API_VERSION_1_2 && self.instance_version >= vk::API_VERSION_1_2
        {
            let mut driver = vk::PhysicalDeviceDriverProperties::default();
            let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut driver);
            // SAFETY: a valid properties chain for a Vulkan 1.2 device.
            unsafe { self.instance.get_physical_device_properties2(pd, &mut p2) };
            driver_name = fixed_str(&driver.driver_name);
            driver_info = fixed_str(&driver.driver_info);
        }
        DeviceSummary {
            name: c_str_lossy(props.device_name_as_c_str()),
            kind: props.device_type,
            vendor_id: props.vendor_id,
            device_id: props.device_id,
            api_version: props.api_version,
            driver_version: props.driver_version,
            driver_name,
            driver_info,
        }
    }

    /// Creates the logical device on device `index`. Where the driver does not offer pipeline
    /// executable properties the device is still opened (pipelines can be compiled), without
    /// statistics, and [`Gpu::unsupported`] says why.
    pub fn open(&self, index: usize) -> Result<Gpu<'_>, String> {
        let pd = *self
            .physical
            .get(index)
            .ok_or_else(|| format!("no device {index}"))?;
        let summary = &self.devices[index];
        let offered = self.offered(pd, summary)?;
        let mut enabled = Enabled::of(&offered);
        let device = self.create_device(pd, summary, &offered, &mut enabled)?;
        let exec = enabled
            .exec
            .then(|| khr::pipeline_executable_properties::Device::new(&self.instance, &device));
        let (v13, e13) = (offered.v13, &enabled.v13);
        let target = Target {
            api_version: summary.api_version,
            robust_buffer_access2: enabled.robust_buffer_access2,
            robust_image_access: on(enabled.robustness2.robust_image_access2)
                || (v13 && on(e13.robust_image_access)),
            zero_initialize_workgroup_memory: v13
                && on(e13.shader_zero_initialize_workgroup_memory),
            vendor_id: summary.vendor_id,
        };
        Ok(Gpu {
            device,
            exec,
            unsupported: unsupported_reason(summary, offered.has_exec, enabled.exec),
            target,
            enabled: enabled.names(&offered),
            allow_varying_subgroup_size: offered.subgroup_feature(),
            _vk: std::marker::PhantomData,
        })
    }

    /// What device `pd` offers of the features wgpu 30 may enable.
    fn offered(&self, pd: vk::PhysicalDevice, summary: &DeviceSummary) -> Result<Offered, String> {
        let inst = &self.instance;
        // SAFETY: pd is one of this instance's devices.
        let exts = unsafe { inst.enumerate_device_extension_properties(pd) }
            .map_err(vkerr("vkEnumerateDeviceExtensionProperties"))?;
        let has = |name: &CStr| {
            exts.iter()
                .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == name))
        };
        let version = summary.api_version.min(self.instance_version);
        let mut o = Offered {
            v12: version >= vk::API_VERSION_1_2,
            v13: version >= vk::API_VERSION_1_3,
            has_exec: has(EXEC_PROPS_EXTENSION),
            has_robustness2: has(ash::ext::robustness2::NAME),
            core: vk::PhysicalDeviceFeatures::default(),
            v11_features: vk::PhysicalDeviceVulkan11Features::default(),
            v12_features: vk::PhysicalDeviceVulkan12Features::default(),
            v13_features: vk::PhysicalDeviceVulkan13Features::default(),
            robustness2: vk::PhysicalDeviceRobustness2FeaturesEXT::default(),
            exec: vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default(),
            subgroup: vk::PhysicalDeviceSubgroupProperties::default(),
        };
        {
            let mut f2 = vk::PhysicalDeviceFeatures2::default();
            if o.v12 {
                f2 = f2
                    .push_next(&mut o.v11_features)
                    .push_next(&mut o.v12_features);
            }
            if o.v13 {
                f2 = f2.push_next(&mut o.v13_features);
            }
            if o.has_robustness2 {
                f2 = f2.push_next(&mut o.robustness2);
            }
            if o.has_exec {
                f2 = f2.push_next(&mut o.exec);
            }
            // SAFETY: a valid chain of feature structs for this device's version and extensions.
            unsafe { inst.get_physical_device_features2(pd, &mut f2) };
            o.core = f2.features;
        }
        {
            let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut o.subgroup);
            // SAFETY: subgroup properties are core in Vulkan 1.1 (the instance is ≥ 1.1).
            unsafe { inst.get_physical_device_properties2(pd, &mut p2) };
        }
        o.clear_chain();
        Ok(o)
    }

    /// The logical device on `pd` with the `enabled` features and their extensions, and one
    /// compute queue.
    fn create_device(
        &self,
        pd: vk::PhysicalDevice,
        summary: &DeviceSummary,
        offered: &Offered,
        enabled: &mut Enabled,
    ) -> Result<ash::Device, String> {
        let inst = &self.instance;
        let mut ext_names: Vec<*const c_char> = Vec::new();
        if offered.has_robustness2 {
            ext_names.push(ash::ext::robustness2::NAME.as_ptr());
        }
        if enabled.exec {
            ext_names.push(EXEC_PROPS_EXTENSION.as_ptr());
        }
        // SAFETY: pd is one of this instance's devices.
        let families = unsafe { inst.get_physical_device_queue_family_properties(pd) };
        let family = families
            .iter()
            .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
            .ok_or_else(|| format!("{} has no compute queue", summary.name))?
            as u32;
        let priorities = [1.0f32];
        let queue_info = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(family)
            .queue_priorities(&priorities)];
        let mut info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_info)
            .enabled_extension_names(&ext_names)
            .enabled_features(&enabled.core);
        if offered.v12 {
            info = info.push_next(&mut enabled.v11).push_next(&mut enabled.v12);
        }
        if offered.v13 {
            info = info.push_next(&mut enabled.v13);
        }
        if offered.has_robustness2 {
            info = info.push_next(&mut enabled.robustness2);
        }
        if enabled.exec {
            info = info.push_next(&mut enabled.exec_features);
        }
        // SAFETY: features and extensions are ones the device reports; the chain matches them.
        unsafe { inst.create_device(pd, &info, None) }.map_err(vkerr("vkCreateDevice"))
    }
}

fn on(b: vk::Bool32) -> bool {
    b == vk::TRUE
}

/// Why a device gives no statistics (`None`: it does).
fn unsupported_reason(summary: &DeviceSummary, has_exec: bool, exec_ok: bool) -> Option<String> {
    if exec_ok {
        None
    } else if has_exec {
        Some(format!(
            "{} offers {} but not its feature pipelineExecutableInfo",
            summary.name,
            EXEC_PROPS_EXTENSION.to_string_lossy()
        ))
    } else {
        Some(format!(
            "{} does not support {} (driver {} {})",
            summary.name,
            EXEC_PROPS_EXTENSION.to_string_lossy(),
            summary.driver_name,
            summary.driver_info
        ))
    }
}

/// What a device supports of the features that matter here (read once; the structs' chain
/// pointers are cleared, only their fields are read).
struct Offered {
    v12: bool,
    v13: bool,
    has_exec: bool,
    has_robustness2: bool,
    core: vk::PhysicalDeviceFeatures,
    v11_features: vk::PhysicalDeviceVulkan11Features<'static>,
    v12_features: vk::PhysicalDeviceVulkan12Features<'static>,
    v13_features: vk::PhysicalDeviceVulkan13Features<'static>,
    robustness2: vk::PhysicalDeviceRobustness2FeaturesEXT<'static>,
    exec: vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR<'static>,
    subgroup: vk::PhysicalDeviceSubgroupProperties<'static>,
}

impl Offered {
    /// Drops the query's `p_next` links, which point at the other structs where they were.
    fn clear_chain(&mut self) {
        self.v11_features.p_next = std::ptr::null_mut();
        self.v12_features.p_next = std::ptr::null_mut();
        self.v13_features.p_next = std::ptr::null_mut();
        self.robustness2.p_next = std::ptr::null_mut();
        self.exec.p_next = std::ptr::null_mut();
        self.subgroup.p_next = std::ptr::null_mut();
    }

    /// Whether wgpu would enable its `SUBGROUP` feature (subgroup size control and the
    /// operations it needs in compute and fragment stages).
    fn subgroup_feature(&self) -> bool {
        self.v13
            && on(self.v13_features.subgroup_size_control)
            && self.subgroup.supported_operations.contains(
                vk::SubgroupFeatureFlags::BASIC
                    | vk::SubgroupFeatureFlags::VOTE
                    | vk::SubgroupFeatureFlags::ARITHMETIC
                    | vk::SubgroupFeatureFlags::BALLOT
                    | vk::SubgroupFeatureFlags::SHUFFLE
                    | vk::SubgroupFeatureFlags::SHUFFLE_RELATIVE
                    | vk::SubgroupFeatureFlags::QUAD,
            )
            && self
                .subgroup
                .supported_stages
                .contains(vk::ShaderStageFlags::COMPUTE | vk::ShaderStageFlags::FRAGMENT)
    }
}

/// The features the device is created with: what wgpu 30 enables of those offered (robustness,
/// zero-init, subgroup size control, and the SDK's optional SHADER_F16 / int64 atomics), plus
/// pipelineExecutableInfo.
struct Enabled {
    core: vk::PhysicalDeviceFeatures,
    v11: vk::PhysicalDeviceVulkan11Features<'static>,
    v12: vk::PhysicalDeviceVulkan12Features<'static>,
    v13: vk::PhysicalDeviceVulkan13Features<'static>,
    robustness2: vk::PhysicalDeviceRobustness2FeaturesEXT<'static>,
    exec_features: vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR<'static>,
    robust_buffer_access2: bool,
    /// pipelineExecutableInfo is enabled (the statistics).
    exec: bool,
}

impl Enabled {
    fn of(o: &Offered) -> Self {
        let (core, s11, s12, s13, srob) = (
            &o.core,
            &o.v11_features,
            &o.v12_features,
            &o.v13_features,
            &o.robustness2,
        );
        let robust_buffer_access2 = on(srob.robust_buffer_access2) && on(core.robust_buffer_access);
        let exec = o.has_exec && on(o.exec.pipeline_executable_info);
        Enabled {
            core: vk::PhysicalDeviceFeatures::default()
                .robust_buffer_access(on(core.robust_buffer_access))
                .shader_int64(on(core.shader_int64))
                .shader_int16(on(core.shader_int16)),
            v11: vk::PhysicalDeviceVulkan11Features::default()
                .storage_buffer16_bit_access(on(s11.storage_buffer16_bit_access))
                .uniform_and_storage_buffer16_bit_access(on(
                    s11.uniform_and_storage_buffer16_bit_access
                )),
            v12: vk::PhysicalDeviceVulkan12Features::default()
                .shader_float16(on(s12.shader_float16))
                .shader_int8(on(s12.shader_int8))
                .shader_buffer_int64_atomics(on(s12.shader_buffer_int64_atomics))
                .shader_shared_int64_atomics(on(s12.shader_shared_int64_atomics)),
            v13: vk::PhysicalDeviceVulkan13Features::default()
                .robust_image_access(on(s13.robust_image_access))
                .subgroup_size_control(on(s13.subgroup_size_control))
                .shader_zero_initialize_workgroup_memory(on(
                    s13.shader_zero_initialize_workgroup_memory
                )),
            robustness2: vk::PhysicalDeviceRobustness2FeaturesEXT::default()
                .robust_buffer_access2(robust_buffer_access2)
                .robust_image_access2(on(srob.robust_image_access2)),
            exec_features: vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default()
                .pipeline_executable_info(exec),
            robust_buffer_access2,
            exec,
        }
    }

    /// The code-generation-relevant features enabled, by their Vulkan names.
    fn names(&self, o: &Offered) -> Vec<String> {
        let (v12, v13) = (o.v12, o.v13);
        [
            (on(self.core.robust_buffer_access), "robustBufferAccess"),
            (self.robust_buffer_access2, "robustBufferAccess2"),
            (
                on(self.robustness2.robust_image_access2),
                "robustImageAccess2",
            ),
            (v13 && on(self.v13.robust_image_access), "robustImageAccess"),
            (
                v13 && on(self.v13.shader_zero_initialize_workgroup_memory),
                "shaderZeroInitializeWorkgroupMemory",
            ),
            (
                v13 && on(self.v13.subgroup_size_control),
                "subgroupSizeControl",
            ),
            (v12 && on(self.v12.shader_float16), "shaderFloat16"),
            (
                v12 && on(self.v12.shader_buffer_int64_atomics),
                "shaderBufferInt64Atomics",
            ),
            (self.exec, "pipelineExecutableInfo"),
        ]
        .into_iter()
        .filter(|&(b, _)| b)
        .map(|(_, name)| name.to_string())
        .collect()
    }
}

impl Drop for Vk {
    fn drop(&mut self) {
        // SAFETY: every device made from the instance is dropped first (`Gpu` borrows `Vk`).
        unsafe { self.instance.destroy_instance(None) };
    }
}

/// A logical device.
pub struct Gpu<'a> {
    device: ash::Device,
    exec: Option<khr::pipeline_executable_properties::Device>,
    /// Why there are no statistics on this device (`None`: there are).
    pub unsupported: Option<String>,
    /// What of the device changes the SPIR-V wgpu writes.
    pub target: Target,
    /// The code-generation-relevant features enabled, for the header.
    pub enabled: Vec<String>,
    /// wgpu sets `ALLOW_VARYING_SUBGROUP_SIZE` on its stages when the device has its
    /// `SUBGROUP` feature (as here).
    pub allow_varying_subgroup_size: bool,
    /// Ties the device's lifetime to the instance's.
    _vk: std::marker::PhantomData<&'a Vk>,
}

/// A statistic's value in the format the driver gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StatValue {
    /// `VK_PIPELINE_EXECUTABLE_STATISTIC_FORMAT_BOOL32_KHR`.
    Bool(bool),
    /// `…_INT64_KHR`.
    I64(i64),
    /// `…_UINT64_KHR`.
    U64(u64),
    /// `…_FLOAT64_KHR`.
    F64(f64),
    /// A format this tool does not know (raw bits).
    Unknown(i32, u64),
}

/// One statistic of an executable.
#[derive(Debug, Clone)]
pub struct Stat {
    /// Short name ("Register Count", …).
    pub name: String,
    /// The driver's description.
    pub description: String,
    /// Value.
    pub value: StatValue,
}

/// One internal representation of an executable (NIR, assembly, …).
#[derive(Debug, Clone)]
pub struct Repr {
    /// Name.
    pub name: String,
    /// The driver's description.
    pub description: String,
    /// Whether `data` is text.
    pub is_text: bool,
    /// Contents (text without its terminating NUL).
    pub data: Vec<u8>,
}

/// One executable of a pipeline (a compute pipeline usually has one).
#[derive(Debug, Clone)]
pub struct Executable {
    /// Name.
    pub name: String,
    /// The driver's description.
    pub description: String,
    /// Subgroup size.
    pub subgroup_size: u32,
    /// Stages it implements.
    pub stages: vk::ShaderStageFlags,
    /// Statistics.
    pub stats: Vec<Stat>,
    /// Internal representations.
    pub reprs: Vec<Repr>,
}

/// What the driver made of one entry point.
#[derive(Debug, Clone)]
pub struct Compiled {
    /// `vkCreateComputePipelines` wall time.
    pub millis: f64,
    /// Executables (empty without the extension).
    pub executables: Vec<Executable>,
}

fn descriptor_type(kind: DescriptorKind) -> vk::DescriptorType {
    match kind {
        DescriptorKind::UniformBuffer => vk::DescriptorType::UNIFORM_BUFFER,
        DescriptorKind::StorageBuffer { .. } => vk::DescriptorType::STORAGE_BUFFER,
        DescriptorKind::SampledImage => vk::DescriptorType::SAMPLED_IMAGE,
        DescriptorKind::StorageImage => vk::DescriptorType::STORAGE_IMAGE,
        DescriptorKind::Sampler => vk::DescriptorType::SAMPLER,
    }
}

/// Objects of one pipeline, destroyed on every path out of [`Gpu::compile`].
struct Objects<'d> {
    device: &'d ash::Device,
    module: vk::ShaderModule,
    set_layouts: Vec<vk::DescriptorSetLayout>,
    pipeline_layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

impl Drop for Objects<'_> {
    fn drop(&mut self) {
        // SAFETY: all made from `device`, none in use by the GPU (nothing is ever submitted);
        // null handles are ignored.
        unsafe {
            self.device.destroy_pipeline(self.pipeline, None);
            self.device
                .destroy_pipeline_layout(self.pipeline_layout, None);
            for &l in &self.set_layouts {
                self.device.destroy_descriptor_set_layout(l, None);
            }
            self.device.destroy_shader_module(self.module, None);
        }
    }
}

impl Gpu<'_> {
    /// Creates the compute pipeline of `entry` from `spirv` (capturing statistics and internal
    /// representations where the extension is enabled) and reads them back.
    pub fn compile(&self, entry: &EntryModule, spirv: &[u32]) -> Result<Compiled, String> {
        let d = &self.device;
        let mut objs = Objects {
            device: d,
            module: vk::ShaderModule::null(),
            set_layouts: Vec::new(),
            pipeline_layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
        };
        // SAFETY: valid SPIR-V words from naga.
        objs.module = unsafe {
            d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(spirv), None)
        }
        .map_err(vkerr("vkCreateShaderModule"))?;
        for set in 0..entry.layout.set_count() {
            let bindings: Vec<vk::DescriptorSetLayoutBinding> = entry
                .layout
                .bindings
                .iter()
                .filter(|b| b.group == set)
                .map(|b| {
                    vk::DescriptorSetLayoutBinding::default()
                        .binding(b.vk_binding)
                        .descriptor_type(descriptor_type(b.kind))
                        .descriptor_count(b.count)
                        .stage_flags(vk::ShaderStageFlags::COMPUTE)
                })
                .collect();
            // SAFETY: a valid create info.
            let l = unsafe {
                d.create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                    None,
                )
            }
            .map_err(vkerr("vkCreateDescriptorSetLayout"))?;
            objs.set_layouts.push(l);
        }
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .offset(0)
            .size(entry.layout.push_constant_size)];
        let n_ranges = usize::from(entry.layout.push_constant_size > 0);
        // SAFETY: a valid create info with live set layouts.
        objs.pipeline_layout = unsafe {
            d.create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default()
                    .set_layouts(&objs.set_layouts)
                    .push_constant_ranges(&ranges[..n_ranges]),
                None,
            )
        }
        .map_err(vkerr("vkCreatePipelineLayout"))?;
        let name = std::ffi::CString::new(entry.name.as_str())
            .map_err(|_| format!("entry point name `{}` contains NUL", entry.name))?;
        let mut stage_flags = vk::PipelineShaderStageCreateFlags::empty();
        if self.allow_varying_subgroup_size {
            stage_flags |= vk::PipelineShaderStageCreateFlags::ALLOW_VARYING_SUBGROUP_SIZE;
        }
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .flags(stage_flags)
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(objs.module)
            .name(&name);
        let mut flags = vk::PipelineCreateFlags::empty();
        if self.exec.is_some() {
            flags |= vk::PipelineCreateFlags::CAPTURE_STATISTICS_KHR
                | vk::PipelineCreateFlags::CAPTURE_INTERNAL_REPRESENTATIONS_KHR;
        }
        let info = [vk::ComputePipelineCreateInfo::default()
            .flags(flags)
            .stage(stage)
            .layout(objs.pipeline_layout)];
        let t0 = Instant::now();
        // SAFETY: a valid create info (module, layout and entry point live).
        let pipelines =
            unsafe { d.create_compute_pipelines(vk::PipelineCache::null(), &info, None) }
                .map_err(|(_, e)| format!("vkCreateComputePipelines failed: {e}"))?;
        let millis = t0.elapsed().as_secs_f64() * 1e3;
        objs.pipeline = pipelines.first().copied().unwrap_or_default();
        let executables = match &self.exec {
            Some(exec) => read_executables(exec, objs.pipeline)?,
            None => Vec::new(),
        };
        Ok(Compiled {
            millis,
            executables,
        })
    }
}

fn read_executables(
    exec: &khr::pipeline_executable_properties::Device,
    pipeline: vk::Pipeline,
) -> Result<Vec<Executable>, String> {
    // SAFETY: a pipeline created with CAPTURE_STATISTICS on a device with pipelineExecutableInfo.
    let props = unsafe {
        exec.get_pipeline_executable_properties(&vk::PipelineInfoKHR::default().pipeline(pipeline))
    }
    .map_err(vkerr("vkGetPipelineExecutablePropertiesKHR"))?;
    let mut out = Vec::with_capacity(props.len());
    for (index, p) in props.iter().enumerate() {
        let info = vk::PipelineExecutableInfoKHR::default()
            .pipeline(pipeline)
            .executable_index(index as u32);
        // SAFETY: as above; index < the executable count.
        let raw_stats = unsafe { exec.get_pipeline_executable_statistics(&info) }
            .map_err(vkerr("vkGetPipelineExecutableStatisticsKHR"))?;
        let stats = raw_stats
            .iter()
            .map(|s| {
                // SAFETY: the union member read is the one `format` names.
                let value = unsafe {
                    match s.format {
                        vk::PipelineExecutableStatisticFormatKHR::BOOL32 => {
                            StatValue::Bool(s.value.b32 != vk::FALSE)
                        }
                        vk::PipelineExecutableStatisticFormatKHR::INT64 => {
                            StatValue::I64(s.value.i64)
                        }
                        vk::PipelineExecutableStatisticFormatKHR::UINT64 => {
                            StatValue::U64(s.value.u64)
                        }
                        vk::PipelineExecutableStatisticFormatKHR::FLOAT64 => {
                            StatValue::F64(s.value.f64)
                        }
                        other => StatValue::Unknown(other.as_raw(), s.value.u64),
                    }
                };
                Stat {
                    name: fixed_str(&s.name),
                    description: fixed_str(&s.description),
                    value,
                }
            })
            .collect();
        out.push(Executable {
            name: fixed_str(&p.name),
            description: fixed_str(&p.description),
            subgroup_size: p.subgroup_size,
            stages: p.stages,
            stats,
            reprs: read_reprs(exec, &info)?,
        });
    }
    Ok(out)
}

/// The two-call read of internal representations: sizes first, then the data.
fn read_reprs(
    exec: &khr::pipeline_executable_properties::Device,
    info: &vk::PipelineExecutableInfoKHR<'_>,
) -> Result<Vec<Repr>, String> {
    // SAFETY: a pipeline created with CAPTURE_INTERNAL_REPRESENTATIONS; with null pData the
    // driver fills in each dataSize.
    let mut reprs = unsafe { exec.get_pipeline_executable_internal_representations(info) }
        .map_err(vkerr("vkGetPipelineExecutableInternalRepresentationsKHR"))?;
    if reprs.is_empty() {
        return Ok(Vec::new());
    }
    let mut buffers: Vec<Vec<u8>> = reprs.iter().map(|r| vec![0u8; r.data_size]).collect();
    for (r, b) in reprs.iter_mut().zip(buffers.iter_mut()) {
        r.p_data = b.as_mut_ptr().cast();
    }
    let mut count = reprs.len() as u32;
    // SAFETY: `count` structures, each with pData pointing at dataSize writable bytes that
    // outlive the call.
    let result = unsafe {
        (exec
            .fp()
            .get_pipeline_executable_internal_representations_khr)(
            exec.device(),
            info,
            &mut count,
            reprs.as_mut_ptr(),
        )
    };
    if result != vk::Result::SUCCESS && result != vk::Result::INCOMPLETE {
        return Err(format!(
            "vkGetPipelineExecutableInternalRepresentationsKHR (data) failed: {result}"
        ));
    }
    let mut out = Vec::new();
    for (r, mut data) in reprs.iter().zip(buffers).take(count as usize) {
        data.truncate(r.data_size);
        let is_text = r.is_text != vk::FALSE;
        if is_text {
            if let Some(end) = data.iter().position(|&b| b == 0) {
                data.truncate(end);
            }
        }
        out.push(Repr {
            name: fixed_str(&r.name),
            description: fixed_str(&r.description),
            is_text,
            data,
        });
    }
    Ok(out)
}

impl Drop for Gpu<'_> {
    fn drop(&mut self) {
        // SAFETY: every object made from the device is destroyed by `compile` before it returns.
        unsafe { self.device.destroy_device(None) };
    }
}
