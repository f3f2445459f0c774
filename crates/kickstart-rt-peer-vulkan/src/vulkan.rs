//! The peer on Vulkan (ash): device, buffers, acceleration structures, the ray-tracing pipeline
//! and its shader binding table, and timestamp-timed submissions.

use std::ffi::{c_char, CStr};
use std::time::Instant;

use ash::khr;
use ash::vk;

use crate::select::{choose_device, DeviceCandidate, DeviceHint, REQUIRED_EXTENSIONS};
use crate::{BuildPreference, Hit, Instance, Mesh, PeerError, Query, Ray, Result, Samples, Timing};

const RAYGEN_SPV: &[u8] = include_bytes!("../shaders/raygen.rgen.spv");
const MISS_SPV: &[u8] = include_bytes!("../shaders/miss.rmiss.spv");
const CLOSEST_SPV: &[u8] = include_bytes!("../shaders/closest.rchit.spv");

/// How long one submission may take before the peer gives up (a hung GPU must not hang the
/// bench forever).
const FENCE_TIMEOUT_NS: u64 = 120_000_000_000;

/// Acceleration structures must start at multiples of 256 bytes within their buffer (spec).
const AS_OFFSET_ALIGN: u64 = 256;

fn vkerr(what: &'static str) -> impl Fn(vk::Result) -> PeerError {
    move |result| PeerError::Vulkan { what, result }
}

fn align_up(x: u64, a: u64) -> u64 {
    if a <= 1 {
        x
    } else {
        x.div_ceil(a) * a
    }
}

/// A buffer with its own memory. Null handles when empty (destroying them is a no-op).
#[derive(Default)]
struct Buffer {
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    size: u64,
    /// Device address (0 without `SHADER_DEVICE_ADDRESS` usage).
    address: u64,
}

/// One uploaded mesh's place in the shared vertex and index buffers.
#[derive(Debug, Clone, Copy)]
struct MeshRange {
    first_vertex: u64,
    vertices: u32,
    first_index: u64,
    triangles: u32,
}

/// A TLAS instance record (`VkAccelerationStructureInstanceKHR`, 64 bytes), as plain data.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct InstanceRecord {
    transform: [f32; 12],
    custom_index_and_mask: u32,
    sbt_offset_and_flags: u32,
    blas: u64,
}

/// Shader binding table regions (device addresses).
#[derive(Default, Clone, Copy)]
struct Sbt {
    raygen: vk::StridedDeviceAddressRegionKHR,
    miss: vk::StridedDeviceAddressRegionKHR,
    hit: vk::StridedDeviceAddressRegionKHR,
}

/// Device properties the peer uses.
#[derive(Default, Clone, Copy)]
struct Props {
    /// Nanoseconds per timestamp tick.
    timestamp_period: f64,
    timestamp_mask: u64,
    handle_size: u32,
    handle_alignment: u32,
    base_alignment: u32,
    scratch_alignment: u64,
    max_dispatch: u64,
    max_launch: [u64; 2],
    max_storage_range: u64,
}

/// The Vulkan hardware ray-tracing peer: one device, one scene (meshes → BLASes → TLAS), and a
/// ray-tracing pipeline that traces batches of [`Ray`]s into [`Hit`]s.
///
/// Every method waits for its GPU work (the peer is a measuring tool, not a renderer).
pub struct VulkanRtPeer {
    _entry: ash::Entry,
    instance: ash::Instance,
    device: ash::Device,
    accel: khr::acceleration_structure::Device,
    rt: khr::ray_tracing_pipeline::Device,
    queue: vk::Queue,
    memory: vk::PhysicalDeviceMemoryProperties,
    props: Props,
    name: String,
    driver: String,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    queries: vk::QueryPool,
    set_layout: vk::DescriptorSetLayout,
    pipeline_layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    descriptor_pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
    sbt_buffer: Buffer,
    sbt: Sbt,
    vertices: Buffer,
    indices: Buffer,
    meshes: Vec<MeshRange>,
    blas_buffer: Buffer,
    blas_scratch: Buffer,
    /// Per mesh; `None` for a mesh without triangles (it gets no BLAS and its instances are left
    /// out of the TLAS: there is nothing to hit).
    blases: Vec<Option<(vk::AccelerationStructureKHR, u64)>>,
    blas_bytes: u64,
    /// One `ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR` query per BLAS of the last fast-trace
    /// build; null otherwise. Destroyed with the BLASes.
    compacted_queries: vk::QueryPool,
    /// See [`VulkanRtPeer::blas_compacted_bytes`].
    blas_compacted_bytes: Option<u64>,
    tlas: vk::AccelerationStructureKHR,
    tlas_buffer: Buffer,
    tlas_scratch: Buffer,
    instance_buffer: Buffer,
}

/// What the peer needs of a device that it may lack, for the Unavailable message.
fn missing_on(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    props: &vk::PhysicalDeviceProperties,
) -> Result<(Vec<String>, Option<u32>)> {
    let mut missing = Vec::new();
    if props.api_version < vk::API_VERSION_1_2 {
        missing.push(format!(
            "Vulkan 1.2 (has {}.{})",
            vk::api_version_major(props.api_version),
            vk::api_version_minor(props.api_version)
        ));
    }
    // SAFETY: pd comes from enumerate_physical_devices of this instance.
    let exts = unsafe { instance.enumerate_device_extension_properties(pd) }
        .map_err(vkerr("vkEnumerateDeviceExtensionProperties"))?;
    let has = |name: &str| {
        exts.iter().any(|e| {
            e.extension_name_as_c_str()
                .is_ok_and(|n| n.to_bytes() == name.as_bytes())
        })
    };
    let mut all_extensions = true;
    for ext in REQUIRED_EXTENSIONS {
        if !has(ext) {
            missing.push(ext.to_string());
            all_extensions = false;
        }
    }
    if props.api_version >= vk::API_VERSION_1_2 {
        let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut fas = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default();
        let mut frt = vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default();
        {
            let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut f12);
            // Extension feature structs only where the extensions exist (valid usage).
            if all_extensions {
                f2 = f2.push_next(&mut fas).push_next(&mut frt);
            }
            // SAFETY: a valid chain of feature structs for this device.
            unsafe { instance.get_physical_device_features2(pd, &mut f2) };
        }
        if f12.buffer_device_address == vk::FALSE {
            missing.push("bufferDeviceAddress".to_string());
        }
        if all_extensions {
            if fas.acceleration_structure == vk::FALSE {
                missing.push("accelerationStructure".to_string());
            }
            if frt.ray_tracing_pipeline == vk::FALSE {
                missing.push("rayTracingPipeline".to_string());
            }
        }
    }
    // SAFETY: as above.
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    let usable = |f: &vk::QueueFamilyProperties| {
        f.queue_flags.contains(vk::QueueFlags::COMPUTE) && f.timestamp_valid_bits > 0
    };
    // A universal (graphics + compute) queue first: ray-tracing pipelines run on any compute
    // queue, but the universal one is what engines use.
    let family = families
        .iter()
        .position(|f| usable(f) && f.queue_flags.contains(vk::QueueFlags::GRAPHICS))
        .or_else(|| families.iter().position(usable))
        .map(|i| i as u32);
    if family.is_none() {
        missing.push("a compute queue with timestamps".to_string());
    }
    Ok((missing, family))
}

/// The build of one BLAS over geometry `g` (destination and scratch still to set).
fn blas_info<'a>(
    g: &'a [vk::AccelerationStructureGeometryKHR<'a>; 1],
    flags: vk::BuildAccelerationStructureFlagsKHR,
) -> vk::AccelerationStructureBuildGeometryInfoKHR<'a> {
    vk::AccelerationStructureBuildGeometryInfoKHR::default()
        .ty(vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL)
        .flags(flags)
        .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
        .geometries(g)
}

/// Where the BLASes of one build go: each one's offset and size in the storage buffer and its
/// offset in the scratch buffer, and both buffers' sizes.
#[derive(Default)]
struct BlasLayout {
    as_offsets: Vec<u64>,
    as_sizes: Vec<u64>,
    scratch_offsets: Vec<u64>,
    as_total: u64,
    scratch_total: u64,
}

/// The logical device on `pd` with one queue of `family`, the ray-tracing extensions and the
/// features they need.
fn create_device(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    family: u32,
) -> std::result::Result<ash::Device, vk::Result> {
    let priorities = [1.0f32];
    let queue_info = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(family)
        .queue_priorities(&priorities)];
    let ext_names: Vec<*const c_char> = [
        khr::acceleration_structure::NAME,
        khr::ray_tracing_pipeline::NAME,
        khr::deferred_host_operations::NAME,
    ]
    .iter()
    .map(|n| n.as_ptr())
    .collect();
    let mut f12 = vk::PhysicalDeviceVulkan12Features::default().buffer_device_address(true);
    let mut fas =
        vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default().acceleration_structure(true);
    let mut frt =
        vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default().ray_tracing_pipeline(true);
    let info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queue_info)
        .enabled_extension_names(&ext_names)
        .push_next(&mut f12)
        .push_next(&mut fas)
        .push_next(&mut frt);
    // SAFETY: the device was checked for these extensions and features.
    unsafe { instance.create_device(pd, &info, None) }
}

/// What the peer keeps of a device's properties.
struct DeviceInfo {
    name: String,
    /// Driver name and info.
    driver: String,
    memory: vk::PhysicalDeviceMemoryProperties,
    props: Props,
}

/// The properties of `pd` (with the ray-tracing extensions) and of its queue `family`.
fn device_info(instance: &ash::Instance, pd: vk::PhysicalDevice, family: u32) -> DeviceInfo {
    let mut rt_props = vk::PhysicalDeviceRayTracingPipelinePropertiesKHR::default();
    let mut as_props = vk::PhysicalDeviceAccelerationStructurePropertiesKHR::default();
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    let mut p2 = vk::PhysicalDeviceProperties2::default()
        .push_next(&mut rt_props)
        .push_next(&mut as_props)
        .push_next(&mut driver);
    // SAFETY: a valid chain; the extensions are supported.
    unsafe { instance.get_physical_device_properties2(pd, &mut p2) };
    let base = p2.properties;
    // SAFETY: as above.
    let memory = unsafe { instance.get_physical_device_memory_properties(pd) };
    // SAFETY: as above.
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    let bits = families
        .get(family as usize)
        .map_or(0, |f| f.timestamp_valid_bits);
    let limits = base.limits;
    let props = Props {
        timestamp_period: f64::from(limits.timestamp_period),
        timestamp_mask: if bits >= 64 {
            u64::MAX
        } else {
            (1u64 << bits) - 1
        },
        handle_size: rt_props.shader_group_handle_size,
        handle_alignment: rt_props.shader_group_handle_alignment.max(1),
        base_alignment: rt_props.shader_group_base_alignment.max(1),
        scratch_alignment: u64::from(
            as_props
                .min_acceleration_structure_scratch_offset_alignment
                .max(1),
        ),
        max_dispatch: u64::from(rt_props.max_ray_dispatch_invocation_count),
        max_launch: [
            u64::from(limits.max_compute_work_group_count[0])
                * u64::from(limits.max_compute_work_group_size[0]),
            u64::from(limits.max_compute_work_group_count[1])
                * u64::from(limits.max_compute_work_group_size[1]),
        ],
        max_storage_range: u64::from(limits.max_storage_buffer_range),
    };
    DeviceInfo {
        name: c_str_lossy(base.device_name_as_c_str()),
        driver: format!(
            "{} {}",
            c_str_lossy(driver.driver_name_as_c_str()),
            c_str_lossy(driver.driver_info_as_c_str())
        ),
        memory,
        props,
    }
}

fn c_str_lossy(r: std::result::Result<&CStr, std::ffi::FromBytesUntilNulError>) -> String {
    r.map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|_| "?".to_string())
}

impl VulkanRtPeer {
    /// Opens the Vulkan loader, picks a device with hardware ray tracing (the hinted GPU where
    /// it is one; see [`choose_device`]), and creates the pipeline.
    ///
    /// [`PeerError::Unavailable`] when there is no loader or no such device: the text names the
    /// devices and the missing extensions or features.
    pub fn new(hint: Option<&DeviceHint>) -> Result<VulkanRtPeer> {
        // SAFETY: loading the system's Vulkan loader library; its initialisation is trusted
        // as every Vulkan application trusts it.
        let entry = unsafe { ash::Entry::load() }
            .map_err(|e| PeerError::Unavailable(format!("cannot load the Vulkan loader: {e}")))?;
        // SAFETY: entry is a loaded loader.
        let loader_version = unsafe { entry.try_enumerate_instance_version() }
            .map_err(vkerr("vkEnumerateInstanceVersion"))?
            .unwrap_or(vk::API_VERSION_1_0);
        if loader_version < vk::API_VERSION_1_2 {
            return Err(PeerError::Unavailable(
                "the Vulkan loader is older than 1.2".to_string(),
            ));
        }
        let app = vk::ApplicationInfo::default()
            .application_name(c"kickstart-rt peer")
            .api_version(vk::API_VERSION_1_2);
        // SAFETY: valid create info without layers or extensions.
        let instance = unsafe {
            entry.create_instance(
                &vk::InstanceCreateInfo::default().application_info(&app),
                None,
            )
        }
        .map_err(vkerr("vkCreateInstance"))?;
        match Self::open_device(&instance, hint) {
            Ok((pd, family)) => Self::with_device(entry, instance, pd, family),
            Err(e) => {
                // SAFETY: nothing was created from the instance.
                unsafe { instance.destroy_instance(None) };
                Err(e)
            }
        }
    }

    /// Chooses the physical device and its queue family.
    fn open_device(
        instance: &ash::Instance,
        hint: Option<&DeviceHint>,
    ) -> Result<(vk::PhysicalDevice, u32)> {
        // SAFETY: a live instance.
        let pds = unsafe { instance.enumerate_physical_devices() }
            .map_err(vkerr("vkEnumeratePhysicalDevices"))?;
        let mut candidates = Vec::new();
        let mut families = Vec::new();
        for &pd in &pds {
            // SAFETY: pd is one of the instance's devices.
            let props = unsafe { instance.get_physical_device_properties(pd) };
            let (missing, family) = missing_on(instance, pd, &props)?;
            candidates.push(DeviceCandidate {
                name: c_str_lossy(props.device_name_as_c_str()),
                vendor_id: props.vendor_id,
                device_id: props.device_id,
                discrete: props.device_type == vk::PhysicalDeviceType::DISCRETE_GPU,
                missing,
            });
            families.push(family);
        }
        let k = choose_device(&candidates, hint)?;
        let family = families[k].ok_or(PeerError::Order("no queue family (unreachable)"))?;
        log::info!("vulkan-rt peer on {}", candidates[k].name);
        Ok((pds[k], family))
    }

    /// Creates the logical device, then everything else; on error, `Drop` releases what exists.
    fn with_device(
        entry: ash::Entry,
        instance: ash::Instance,
        pd: vk::PhysicalDevice,
        family: u32,
    ) -> Result<VulkanRtPeer> {
        let device = match create_device(&instance, pd, family) {
            Ok(d) => d,
            Err(e) => {
                // SAFETY: nothing else was created from the instance.
                unsafe { instance.destroy_instance(None) };
                return Err(vkerr("vkCreateDevice")(e));
            }
        };
        let DeviceInfo {
            name,
            driver,
            memory,
            props,
        } = device_info(&instance, pd, family);
        // SAFETY: family was used to create the device with one queue.
        let queue = unsafe { device.get_device_queue(family, 0) };
        let accel = khr::acceleration_structure::Device::new(&instance, &device);
        let rt = khr::ray_tracing_pipeline::Device::new(&instance, &device);
        let mut peer = VulkanRtPeer {
            _entry: entry,
            name,
            driver,
            instance,
            device,
            accel,
            rt,
            queue,
            memory,
            props,
            pool: vk::CommandPool::null(),
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            queries: vk::QueryPool::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            pipeline_layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            descriptor_pool: vk::DescriptorPool::null(),
            set: vk::DescriptorSet::null(),
            sbt_buffer: Buffer::default(),
            sbt: Sbt::default(),
            vertices: Buffer::default(),
            indices: Buffer::default(),
            meshes: Vec::new(),
            blas_buffer: Buffer::default(),
            blas_scratch: Buffer::default(),
            blases: Vec::new(),
            blas_bytes: 0,
            compacted_queries: vk::QueryPool::null(),
            blas_compacted_bytes: None,
            tlas: vk::AccelerationStructureKHR::null(),
            tlas_buffer: Buffer::default(),
            tlas_scratch: Buffer::default(),
            instance_buffer: Buffer::default(),
        };
        peer.init(family)?;
        Ok(peer)
    }

    /// Command buffer, fence, timestamp queries, pipeline and shader binding table.
    fn init(&mut self, family: u32) -> Result<()> {
        let d = &self.device;
        // SAFETY (this block): plain object creation on a live device; every handle is stored in
        // `self` at once, so `Drop` releases it on a later error.
        unsafe {
            self.pool = d
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default()
                        .queue_family_index(family)
                        .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                    None,
                )
                .map_err(vkerr("vkCreateCommandPool"))?;
            self.cmd = d
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(self.pool)
                        .level(vk::CommandBufferLevel::PRIMARY)
                        .command_buffer_count(1),
                )
                .map_err(vkerr("vkAllocateCommandBuffers"))?
                .first()
                .copied()
                .ok_or(PeerError::Order("no command buffer allocated"))?;
            self.fence = d
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .map_err(vkerr("vkCreateFence"))?;
            self.queries = d
                .create_query_pool(
                    &vk::QueryPoolCreateInfo::default()
                        .query_type(vk::QueryType::TIMESTAMP)
                        .query_count(2),
                    None,
                )
                .map_err(vkerr("vkCreateQueryPool"))?;
            let rgen = vk::ShaderStageFlags::RAYGEN_KHR;
            let bindings = [
                vk::DescriptorSetLayoutBinding::default()
                    .binding(0)
                    .descriptor_type(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
                    .descriptor_count(1)
                    .stage_flags(rgen),
                vk::DescriptorSetLayoutBinding::default()
                    .binding(1)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(rgen),
                vk::DescriptorSetLayoutBinding::default()
                    .binding(2)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(rgen),
            ];
            self.set_layout = d
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                    None,
                )
                .map_err(vkerr("vkCreateDescriptorSetLayout"))?;
            let layouts = [self.set_layout];
            let push = [vk::PushConstantRange::default()
                .stage_flags(rgen)
                .offset(0)
                .size(16)];
            self.pipeline_layout = d
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default()
                        .set_layouts(&layouts)
                        .push_constant_ranges(&push),
                    None,
                )
                .map_err(vkerr("vkCreatePipelineLayout"))?;
            let sizes = [
                vk::DescriptorPoolSize::default()
                    .ty(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
                    .descriptor_count(1),
                vk::DescriptorPoolSize::default()
                    .ty(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(2),
            ];
            self.descriptor_pool = d
                .create_descriptor_pool(
                    &vk::DescriptorPoolCreateInfo::default()
                        .max_sets(1)
                        .pool_sizes(&sizes),
                    None,
                )
                .map_err(vkerr("vkCreateDescriptorPool"))?;
            self.set = d
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default()
                        .descriptor_pool(self.descriptor_pool)
                        .set_layouts(&layouts),
                )
                .map_err(vkerr("vkAllocateDescriptorSets"))?
                .first()
                .copied()
                .ok_or(PeerError::Order("no descriptor set allocated"))?;
        }
        self.create_pipeline()?;
        self.create_sbt()
    }

    fn shader_module(&self, spv: &[u8]) -> Result<vk::ShaderModule> {
        let words = ash::util::read_spv(&mut std::io::Cursor::new(spv))
            .map_err(|e| PeerError::InvalidInput(format!("embedded SPIR-V: {e}")))?;
        // SAFETY: valid SPIR-V compiled by shaders/compile.sh.
        unsafe {
            self.device
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
        }
        .map_err(vkerr("vkCreateShaderModule"))
    }

    fn create_pipeline(&mut self) -> Result<()> {
        let mut modules = Vec::new();
        let mut result = Ok(());
        for spv in [RAYGEN_SPV, MISS_SPV, CLOSEST_SPV] {
            match self.shader_module(spv) {
                Ok(m) => modules.push(m),
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        if result.is_ok() {
            let main = c"main";
            let stages = [
                (vk::ShaderStageFlags::RAYGEN_KHR, modules[0]),
                (vk::ShaderStageFlags::MISS_KHR, modules[1]),
                (vk::ShaderStageFlags::CLOSEST_HIT_KHR, modules[2]),
            ]
            .map(|(stage, module)| {
                vk::PipelineShaderStageCreateInfo::default()
                    .stage(stage)
                    .module(module)
                    .name(main)
            });
            let general = |i: u32| {
                vk::RayTracingShaderGroupCreateInfoKHR::default()
                    .ty(vk::RayTracingShaderGroupTypeKHR::GENERAL)
                    .general_shader(i)
                    .closest_hit_shader(vk::SHADER_UNUSED_KHR)
                    .any_hit_shader(vk::SHADER_UNUSED_KHR)
                    .intersection_shader(vk::SHADER_UNUSED_KHR)
            };
            let groups = [
                general(0),
                general(1),
                vk::RayTracingShaderGroupCreateInfoKHR::default()
                    .ty(vk::RayTracingShaderGroupTypeKHR::TRIANGLES_HIT_GROUP)
                    .general_shader(vk::SHADER_UNUSED_KHR)
                    .closest_hit_shader(2)
                    .any_hit_shader(vk::SHADER_UNUSED_KHR)
                    .intersection_shader(vk::SHADER_UNUSED_KHR),
            ];
            let info = vk::RayTracingPipelineCreateInfoKHR::default()
                .stages(&stages)
                .groups(&groups)
                .max_pipeline_ray_recursion_depth(1)
                .layout(self.pipeline_layout);
            // SAFETY: valid create info; the modules outlive the call.
            result = match unsafe {
                self.rt.create_ray_tracing_pipelines(
                    vk::DeferredOperationKHR::null(),
                    vk::PipelineCache::null(),
                    &[info],
                    None,
                )
            } {
                Ok(p) => p
                    .first()
                    .copied()
                    .map(|p| self.pipeline = p)
                    .ok_or(PeerError::Order("no pipeline created")),
                Err((_, e)) => Err(vkerr("vkCreateRayTracingPipelinesKHR")(e)),
            };
        }
        for m in modules {
            // SAFETY: the pipeline no longer needs its modules once created.
            unsafe { self.device.destroy_shader_module(m, None) };
        }
        result
    }

    /// The shader binding table: one record per region, each region at a multiple of
    /// `shaderGroupBaseAlignment`, record strides a multiple of `shaderGroupHandleAlignment`.
    fn create_sbt(&mut self) -> Result<()> {
        let p = self.props;
        let handle = u64::from(p.handle_size);
        let stride = align_up(handle, u64::from(p.handle_alignment));
        let region = align_up(stride, u64::from(p.base_alignment));
        let data_size = (3 * p.handle_size) as usize;
        // SAFETY: the pipeline has 3 groups.
        let handles = unsafe {
            self.rt
                .get_ray_tracing_shader_group_handles(self.pipeline, 0, 3, data_size)
        }
        .map_err(vkerr("vkGetRayTracingShaderGroupHandlesKHR"))?;
        // The buffer's address is only guaranteed to be aligned to its memory requirements:
        // room for aligning the table's start up to the base alignment.
        let pad = u64::from(p.base_alignment);
        let mut table = vec![0u8; (3 * region + pad) as usize];
        let probe = self.create_buffer(
            table.len() as u64,
            vk::BufferUsageFlags::SHADER_BINDING_TABLE_KHR
                | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS
                | vk::BufferUsageFlags::TRANSFER_DST,
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
            "shader binding table",
        )?;
        self.sbt_buffer = probe;
        let start = align_up(self.sbt_buffer.address, pad) - self.sbt_buffer.address;
        for g in 0..3u64 {
            let src = &handles[(g * handle) as usize..((g + 1) * handle) as usize];
            let at = (start + g * region) as usize;
            table[at..at + src.len()].copy_from_slice(src);
        }
        self.write_device_buffer(self.sbt_buffer.buffer, &table)?;
        let base = self.sbt_buffer.address + start;
        let r = |g: u64| {
            vk::StridedDeviceAddressRegionKHR::default()
                .device_address(base + g * region)
                .stride(stride)
                .size(stride)
        };
        self.sbt = Sbt {
            raygen: r(0),
            miss: r(1),
            hit: r(2),
        };
        Ok(())
    }

    /// The device's name.
    pub fn device_name(&self) -> &str {
        &self.name
    }

    /// The driver's name and version.
    pub fn driver(&self) -> &str {
        &self.driver
    }

    /// Bytes of the BLASes built last (acceleration structure storage, without scratch; with the
    /// padding that starts each at a multiple of 256 bytes in the one buffer).
    pub fn blas_bytes(&self) -> u64 {
        self.blas_bytes
    }

    /// Bytes the BLASes built last would take once compacted, as the driver reports them
    /// (`VK_QUERY_TYPE_ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR`, summed over the BLASes): what a
    /// `vkCmdCopyAccelerationStructureKHR` in `COMPACT` mode would keep, to set beside
    /// [`Self::blas_bytes`]. Only the size is queried: the peer traces the uncompacted BLASes.
    /// The plain sum: unlike [`Self::blas_bytes`], no padding to the 256-byte offsets at which
    /// BLASes sit in one buffer (lavapipe reports each BLAS's full size as its compacted size,
    /// so there the two differ by that padding alone).
    ///
    /// `None` before any build, after a [`BuildPreference::FastBuild`] build (built without
    /// `ALLOW_COMPACTION`, as dynamic geometry is: it is rebuilt, not compacted) and after a
    /// build that failed.
    pub fn blas_compacted_bytes(&self) -> Option<u64> {
        self.blas_compacted_bytes
    }

    fn memory_type(&self, bits: u32, want: vk::MemoryPropertyFlags) -> Option<u32> {
        (0..self.memory.memory_type_count).find(|&i| {
            bits & (1 << i) != 0
                && self.memory.memory_types[i as usize]
                    .property_flags
                    .contains(want)
        })
    }

    fn create_buffer(
        &self,
        size: u64,
        usage: vk::BufferUsageFlags,
        props: vk::MemoryPropertyFlags,
        what: &'static str,
    ) -> Result<Buffer> {
        let d = &self.device;
        let mut b = Buffer {
            size: size.max(16),
            ..Buffer::default()
        };
        // SAFETY (this block): object creation on a live device; on error what was made is
        // destroyed before returning.
        unsafe {
            b.buffer = d
                .create_buffer(
                    &vk::BufferCreateInfo::default()
                        .size(b.size)
                        .usage(usage)
                        .sharing_mode(vk::SharingMode::EXCLUSIVE),
                    None,
                )
                .map_err(vkerr("vkCreateBuffer"))?;
            let req = d.get_buffer_memory_requirements(b.buffer);
            let Some(ty) = self.memory_type(req.memory_type_bits, props) else {
                d.destroy_buffer(b.buffer, None);
                return Err(PeerError::NoMemoryType(what));
            };
            let mut flags = vk::MemoryAllocateFlagsInfo::default()
                .flags(vk::MemoryAllocateFlags::DEVICE_ADDRESS);
            let mut info = vk::MemoryAllocateInfo::default()
                .allocation_size(req.size)
                .memory_type_index(ty);
            let addressed = usage.contains(vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS);
            if addressed {
                info = info.push_next(&mut flags);
            }
            b.memory = match d.allocate_memory(&info, None) {
                Ok(m) => m,
                Err(e) => {
                    d.destroy_buffer(b.buffer, None);
                    return Err(vkerr("vkAllocateMemory")(e));
                }
            };
            if let Err(e) = d.bind_buffer_memory(b.buffer, b.memory, 0) {
                self.destroy_buffer(&mut b);
                return Err(vkerr("vkBindBufferMemory")(e));
            }
            if addressed {
                b.address = d.get_buffer_device_address(
                    &vk::BufferDeviceAddressInfo::default().buffer(b.buffer),
                );
            }
        }
        Ok(b)
    }

    fn destroy_buffer(&self, b: &mut Buffer) {
        // SAFETY: the peer waits for all its GPU work before returning from any call, so no
        // submitted work uses the buffer; null handles are ignored.
        unsafe {
            self.device.destroy_buffer(b.buffer, None);
            self.device.free_memory(b.memory, None);
        }
        *b = Buffer::default();
    }

    /// Copies `bytes` into the device-local `dst` through a host-visible staging buffer.
    fn write_device_buffer(&self, dst: vk::Buffer, bytes: &[u8]) -> Result<()> {
        let mut staging = self.create_buffer(
            bytes.len() as u64,
            vk::BufferUsageFlags::TRANSFER_SRC,
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
            "staging",
        )?;
        let result = self.write_host(&staging, bytes).and_then(|()| {
            self.submit(|d, cmd| {
                let region = vk::BufferCopy::default().size(bytes.len() as u64);
                // SAFETY: both buffers are at least bytes.len() long.
                unsafe { d.cmd_copy_buffer(cmd, staging.buffer, dst, &[region]) };
            })
        });
        self.destroy_buffer(&mut staging);
        result
    }

    fn write_host(&self, b: &Buffer, bytes: &[u8]) -> Result<()> {
        if bytes.is_empty() {
            return Ok(());
        }
        // SAFETY: host-visible, coherent memory of at least bytes.len() bytes, not in use by the
        // GPU; unmapped before returning.
        unsafe {
            let p = self
                .device
                .map_memory(b.memory, 0, b.size, vk::MemoryMapFlags::empty())
                .map_err(vkerr("vkMapMemory"))?;
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), p.cast::<u8>(), bytes.len());
            self.device.unmap_memory(b.memory);
        }
        Ok(())
    }

    fn read_host(&self, b: &Buffer, len: usize) -> Result<Vec<u8>> {
        let mut out = vec![0u8; len];
        if len == 0 {
            return Ok(out);
        }
        // SAFETY: as write_host; the GPU finished writing (fence waited).
        unsafe {
            let p = self
                .device
                .map_memory(b.memory, 0, b.size, vk::MemoryMapFlags::empty())
                .map_err(vkerr("vkMapMemory"))?;
            std::ptr::copy_nonoverlapping(p.cast::<u8>(), out.as_mut_ptr(), len);
            self.device.unmap_memory(b.memory);
        }
        Ok(out)
    }

    /// A device-local buffer holding `bytes`.
    fn upload(
        &self,
        bytes: &[u8],
        usage: vk::BufferUsageFlags,
        what: &'static str,
    ) -> Result<Buffer> {
        let mut b = self.create_buffer(
            bytes.len() as u64,
            usage | vk::BufferUsageFlags::TRANSFER_DST,
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
            what,
        )?;
        if let Err(e) = self.write_device_buffer(b.buffer, bytes) {
            self.destroy_buffer(&mut b);
            return Err(e);
        }
        Ok(b)
    }

    /// Records `record` into the command buffer, submits it and waits.
    fn submit(&self, record: impl FnOnce(&ash::Device, vk::CommandBuffer)) -> Result<()> {
        let d = &self.device;
        let cmd = self.cmd;
        // SAFETY: the one command buffer is never in flight here (every submission is waited
        // for before returning), so it can be reset and re-recorded.
        unsafe {
            d.reset_command_buffer(cmd, vk::CommandBufferResetFlags::empty())
                .map_err(vkerr("vkResetCommandBuffer"))?;
            d.begin_command_buffer(
                cmd,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )
            .map_err(vkerr("vkBeginCommandBuffer"))?;
            // Earlier submissions' writes (uploads, builds) become visible to everything here:
            // a pipeline barrier's first scope includes all earlier commands on the queue.
            let barrier = vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                .dst_access_mask(vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE);
            d.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[barrier],
                &[],
                &[],
            );
            record(d, cmd);
            d.end_command_buffer(cmd)
                .map_err(vkerr("vkEndCommandBuffer"))?;
            d.reset_fences(&[self.fence])
                .map_err(vkerr("vkResetFences"))?;
            let cmds = [cmd];
            d.queue_submit(
                self.queue,
                &[vk::SubmitInfo::default().command_buffers(&cmds)],
                self.fence,
            )
            .map_err(vkerr("vkQueueSubmit"))?;
            d.wait_for_fences(&[self.fence], true, FENCE_TIMEOUT_NS)
                .map_err(vkerr("vkWaitForFences"))?;
        }
        Ok(())
    }

    /// Like [`Self::submit`], with timestamps around `work`; `after` is recorded after the
    /// second timestamp (untimed). Returns the GPU time of `work` in milliseconds.
    fn timed(
        &self,
        work: impl FnOnce(&ash::Device, vk::CommandBuffer),
        after: impl FnOnce(&ash::Device, vk::CommandBuffer),
    ) -> Result<f64> {
        let q = self.queries;
        self.submit(|d, cmd| {
            // SAFETY: recording into the command buffer `submit` began.
            unsafe {
                d.cmd_reset_query_pool(cmd, q, 0, 2);
                d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::TOP_OF_PIPE, q, 0);
            }
            work(d, cmd);
            // SAFETY: as above. BOTTOM_OF_PIPE: written once all of `work` has completed.
            unsafe { d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, q, 1) };
            after(d, cmd);
        })?;
        let mut ticks = [0u64; 2];
        // SAFETY: both queries were written by the waited submission.
        unsafe {
            self.device.get_query_pool_results(
                q,
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .map_err(vkerr("vkGetQueryPoolResults"))?;
        let delta = ticks[1].wrapping_sub(ticks[0]) & self.props.timestamp_mask;
        Ok(delta as f64 * self.props.timestamp_period / 1e6)
    }

    /// Runs `one` untimed for at least `timing.warm_up` (at least once), then
    /// `timing.iterations` times; `one(last)` is told which run is the last.
    fn repeat(&self, timing: Timing, mut one: impl FnMut(bool) -> Result<f64>) -> Result<Samples> {
        let start = Instant::now();
        one(false)?;
        while start.elapsed() < timing.warm_up {
            one(false)?;
        }
        let n = timing.iterations.max(1);
        (0..n)
            .map(|i| one(i + 1 == n))
            .collect::<Result<Vec<f64>>>()
            .map(Samples)
    }

    fn destroy_tlas(&mut self) {
        // SAFETY: no GPU work is in flight (every call waits); null handles are ignored.
        unsafe { self.accel.destroy_acceleration_structure(self.tlas, None) };
        self.tlas = vk::AccelerationStructureKHR::null();
        let mut b = std::mem::take(&mut self.tlas_buffer);
        self.destroy_buffer(&mut b);
        let mut b = std::mem::take(&mut self.tlas_scratch);
        self.destroy_buffer(&mut b);
        let mut b = std::mem::take(&mut self.instance_buffer);
        self.destroy_buffer(&mut b);
    }

    fn destroy_blases(&mut self) {
        self.destroy_tlas();
        for (blas, _) in std::mem::take(&mut self.blases).into_iter().flatten() {
            // SAFETY: as destroy_tlas.
            unsafe { self.accel.destroy_acceleration_structure(blas, None) };
        }
        let mut b = std::mem::take(&mut self.blas_buffer);
        self.destroy_buffer(&mut b);
        let mut b = std::mem::take(&mut self.blas_scratch);
        self.destroy_buffer(&mut b);
        self.blas_bytes = 0;
        // SAFETY: as destroy_tlas.
        unsafe { self.device.destroy_query_pool(self.compacted_queries, None) };
        self.compacted_queries = vk::QueryPool::null();
        self.blas_compacted_bytes = None;
    }

    /// Uploads the scene's meshes (replacing any earlier scene, its BLASes and TLAS). Indices
    /// are checked against each mesh's positions: an out-of-range index is an error, not a GPU
    /// fault.
    pub fn upload_meshes(&mut self, meshes: &[Mesh<'_>]) -> Result<()> {
        self.destroy_blases();
        let mut v = std::mem::take(&mut self.vertices);
        self.destroy_buffer(&mut v);
        let mut i = std::mem::take(&mut self.indices);
        self.destroy_buffer(&mut i);
        self.meshes.clear();
        let mut positions: Vec<[f32; 3]> = Vec::new();
        let mut indices: Vec<u32> = Vec::new();
        let mut ranges = Vec::with_capacity(meshes.len());
        for (k, m) in meshes.iter().enumerate() {
            if m.indices.len() % 3 != 0 {
                return Err(PeerError::InvalidInput(format!(
                    "mesh {k}: {} indices, not a multiple of 3",
                    m.indices.len()
                )));
            }
            if let Some(bad) = m.indices.iter().find(|&&i| i as usize >= m.positions.len()) {
                return Err(PeerError::InvalidInput(format!(
                    "mesh {k}: index {bad} beyond its {} positions",
                    m.positions.len()
                )));
            }
            let vertices = u32::try_from(m.positions.len()).map_err(|_| {
                PeerError::InvalidInput(format!("mesh {k}: more than 2^32 vertices"))
            })?;
            ranges.push(MeshRange {
                first_vertex: positions.len() as u64,
                vertices,
                first_index: indices.len() as u64,
                triangles: (m.indices.len() / 3) as u32,
            });
            positions.extend_from_slice(m.positions);
            indices.extend_from_slice(m.indices);
        }
        let usage = vk::BufferUsageFlags::ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_KHR
            | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS
            | vk::BufferUsageFlags::STORAGE_BUFFER;
        self.vertices = self.upload(bytemuck::cast_slice(&positions), usage, "vertices")?;
        self.indices = self.upload(bytemuck::cast_slice(&indices), usage, "indices")?;
        self.meshes = ranges;
        Ok(())
    }

    /// Builds one BLAS per uploaded mesh, all in one `vkCmdBuildAccelerationStructuresKHR`
    /// (each with its own scratch region), `timing.iterations` times after the warm-up (each
    /// rebuild writes the same acceleration structures). Returns the GPU times of the builds.
    /// Replaces any earlier BLASes (and drops the TLAS, which referenced them).
    ///
    /// [`BuildPreference::FastTrace`] builds also allow compaction and query the compacted size
    /// after the last timed build, outside its timestamps ([`Self::blas_compacted_bytes`]).
    pub fn build_blases(&mut self, preference: BuildPreference, timing: Timing) -> Result<Samples> {
        if self.meshes.is_empty() {
            return Err(PeerError::Order(
                "upload_meshes first (or the scene has no mesh)",
            ));
        }
        self.destroy_blases();
        // ALLOW_COMPACTION with fast trace only: a static scene's BLASes are what engines
        // compact, and the flag may cost build time or size, which the fast-build figures should
        // not carry.
        let flags = match preference {
            BuildPreference::FastTrace => {
                vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE
                    | vk::BuildAccelerationStructureFlagsKHR::ALLOW_COMPACTION
            }
            BuildPreference::FastBuild => vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_BUILD,
        };
        let compact = preference == BuildPreference::FastTrace;
        let built: Vec<MeshRange> = self
            .meshes
            .iter()
            .copied()
            .filter(|m| m.triangles > 0)
            .collect();
        let geometries = self.blas_geometries(&built);
        let layout = self.blas_layout(&built, &geometries, flags);
        self.create_blas_buffers(&layout)?;
        let handles = self.create_blas_handles(&layout)?;
        if compact {
            if let Err(e) = self.create_compacted_queries(handles.len()) {
                self.store_blases(handles);
                return Err(e);
            }
        }
        let queries = self.compacted_queries;
        let scratch_base = align_up(self.blas_scratch.address, self.props.scratch_alignment);
        let infos: Vec<vk::AccelerationStructureBuildGeometryInfoKHR<'_>> = geometries
            .iter()
            .zip(&handles)
            .zip(&layout.scratch_offsets)
            .map(|((g, &dst), &s)| {
                blas_info(g, flags)
                    .dst_acceleration_structure(dst)
                    .scratch_data(vk::DeviceOrHostAddressKHR {
                        device_address: scratch_base + s,
                    })
            })
            .collect();
        let ranges: Vec<[vk::AccelerationStructureBuildRangeInfoKHR; 1]> =
            built
                .iter()
                .map(|m| {
                    [vk::AccelerationStructureBuildRangeInfoKHR::default()
                        .primitive_count(m.triangles)]
                })
                .collect();
        let range_refs: Vec<&[vk::AccelerationStructureBuildRangeInfoKHR]> =
            ranges.iter().map(|r| r.as_slice()).collect();
        let accel = &self.accel;
        let samples = self.repeat(timing, |last| {
            self.timed(
                |_, cmd| {
                    // SAFETY: inputs, destinations and disjoint scratch regions are live.
                    unsafe { accel.cmd_build_acceleration_structures(cmd, &infos, &range_refs) }
                },
                // After the second timestamp: the size query is not part of the build's time.
                |d, cmd| {
                    if last && queries != vk::QueryPool::null() {
                        self.record_compacted_sizes(d, cmd, &handles, queries);
                    }
                },
            )
        });
        let compacted = match &samples {
            Ok(_) if compact => Some(self.read_compacted_sizes(handles.len())),
            _ => None,
        };
        // Store the handles whatever the builds did, so they are destroyed later.
        self.store_blases(handles);
        self.blas_compacted_bytes = compacted.transpose()?;
        samples
    }

    /// The query pool of one compacted size per BLAS (`count` of them; none for 0, as a pool
    /// must hold at least one query), in `self.compacted_queries`.
    fn create_compacted_queries(&mut self, count: usize) -> Result<()> {
        if count == 0 {
            return Ok(());
        }
        let count = u32::try_from(count)
            .map_err(|_| PeerError::InvalidInput(format!("{count} BLASes: too many to query")))?;
        // SAFETY: plain object creation on a live device; stored in `self` at once, so
        // `destroy_blases` (and with it `Drop`) releases it.
        self.compacted_queries = unsafe {
            self.device.create_query_pool(
                &vk::QueryPoolCreateInfo::default()
                    .query_type(vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR)
                    .query_count(count),
                None,
            )
        }
        .map_err(vkerr("vkCreateQueryPool (compacted sizes)"))?;
        Ok(())
    }

    /// Records, after the build in `cmd`, the writing of each of `blases`' compacted size into
    /// query i of `queries` (reset first: a query must be reset before each use).
    fn record_compacted_sizes(
        &self,
        d: &ash::Device,
        cmd: vk::CommandBuffer,
        blases: &[vk::AccelerationStructureKHR],
        queries: vk::QueryPool,
    ) {
        // The build writes the structures in the build stage; the size query reads them there.
        let barrier = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::ACCELERATION_STRUCTURE_WRITE_KHR)
            .dst_access_mask(vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR);
        let stage = vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR;
        // SAFETY: recording; the pool holds one query per BLAS, and the BLASes were built with
        // ALLOW_COMPACTION by the build recorded before this.
        unsafe {
            d.cmd_reset_query_pool(cmd, queries, 0, blases.len() as u32);
            d.cmd_pipeline_barrier(
                cmd,
                stage,
                stage,
                vk::DependencyFlags::empty(),
                &[barrier],
                &[],
                &[],
            );
            self.accel.cmd_write_acceleration_structures_properties(
                cmd,
                blases,
                vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
                queries,
                0,
            );
        }
    }

    /// The sum of the `count` compacted sizes [`Self::record_compacted_sizes`] wrote (0 for no
    /// BLAS).
    fn read_compacted_sizes(&self, count: usize) -> Result<u64> {
        if count == 0 {
            return Ok(0);
        }
        let mut sizes = vec![0u64; count];
        // SAFETY: the waited submission wrote all `count` queries of the pool.
        unsafe {
            self.device.get_query_pool_results(
                self.compacted_queries,
                0,
                &mut sizes,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .map_err(vkerr("vkGetQueryPoolResults (compacted sizes)"))?;
        Ok(sizes.iter().sum())
    }

    /// The triangle geometry of each mesh of `built` in the uploaded vertex and index buffers.
    fn blas_geometries(
        &self,
        built: &[MeshRange],
    ) -> Vec<[vk::AccelerationStructureGeometryKHR<'static>; 1]> {
        built
            .iter()
            .map(|m| {
                let tri = vk::AccelerationStructureGeometryTrianglesDataKHR::default()
                    .vertex_format(vk::Format::R32G32B32_SFLOAT)
                    .vertex_data(vk::DeviceOrHostAddressConstKHR {
                        device_address: self.vertices.address + m.first_vertex * 12,
                    })
                    .vertex_stride(12)
                    .max_vertex(m.vertices.saturating_sub(1))
                    .index_type(vk::IndexType::UINT32)
                    .index_data(vk::DeviceOrHostAddressConstKHR {
                        device_address: self.indices.address + m.first_index * 4,
                    });
                [vk::AccelerationStructureGeometryKHR::default()
                    .geometry_type(vk::GeometryTypeKHR::TRIANGLES)
                    .geometry(vk::AccelerationStructureGeometryDataKHR { triangles: tri })
                    .flags(vk::GeometryFlagsKHR::OPAQUE)]
            })
            .collect()
    }

    /// The sizes of the BLASes of `built`, and each one's place in one storage buffer and one
    /// scratch buffer.
    fn blas_layout(
        &self,
        built: &[MeshRange],
        geometries: &[[vk::AccelerationStructureGeometryKHR<'_>; 1]],
        flags: vk::BuildAccelerationStructureFlagsKHR,
    ) -> BlasLayout {
        let mut layout = BlasLayout::default();
        for (m, g) in built.iter().zip(geometries) {
            let mut sizes = vk::AccelerationStructureBuildSizesInfoKHR::default();
            // SAFETY: a valid build info; one primitive count per geometry.
            unsafe {
                self.accel.get_acceleration_structure_build_sizes(
                    vk::AccelerationStructureBuildTypeKHR::DEVICE,
                    &blas_info(g, flags),
                    &[m.triangles],
                    &mut sizes,
                )
            };
            layout.as_total = align_up(layout.as_total, AS_OFFSET_ALIGN);
            layout.as_offsets.push(layout.as_total);
            layout.as_sizes.push(sizes.acceleration_structure_size);
            layout.as_total += sizes.acceleration_structure_size;
            layout.scratch_total = align_up(layout.scratch_total, self.props.scratch_alignment);
            layout.scratch_offsets.push(layout.scratch_total);
            layout.scratch_total += sizes.build_scratch_size;
        }
        layout
    }

    /// The BLAS storage and scratch buffers of `layout`.
    fn create_blas_buffers(&mut self, layout: &BlasLayout) -> Result<()> {
        self.blas_buffer = self.create_buffer(
            layout.as_total,
            vk::BufferUsageFlags::ACCELERATION_STRUCTURE_STORAGE_KHR
                | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
            "BLAS storage",
        )?;
        self.blas_bytes = layout.as_total;
        // Padded so the scratch base can be aligned up.
        self.blas_scratch = self.create_buffer(
            layout.scratch_total + self.props.scratch_alignment,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
            "BLAS scratch",
        )?;
        Ok(())
    }

    /// One acceleration structure per BLAS of `layout` in the storage buffer. On an error the
    /// ones made so far go into `self.blases`, so they are destroyed with them.
    fn create_blas_handles(
        &mut self,
        layout: &BlasLayout,
    ) -> Result<Vec<vk::AccelerationStructureKHR>> {
        let mut handles = Vec::with_capacity(layout.as_offsets.len());
        for (&off, &size) in layout.as_offsets.iter().zip(&layout.as_sizes) {
            // SAFETY: the range lies within blas_buffer; the handle is returned or stored in
            // `self.blases` right below, so it is destroyed with them.
            let blas = unsafe {
                self.accel.create_acceleration_structure(
                    &vk::AccelerationStructureCreateInfoKHR::default()
                        .buffer(self.blas_buffer.buffer)
                        .offset(off)
                        .size(size)
                        .ty(vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL),
                    None,
                )
            };
            match blas {
                Ok(b) => handles.push(b),
                Err(e) => {
                    self.blases = handles.into_iter().map(|h| Some((h, 0))).collect();
                    return Err(vkerr("vkCreateAccelerationStructureKHR")(e));
                }
            }
        }
        Ok(handles)
    }

    /// `self.blases`: the built `handles` (one per mesh with triangles, in order) with their
    /// device addresses, `None` for the meshes without triangles.
    fn store_blases(&mut self, handles: Vec<vk::AccelerationStructureKHR>) {
        let accel = &self.accel;
        let mut it = handles.into_iter();
        self.blases = self
            .meshes
            .iter()
            .map(|m| {
                if m.triangles == 0 {
                    None
                } else {
                    it.next().map(|h| {
                        // SAFETY: a live acceleration structure.
                        let addr = unsafe {
                            accel.get_acceleration_structure_device_address(
                                &vk::AccelerationStructureDeviceAddressInfoKHR::default()
                                    .acceleration_structure(h),
                            )
                        };
                        (h, addr)
                    })
                }
            })
            .collect();
    }

    /// Builds the TLAS over `instances` (PREFER_FAST_TRACE, facing culling disabled, forced
    /// opaque: our hit rules), timed as [`Self::build_blases`]. Instances of meshes without
    /// triangles are left out.
    pub fn build_tlas(&mut self, instances: &[Instance], timing: Timing) -> Result<Samples> {
        if self.blases.is_empty() {
            return Err(PeerError::Order("build_blases first"));
        }
        self.destroy_tlas();
        let flags = (vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE
            | vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE)
            .as_raw();
        let mut records = Vec::with_capacity(instances.len());
        for (k, inst) in instances.iter().enumerate() {
            let blas = self.blases.get(inst.mesh).ok_or_else(|| {
                PeerError::InvalidInput(format!("instance {k}: mesh {} does not exist", inst.mesh))
            })?;
            if inst.index > 0xff_ffff {
                return Err(PeerError::InvalidInput(format!(
                    "instance {k}: index {} does not fit the 24-bit custom index",
                    inst.index
                )));
            }
            if let Some((_, addr)) = blas {
                records.push(InstanceRecord {
                    transform: inst.transform,
                    custom_index_and_mask: inst.index | (u32::from(inst.mask) << 24),
                    sbt_offset_and_flags: flags << 24,
                    blas: *addr,
                });
            }
        }
        self.instance_buffer = self.upload(
            bytemuck::cast_slice(&records),
            vk::BufferUsageFlags::ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_KHR
                | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            "TLAS instances",
        )?;
        let geometry = [vk::AccelerationStructureGeometryKHR::default()
            .geometry_type(vk::GeometryTypeKHR::INSTANCES)
            .geometry(vk::AccelerationStructureGeometryDataKHR {
                instances: vk::AccelerationStructureGeometryInstancesDataKHR::default()
                    .array_of_pointers(false)
                    .data(vk::DeviceOrHostAddressConstKHR {
                        device_address: self.instance_buffer.address,
                    }),
            })
            .flags(vk::GeometryFlagsKHR::OPAQUE)];
        let count = records.len() as u32;
        let info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::TOP_LEVEL)
            .flags(vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE)
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(&geometry);
        let mut sizes = vk::AccelerationStructureBuildSizesInfoKHR::default();
        // SAFETY: a valid build info with one geometry.
        unsafe {
            self.accel.get_acceleration_structure_build_sizes(
                vk::AccelerationStructureBuildTypeKHR::DEVICE,
                &info,
                &[count],
                &mut sizes,
            )
        };
        self.tlas_buffer = self.create_buffer(
            sizes.acceleration_structure_size,
            vk::BufferUsageFlags::ACCELERATION_STRUCTURE_STORAGE_KHR
                | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
            "TLAS storage",
        )?;
        self.tlas_scratch = self.create_buffer(
            sizes.build_scratch_size + self.props.scratch_alignment,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
            "TLAS scratch",
        )?;
        // SAFETY: the buffer holds acceleration_structure_size bytes.
        self.tlas = unsafe {
            self.accel.create_acceleration_structure(
                &vk::AccelerationStructureCreateInfoKHR::default()
                    .buffer(self.tlas_buffer.buffer)
                    .size(sizes.acceleration_structure_size)
                    .ty(vk::AccelerationStructureTypeKHR::TOP_LEVEL),
                None,
            )
        }
        .map_err(vkerr("vkCreateAccelerationStructureKHR"))?;
        let infos =
            [info
                .dst_acceleration_structure(self.tlas)
                .scratch_data(vk::DeviceOrHostAddressKHR {
                    device_address: align_up(
                        self.tlas_scratch.address,
                        self.props.scratch_alignment,
                    ),
                })];
        let range = [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(count)];
        let accel = &self.accel;
        self.repeat(timing, |_| {
            self.timed(
                |_, cmd| {
                    // SAFETY: instances, destination and scratch are live; the BLASes were built
                    // by an earlier, waited submission.
                    unsafe { accel.cmd_build_acceleration_structures(cmd, &infos, &[&range]) }
                },
                |_, _| {},
            )
        })
    }

    /// Traces `rays` against the TLAS (`timing.iterations` times after the warm-up) and returns
    /// the GPU times of `vkCmdTraceRaysKHR` and the last run's hits. Ray i is launch id
    /// (i % width, i / width) with `width = launch_width` (the bench passes its image width, so
    /// primary rays keep their 2-D coherence).
    pub fn trace(
        &mut self,
        rays: &[Ray],
        query: Query,
        launch_width: u32,
        timing: Timing,
    ) -> Result<(Samples, Vec<Hit>)> {
        if self.tlas == vk::AccelerationStructureKHR::null() {
            return Err(PeerError::Order("build_tlas first"));
        }
        if rays.is_empty() {
            return Ok((Samples(Vec::new()), Vec::new()));
        }
        let n = rays.len() as u64;
        let bytes = n * 32;
        if bytes > self.props.max_storage_range {
            return Err(PeerError::InvalidInput(format!(
                "{n} rays need {bytes} bytes, beyond the device's storage buffer range ({})",
                self.props.max_storage_range
            )));
        }
        let width = u64::from(launch_width.max(1))
            .min(n)
            .min(self.props.max_launch[0]);
        let height = n.div_ceil(width);
        if height > self.props.max_launch[1] || width * height > self.props.max_dispatch {
            return Err(PeerError::InvalidInput(format!(
                "{n} rays need a {width}x{height} launch, beyond the device's limits"
            )));
        }
        let mut ray_buf = self.upload(
            bytemuck::cast_slice(rays),
            vk::BufferUsageFlags::STORAGE_BUFFER,
            "rays",
        )?;
        let result = self.trace_uploaded(&ray_buf, n, query, (width as u32, height as u32), timing);
        self.destroy_buffer(&mut ray_buf);
        result
    }

    fn trace_uploaded(
        &mut self,
        rays: &Buffer,
        n: u64,
        query: Query,
        (width, height): (u32, u32),
        timing: Timing,
    ) -> Result<(Samples, Vec<Hit>)> {
        let bytes = n * 32;
        let mut hits = self.create_buffer(
            bytes,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC,
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
            "hits",
        )?;
        let mut readback = match self.create_buffer(
            bytes,
            vk::BufferUsageFlags::TRANSFER_DST,
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
            "hit read-back",
        ) {
            Ok(b) => b,
            Err(e) => {
                self.destroy_buffer(&mut hits);
                return Err(e);
            }
        };
        let result = self.trace_into(rays, &hits, &readback, n, query, (width, height), timing);
        let out = result.and_then(|samples| {
            let raw = self.read_host(&readback, bytes as usize)?;
            let hits = raw
                .chunks_exact(32)
                .map(bytemuck::pod_read_unaligned::<Hit>)
                .collect();
            Ok((samples, hits))
        });
        self.destroy_buffer(&mut hits);
        self.destroy_buffer(&mut readback);
        out
    }

    #[allow(clippy::too_many_arguments)]
    fn trace_into(
        &self,
        rays: &Buffer,
        hits: &Buffer,
        readback: &Buffer,
        n: u64,
        query: Query,
        (width, height): (u32, u32),
        timing: Timing,
    ) -> Result<Samples> {
        let tlases = [self.tlas];
        let mut as_write = vk::WriteDescriptorSetAccelerationStructureKHR::default()
            .acceleration_structures(&tlases);
        let ray_info = [vk::DescriptorBufferInfo::default()
            .buffer(rays.buffer)
            .range(vk::WHOLE_SIZE)];
        let hit_info = [vk::DescriptorBufferInfo::default()
            .buffer(hits.buffer)
            .range(vk::WHOLE_SIZE)];
        let mut tlas_write = vk::WriteDescriptorSet::default()
            .dst_set(self.set)
            .dst_binding(0)
            .descriptor_type(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
            .push_next(&mut as_write);
        // The count comes from the pushed struct's array for the other types; set it here.
        tlas_write.descriptor_count = 1;
        let writes = [
            tlas_write,
            vk::WriteDescriptorSet::default()
                .dst_set(self.set)
                .dst_binding(1)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .buffer_info(&ray_info),
            vk::WriteDescriptorSet::default()
                .dst_set(self.set)
                .dst_binding(2)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .buffer_info(&hit_info),
        ];
        // SAFETY: the set is not in use by pending work (every submission is waited for).
        unsafe { self.device.update_descriptor_sets(&writes, &[]) };
        let flags: u32 = match query {
            Query::Closest => 0,
            // gl_RayFlagsTerminateOnFirstHitEXT
            Query::Any => 4,
        };
        let push: [u32; 4] = [n as u32, width, flags, 0];
        let sbt = self.sbt;
        let callable = vk::StridedDeviceAddressRegionKHR::default();
        self.repeat(timing, |last| {
            self.timed(
                |d, cmd| {
                    // SAFETY: pipeline, set and SBT are live; push constants match the layout.
                    unsafe {
                        d.cmd_bind_pipeline(
                            cmd,
                            vk::PipelineBindPoint::RAY_TRACING_KHR,
                            self.pipeline,
                        );
                        d.cmd_bind_descriptor_sets(
                            cmd,
                            vk::PipelineBindPoint::RAY_TRACING_KHR,
                            self.pipeline_layout,
                            0,
                            &[self.set],
                            &[],
                        );
                        d.cmd_push_constants(
                            cmd,
                            self.pipeline_layout,
                            vk::ShaderStageFlags::RAYGEN_KHR,
                            0,
                            bytemuck::cast_slice(&push),
                        );
                        self.rt.cmd_trace_rays(
                            cmd,
                            &sbt.raygen,
                            &sbt.miss,
                            &sbt.hit,
                            &callable,
                            width,
                            height,
                            1,
                        );
                    }
                },
                |d, cmd| {
                    if !last {
                        return;
                    }
                    let barrier = vk::MemoryBarrier::default()
                        .src_access_mask(vk::AccessFlags::SHADER_WRITE)
                        .dst_access_mask(vk::AccessFlags::TRANSFER_READ);
                    // SAFETY: recording; both buffers hold n * 32 bytes.
                    unsafe {
                        d.cmd_pipeline_barrier(
                            cmd,
                            vk::PipelineStageFlags::RAY_TRACING_SHADER_KHR,
                            vk::PipelineStageFlags::TRANSFER,
                            vk::DependencyFlags::empty(),
                            &[barrier],
                            &[],
                            &[],
                        );
                        d.cmd_copy_buffer(
                            cmd,
                            hits.buffer,
                            readback.buffer,
                            &[vk::BufferCopy::default().size(n * 32)],
                        );
                    }
                },
            )
        })
    }
}

impl Drop for VulkanRtPeer {
    fn drop(&mut self) {
        // SAFETY: waiting for the device first, then destroying every object this peer made
        // (null handles are ignored), the device, and the instance last.
        unsafe {
            let _ = self.device.device_wait_idle();
            self.destroy_blases();
            let mut b = std::mem::take(&mut self.vertices);
            self.destroy_buffer(&mut b);
            let mut b = std::mem::take(&mut self.indices);
            self.destroy_buffer(&mut b);
            let mut b = std::mem::take(&mut self.sbt_buffer);
            self.destroy_buffer(&mut b);
            let d = &self.device;
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_descriptor_pool(self.descriptor_pool, None);
            d.destroy_pipeline_layout(self.pipeline_layout, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
            d.destroy_query_pool(self.queries, None);
            d.destroy_fence(self.fence, None);
            d.destroy_command_pool(self.pool, None);
            d.destroy_device(None);
            self.instance.destroy_instance(None);
        }
    }
}
