//! Render tasks: lighting-cache injection and transfer, the trace tasks and the denoisers, with the
//! G-buffer inputs they share. Defaults are the reference's.

use crate::handles::{DenoisingContextHandle, InstanceHandle};
use crate::tasks::bvh::InstanceInclusionMask;
use glam::{Mat4, Vec3, Vec4};

/// A texture the SDK reads or writes (the view is reference counted; the SDK keeps a clone while
/// GPU work uses it).
pub type TextureInput = wgpu::TextureView;

/// A pixel rectangle of the input/output textures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Viewport {
    /// Left edge, pixels.
    pub x: u32,
    /// Top edge, pixels.
    pub y: u32,
    /// Width, pixels (> 0).
    pub width: u32,
    /// Height, pixels (> 0).
    pub height: u32,
}

/// How the depth texture encodes the surface position.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepthType {
    /// RGB holds the world-space position.
    RgbWorldSpace,
    /// R holds the hardware depth (clip z / w) of the viewport; normal or reverse Z.
    #[default]
    RClipSpace,
}

/// The depth input.
#[derive(Debug, Clone)]
pub struct DepthInput {
    /// The texture.
    pub texture: TextureInput,
    /// Its encoding.
    pub depth_type: DepthType,
}

/// How the normal texture encodes the surface normal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NormalType {
    /// RGB is the normal.
    RgbVector,
    /// RGB × 2 − 1 is the normal.
    #[default]
    RgbNormalizedVector,
    /// RG is an octahedral-encoded normal.
    RgOctahedron,
    /// BA is an octahedral-encoded normal.
    BaOctahedron,
    /// RG × 2 − 1 is an octahedral-encoded normal.
    RgNormalizedOctahedron,
    /// BA × 2 − 1 is an octahedral-encoded normal.
    BaNormalizedOctahedron,
}

/// The normal input.
#[derive(Debug, Clone)]
pub struct NormalInput {
    /// The texture.
    pub texture: TextureInput,
    /// Its encoding.
    pub normal_type: NormalType,
    /// Transforms decoded normals to world space (identity when they are world-space already).
    pub normal_to_world: Mat4,
}

/// How the motion-vector texture encodes motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MotionType {
    /// RG: viewport-UV motion; previous_uv = uv + motion × scale.
    #[default]
    RgViewSpace,
    /// RGB: world-space displacement; previous_position = position + motion × scale.
    RgbWorldSpace,
}

/// The motion-vector input.
#[derive(Debug, Clone)]
pub struct MotionInput {
    /// The texture.
    pub texture: TextureInput,
    /// Its encoding.
    pub motion_type: MotionType,
    /// Multiplies every motion vector.
    pub scale: Vec3,
}

/// Roughness: a texture channel or a global value, remapped.
#[derive(Debug, Clone)]
pub struct RoughnessInput {
    /// The texture, or `None` to use `global_roughness`.
    pub texture: Option<TextureInput>,
    /// Dot product with the texel selects the channel (default: alpha).
    pub roughness_mask: Vec4,
    /// Used when there is no texture (0..=1).
    pub global_roughness: f32,
    /// Multiplies the value read.
    pub roughness_multiplier: f32,
    /// Lower clamp (0..=1).
    pub min_roughness: f32,
    /// Upper clamp (0..=1, ≥ min).
    pub max_roughness: f32,
}

impl Default for RoughnessInput {
    fn default() -> Self {
        RoughnessInput {
            texture: None,
            roughness_mask: Vec4::new(0.0, 0.0, 0.0, 1.0),
            global_roughness: 0.3,
            roughness_multiplier: 1.0,
            min_roughness: 0.0,
            max_roughness: 1.0,
        }
    }
}

/// Specular colour / metalness: a texture or a global metalness.
#[derive(Debug, Clone)]
pub struct SpecularInput {
    /// The texture, or `None` to use `global_metalness`.
    pub texture: Option<TextureInput>,
    /// Used when there is no texture (0..=1).
    pub global_metalness: f32,
}

impl Default for SpecularInput {
    fn default() -> Self {
        SpecularInput {
            texture: None,
            global_metalness: 1.0,
        }
    }
}

/// Ray-origin offset against self-intersection.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum RayOffsetType {
    /// No offset.
    #[default]
    Disabled,
    /// Offset scaled by the magnitude of the world position.
    WorldPosition,
    /// Offset growing with distance from the camera.
    CamDistance,
}

/// Parameters of the ray offset (world units where lengths).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayOffset {
    /// Which offset.
    pub offset_type: RayOffsetType,
    /// World-position mode: switch from float to integer offset above this magnitude.
    pub world_position_threshold: f32,
    /// World-position mode: normal scale for the float offset.
    pub world_position_float_scale: f32,
    /// World-position mode: normal scale for the integer (ulp) offset.
    pub world_position_int_scale: f32,
    /// Camera-distance mode: constant term.
    pub cam_distance_constant: f32,
    /// Camera-distance mode: linear term.
    pub cam_distance_linear: f32,
    /// Camera-distance mode: quadratic term.
    pub cam_distance_quadratic: f32,
}

impl Default for RayOffset {
    fn default() -> Self {
        RayOffset {
            offset_type: RayOffsetType::Disabled,
            world_position_threshold: 1.0 / 32.0,
            world_position_float_scale: 1.0 / 65536.0,
            world_position_int_scale: 256.0,
            cam_distance_constant: 0.00174,
            cam_distance_linear: -0.0001547,
            cam_distance_quadratic: 0.0000996,
        }
    }
}

/// Which pixels a trace task traces, and how its denoiser reconstructs the others.
///
/// The checkerboard modes are the reference's: half the pixels traced, the denoiser fills the
/// others from their traced neighbours at full resolution. The block modes trace one pixel per
/// 2×2 or 4×4 block (a quarter or a sixteenth of the rays): the denoiser filters at that
/// reduced resolution and upsamples its result to every pixel, guided by the G-buffer (normals
/// and depth, so that edges stay sharp), which also makes it cheaper. In every mode the trace
/// writes only the pixels it traces.
///
/// Give a trace task and the denoise task that reads its output the same mode. Advance
/// `phase` every frame (the frame index will do): it moves the traced pixel through the block,
/// so that the temporal accumulation sees every pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum HalfResolutionMode {
    /// Full resolution.
    #[default]
    Off,
    /// Trace the even checkerboard cells (viewport-relative `(x + y)` even).
    Checkerboard,
    /// Trace the odd checkerboard cells.
    CheckerboardInverted,
    /// One pixel per 2×2 block: the pixel `phase % 4` of the sequence (0, 0), (1, 1), (1, 0),
    /// (0, 1) within each block (viewport-relative).
    OnePer2x2 {
        /// Which pixel of each block (modulo 4).
        phase: u32,
    },
    /// One pixel per 4×4 block: the pixel `phase % 16` of a 4×4 ordered-dither (Bayer)
    /// sequence within each block, which spreads consecutive phases across the block.
    OnePer4x4 {
        /// Which pixel of each block (modulo 16).
        phase: u32,
    },
}

/// The pixels of a 2×2 block in the order [`HalfResolutionMode::OnePer2x2`] traces them.
const BLOCK2_ORDER: [(u32, u32); 4] = [(0, 0), (1, 1), (1, 0), (0, 1)];

/// The pixels of a 4×4 block in the order [`HalfResolutionMode::OnePer4x4`] traces them: the
/// pixel of Bayer-matrix value k is the k-th.
const BLOCK4_ORDER: [(u32, u32); 16] = [
    (0, 0),
    (2, 2),
    (2, 0),
    (0, 2),
    (1, 1),
    (3, 3),
    (3, 1),
    (1, 3),
    (1, 0),
    (3, 2),
    (3, 0),
    (1, 2),
    (0, 1),
    (2, 3),
    (2, 1),
    (0, 3),
];

impl HalfResolutionMode {
    /// Side of the pixel block one ray stands for: 2 or 4 in the block modes, 1 otherwise (the
    /// checkerboard modes trace every other pixel of a full-resolution grid).
    pub fn block_size(self) -> u32 {
        match self {
            HalfResolutionMode::OnePer2x2 { .. } => 2,
            HalfResolutionMode::OnePer4x4 { .. } => 4,
            _ => 1,
        }
    }

    /// The traced pixel of each block, relative to the block's top-left pixel ((0, 0) outside
    /// the block modes).
    pub fn traced_pixel(self) -> (u32, u32) {
        match self {
            HalfResolutionMode::OnePer2x2 { phase } => BLOCK2_ORDER[(phase % 4) as usize],
            HalfResolutionMode::OnePer4x4 { phase } => BLOCK4_ORDER[(phase % 16) as usize],
            _ => (0, 0),
        }
    }

    /// Whether viewport-relative pixel `(x, y)` is traced in this mode.
    pub fn is_traced(self, x: u32, y: u32) -> bool {
        match self {
            HalfResolutionMode::Off => true,
            HalfResolutionMode::Checkerboard => (x + y).is_multiple_of(2),
            HalfResolutionMode::CheckerboardInverted => (x + y) % 2 == 1,
            _ => {
                let b = self.block_size();
                (x % b, y % b) == self.traced_pixel()
            }
        }
    }

    /// The mode as the trace and denoise shaders read it: bits 0–7 the mode (0 off,
    /// 1 checkerboard, 2 inverted, 3 block), 8–15 the block size, 16–23 and 24–31 the traced
    /// pixel's x and y in the block.
    pub(crate) fn shader_code(self) -> u32 {
        let (x, y) = self.traced_pixel();
        let mode = match self {
            HalfResolutionMode::Off => 0,
            HalfResolutionMode::Checkerboard => 1,
            HalfResolutionMode::CheckerboardInverted => 2,
            _ => 3,
        };
        mode | (self.block_size() << 8) | (x << 16) | (y << 24)
    }

    /// The size of the grid of traced pixels for a `width` × `height` viewport: the viewport,
    /// its half-width in a checkerboard mode, one pixel per block in a block mode.
    pub(crate) fn traced_grid(self, width: u32, height: u32) -> (u32, u32) {
        match self {
            HalfResolutionMode::Off => (width, height),
            HalfResolutionMode::Checkerboard | HalfResolutionMode::CheckerboardInverted => {
                (width.div_ceil(2), height)
            }
            _ => {
                let b = self.block_size();
                (width.div_ceil(b), height.div_ceil(b))
            }
        }
    }
}

/// Debug output of the trace tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DebugOutputType {
    /// Normal output.
    #[default]
    Default,
    /// Primary-ray hit distance.
    HitT,
    /// Primary-ray barycentrics.
    Barycentrics,
    /// A colour per instance.
    RandomMeshColor,
    /// A colour per cache tile.
    RandomTileColor,
    /// The direct lighting cache seen by primary rays.
    DirectLightingCache,
    /// The decoded normal.
    Normal,
    /// The decoded roughness.
    Roughness,
    /// The reconstructed world position.
    WorldPosition,
}

/// Random numbers for ray directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RandomNumberGenerator {
    /// A generated blue-noise texture.
    #[default]
    BlueNoise,
    /// xorshift per pixel.
    Xorshift,
}

/// Debug parameters shared by trace tasks.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DebugParameters {
    /// What to write.
    pub debug_output_type: DebugOutputType,
    /// The random sequence.
    pub random_number_generator: RandomNumberGenerator,
    /// Frame index for noise; same index, same noise.
    pub frame_index: u32,
}

/// The camera of a task.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewInfo {
    /// World to view.
    pub world_to_view: Mat4,
    /// View to clip (unjittered), normal or reverse Z.
    pub view_to_clip: Mat4,
    /// Previous frame's world to view (denoisers).
    pub prev_world_to_view: Mat4,
    /// Previous frame's view to clip (denoisers).
    pub prev_view_to_clip: Mat4,
    /// Sub-pixel jitter of this frame, pixels, x right and y down: a point at unjittered pixel
    /// coordinate `c` was rendered at `c + jitter` (the depth was rasterised with the jittered
    /// projection, `view_to_clip` is the unjittered one). Every task that reads clip-space depth
    /// unprojects each texel where it was sampled; a wrong jitter puts surfaces off their planes
    /// at grazing angles (self-shadowing, light leaks).
    pub jitter: glam::Vec2,
}

impl Default for ViewInfo {
    fn default() -> Self {
        ViewInfo {
            world_to_view: Mat4::IDENTITY,
            view_to_clip: Mat4::IDENTITY,
            prev_world_to_view: Mat4::IDENTITY,
            prev_view_to_clip: Mat4::IDENTITY,
            jitter: glam::Vec2::ZERO,
        }
    }
}

/// The G-buffer and settings every trace task reads.
#[derive(Debug, Clone)]
pub struct TraceTaskCommon {
    /// Region of the textures to process; `None` = the whole output.
    pub viewport: Option<Viewport>,
    /// Depth.
    pub depth: DepthInput,
    /// Normals.
    pub normal: NormalInput,
    /// Roughness.
    pub roughness: RoughnessInput,
    /// Specular / metalness.
    pub specular: SpecularInput,
    /// Optional mask: texel value 0 skips the pixel.
    pub input_mask: Option<TextureInput>,
    /// Optional screen-space direct lighting used where a hit is visible in it.
    pub direct_lighting: Option<TextureInput>,
    /// Optional lat-long environment map sampled on miss.
    pub environment_map: Option<TextureInput>,
    /// Camera.
    pub view: ViewInfo,
    /// Longest ray, world units (> 0; ∞ allowed).
    pub max_ray_length: f32,
    /// Ray offset.
    pub ray_offset: RayOffset,
    /// Checkerboard mode.
    pub half_resolution_mode: HalfResolutionMode,
    /// Read the cache with bilinear interpolation.
    pub use_bilinear_sampling: bool,
    /// Debug options.
    pub debug_parameters: DebugParameters,
}

impl TraceTaskCommon {
    /// The common inputs with the reference's defaults.
    pub fn new(depth: DepthInput, normal: NormalInput) -> Self {
        TraceTaskCommon {
            viewport: None,
            depth,
            normal,
            roughness: RoughnessInput::default(),
            specular: SpecularInput::default(),
            input_mask: None,
            direct_lighting: None,
            environment_map: None,
            view: ViewInfo::default(),
            max_ray_length: f32::INFINITY,
            ray_offset: RayOffset::default(),
            half_resolution_mode: HalfResolutionMode::Off,
            use_bilinear_sampling: true,
            debug_parameters: DebugParameters::default(),
        }
    }
}

/// Blends the engine's rasterised direct lighting into the world-space cache.
#[derive(Debug, Clone)]
pub struct DirectLightingInjectionTask {
    /// Region to inject; `None` = the whole lighting texture.
    pub viewport: Option<Viewport>,
    /// Depth of the injecting view.
    pub depth: DepthInput,
    /// HDR direct lighting of the view.
    pub direct_lighting: TextureInput,
    /// Camera of the view.
    pub view: ViewInfo,
    /// Running average over about this many tasks (≥ 1).
    pub average_window: f32,
    /// Inject one pixel per stride×stride block (1..=8).
    pub injection_resolution_stride: u32,
}

impl DirectLightingInjectionTask {
    /// An injection task with the reference's defaults.
    pub fn new(depth: DepthInput, direct_lighting: TextureInput, view: ViewInfo) -> Self {
        DirectLightingInjectionTask {
            viewport: None,
            depth,
            direct_lighting,
            view,
            average_window: 200.0,
            injection_resolution_stride: 4,
        }
    }
}

/// Copies cached lighting between instances (LOD switch).
#[derive(Debug, Clone)]
pub struct DirectLightTransferTask {
    /// Source instance.
    pub source: InstanceHandle,
    /// Target instance (its geometry needs `allow_light_transfer_target`).
    pub target: InstanceHandle,
}

/// GGX reflections.
#[derive(Debug, Clone)]
pub struct TraceSpecularTask {
    /// Shared inputs.
    pub common: TraceTaskCommon,
    /// Radiance (RGB) and hit distance (A).
    pub output: TextureInput,
    /// Write radiance divided by the specular BRDF estimate.
    pub demodulate_specular: bool,
    /// Output for the demodulation factor, when demodulating.
    pub demodulation_output: Option<TextureInput>,
}

/// Diffuse BRDF of [`TraceDiffuseTask`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DiffuseBrdf {
    /// Lambertian.
    #[default]
    Lambertian,
    /// Normalised Disney.
    NormalizedDisney,
}

/// Diffuse GI.
#[derive(Debug, Clone)]
pub struct TraceDiffuseTask {
    /// Shared inputs.
    pub common: TraceTaskCommon,
    /// Radiance (RGB) and hit distance (A).
    pub output: TextureInput,
    /// BRDF for ray sampling.
    pub diffuse_brdf: DiffuseBrdf,
    /// Also write ambient occlusion from the same rays, instead of tracing a
    /// [`TraceAmbientOcclusionTask`]: one traversal for both effects.
    pub ambient_occlusion: Option<DiffuseAmbientOcclusion>,
}

impl TraceDiffuseTask {
    /// A Lambertian diffuse task without ambient occlusion.
    pub fn new(common: TraceTaskCommon, output: TextureInput) -> Self {
        TraceDiffuseTask {
            common,
            output,
            diffuse_brdf: DiffuseBrdf::Lambertian,
            ambient_occlusion: None,
        }
    }
}

/// Ambient occlusion written by a [`TraceDiffuseTask`] from its own rays.
///
/// The diffuse rays are cosine-weighted, as the AO task's are, so the output is what a
/// [`TraceAmbientOcclusionTask`] with the same inputs and `ao_radius` writes (hit distance /
/// `ao_radius`, 1 where nothing is hit within it) and its denoiser reads it the same way. Its
/// noise is the diffuse signal's (the same rays), and with
/// [`DiffuseBrdf::NormalizedDisney`] the rays are still cosine-weighted (Disney only reweights
/// their radiance). Costs one extra texture write per pixel instead of a traversal.
#[derive(Debug, Clone)]
pub struct DiffuseAmbientOcclusion {
    /// Hit distance / `ao_radius` (1 when nothing within it).
    pub output: TextureInput,
    /// Occlusion radius, world units (> 0).
    pub ao_radius: f32,
}

/// Ambient occlusion.
#[derive(Debug, Clone)]
pub struct TraceAmbientOcclusionTask {
    /// Shared inputs.
    pub common: TraceTaskCommon,
    /// Hit distance / `ao_radius` (1 when nothing within it).
    pub output: TextureInput,
    /// Occlusion radius, world units (> 0).
    pub ao_radius: f32,
}

/// A light for the shadow tasks. Lengths are world units, angles radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LightInfo {
    /// Sun-like light.
    Directional {
        /// Direction the light travels (unit).
        direction: Vec3,
        /// Apparent angular diameter.
        angular_extent: f32,
    },
    /// Point light.
    Point {
        /// Position.
        position: Vec3,
        /// Emitter radius (≥ 0).
        radius: f32,
        /// Range (> 0).
        range: f32,
    },
    /// Spot light.
    Spot {
        /// Position.
        position: Vec3,
        /// Axis (unit).
        direction: Vec3,
        /// Emitter radius (≥ 0).
        radius: f32,
        /// Range (> 0).
        range: f32,
        /// Half-angle of the cone (0..π/2].
        apex_angle: f32,
    },
}

/// Shadow of one light.
#[derive(Debug, Clone)]
pub struct TraceShadowTask {
    /// Shared inputs.
    pub common: TraceTaskCommon,
    /// Closest hit distance; negative where the light is visible: there minus the tangent of the
    /// light's angular radius seen from the pixel (at least 2^-14, so negative in every float
    /// format), which [`DenoiseShadowTask`] reads as the width of the penumbra; -1 where the
    /// G-buffer has no surface.
    pub output: TextureInput,
    /// The light.
    pub light: LightInfo,
    /// Stop at the first hit (the reference's first-hit-and-end-search).
    pub enable_first_hit_and_end_search: bool,
}

/// Most lights one [`TraceMultiShadowTask`] takes.
pub const MAX_MULTI_SHADOW_LIGHTS: usize = 32;

/// Shadows of up to [`MAX_MULTI_SHADOW_LIGHTS`] lights in one pass.
#[derive(Debug, Clone)]
pub struct TraceMultiShadowTask {
    /// Shared inputs.
    pub common: TraceTaskCommon,
    /// Packed visibility.
    pub output0: TextureInput,
    /// Packed visibility, second half.
    pub output1: TextureInput,
    /// The lights (1..=32).
    pub lights: Vec<LightInfo>,
    /// Stop at the first hit.
    pub enable_first_hit_and_end_search: bool,
}

/// What a denoiser does with its history this frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DenoiseMode {
    /// Accumulate.
    #[default]
    Continue,
    /// Drop history (camera cut).
    DiscardHistory,
}

/// The G-buffer and settings every denoise task reads.
#[derive(Debug, Clone)]
pub struct DenoiseTaskCommon {
    /// The denoiser's history.
    pub context: DenoisingContextHandle,
    /// Region; `None` = the whole output.
    pub viewport: Option<Viewport>,
    /// Depth.
    pub depth: DepthInput,
    /// Normals.
    pub normal: NormalInput,
    /// Roughness.
    pub roughness: RoughnessInput,
    /// Motion vectors; `None` reprojects with the matrices.
    pub motion: Option<MotionInput>,
    /// Camera (with previous matrices and jitter).
    pub view: ViewInfo,
    /// Must match the trace task's.
    pub half_resolution_mode: HalfResolutionMode,
    /// History handling.
    pub mode: DenoiseMode,
}

/// Denoises a specular trace.
#[derive(Debug, Clone)]
pub struct DenoiseSpecularTask {
    /// Shared inputs.
    pub common: DenoiseTaskCommon,
    /// The trace output.
    pub input: TextureInput,
    /// Denoised result.
    pub output: TextureInput,
}

/// Denoises a diffuse trace.
#[derive(Debug, Clone)]
pub struct DenoiseDiffuseTask {
    /// Shared inputs.
    pub common: DenoiseTaskCommon,
    /// The trace output.
    pub input: TextureInput,
    /// Denoised result.
    pub output: TextureInput,
}

/// Denoises specular and diffuse traces in one pass.
#[derive(Debug, Clone)]
pub struct DenoiseSpecularAndDiffuseTask {
    /// Shared inputs.
    pub common: DenoiseTaskCommon,
    /// Specular trace output.
    pub input_specular: TextureInput,
    /// Diffuse trace output.
    pub input_diffuse: TextureInput,
    /// Denoised specular.
    pub output_specular: TextureInput,
    /// Denoised diffuse.
    pub output_diffuse: TextureInput,
}

/// Denoises ambient occlusion.
#[derive(Debug, Clone)]
pub struct DenoiseDiffuseOcclusionTask {
    /// Shared inputs.
    pub common: DenoiseTaskCommon,
    /// AO trace output (normalised hit distance).
    pub input: TextureInput,
    /// Denoised occlusion.
    pub output: TextureInput,
}

/// Denoises one shadow.
#[derive(Debug, Clone)]
pub struct DenoiseShadowTask {
    /// Shared inputs.
    pub common: DenoiseTaskCommon,
    /// Shadow trace output.
    pub input: TextureInput,
    /// Denoised visibility.
    pub output: TextureInput,
}

/// Denoises a multi-light shadow.
#[derive(Debug, Clone)]
pub struct DenoiseMultiShadowTask {
    /// Shared inputs.
    pub common: DenoiseTaskCommon,
    /// Packed trace output.
    pub input0: TextureInput,
    /// Packed trace output, second half.
    pub input1: TextureInput,
    /// Denoised visibility.
    pub output: TextureInput,
}

/// Which query a [`TraceRaysTask`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RayQuery {
    /// The closest hit in `[t_min, t_max]` (ties: lowest instance, then lowest primitive index).
    #[default]
    ClosestHit,
    /// Any hit in `[t_min, t_max]` (occlusion); stops at the first hit found, which need not be
    /// the closest.
    AnyHit,
}

/// One ray of a [`TraceRaysTask`] (32 bytes, `#[repr(C)]`): the points `origin + t·dir` for
/// `t_min ≤ t ≤ t_max`. `dir` need not be normalised (`t` is in units of its length); `t_max` may
/// be `f32::INFINITY`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuRay {
    /// Start point, world space.
    pub origin: [f32; 3],
    /// Smallest accepted `t`.
    pub t_min: f32,
    /// Direction, world space.
    pub dir: [f32; 3],
    /// Largest accepted `t`.
    pub t_max: f32,
}

/// One result of a [`TraceRaysTask`] (32 bytes, `#[repr(C)]`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuHit {
    /// Ray parameter of the hit; −1 on a miss.
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the third vertex.
    pub v: f32,
    /// Instance index (the instance handle's [`crate::InstanceHandle::index`]); `u32::MAX` on a
    /// miss.
    pub instance: u32,
    /// Triangle index within the instance's geometry: the triangles of earlier components first,
    /// then this component's, after its `index_range`.
    pub primitive: u32,
    /// Padding to 32 bytes.
    pub _pad: [u32; 3],
}

impl GpuHit {
    /// `instance` of a miss.
    pub const MISS: u32 = u32::MAX;

    /// Whether the ray hit something.
    pub fn is_hit(&self) -> bool {
        self.instance != Self::MISS
    }
}

/// A batch of rays read from a buffer, their hits written to a buffer: ray queries for tools,
/// gameplay (visibility, picking) and tests, through the same traversal as every trace task.
#[derive(Debug, Clone)]
pub struct TraceRaysTask {
    /// [`GpuRay`] records; needs `BufferUsages::STORAGE`.
    pub rays: wgpu::Buffer,
    /// Byte offset of the first ray: a multiple of the device's
    /// `min_storage_buffer_offset_alignment`.
    pub ray_offset: u64,
    /// Rays to trace (0 traces nothing).
    pub ray_count: u32,
    /// Receives one [`GpuHit`] per ray; needs `BufferUsages::STORAGE`.
    pub hits: wgpu::Buffer,
    /// Byte offset of the first hit: a multiple of `min_storage_buffer_offset_alignment`.
    pub hit_offset: u64,
    /// Closest or any hit.
    pub query: RayQuery,
    /// Instances whose inclusion mask shares a bit with this one are visible.
    pub instance_mask: InstanceInclusionMask,
}

impl TraceRaysTask {
    /// A closest-hit batch of `ray_count` rays at offset 0, visible to `VISIBLE_IN_RT` instances.
    pub fn new(rays: wgpu::Buffer, ray_count: u32, hits: wgpu::Buffer) -> Self {
        TraceRaysTask {
            rays,
            ray_offset: 0,
            ray_count,
            hits,
            hit_offset: 0,
            query: RayQuery::ClosestHit,
            instance_mask: InstanceInclusionMask::VISIBLE_IN_RT,
        }
    }
}

/// Any render task.
#[derive(Debug, Clone)]
#[allow(missing_docs)]
pub enum RenderTask {
    TraceRays(TraceRaysTask),
    DirectLightingInjection(DirectLightingInjectionTask),
    DirectLightTransfer(DirectLightTransferTask),
    TraceSpecular(TraceSpecularTask),
    TraceDiffuse(TraceDiffuseTask),
    TraceAmbientOcclusion(TraceAmbientOcclusionTask),
    TraceShadow(TraceShadowTask),
    TraceMultiShadow(TraceMultiShadowTask),
    DenoiseSpecular(DenoiseSpecularTask),
    DenoiseDiffuse(DenoiseDiffuseTask),
    DenoiseSpecularAndDiffuse(DenoiseSpecularAndDiffuseTask),
    DenoiseDiffuseOcclusion(DenoiseDiffuseOcclusionTask),
    DenoiseShadow(DenoiseShadowTask),
    DenoiseMultiShadow(DenoiseMultiShadowTask),
}

impl RenderTask {
    /// The shared inputs of a denoise task; `None` for other tasks.
    pub fn denoise_common(&self) -> Option<&DenoiseTaskCommon> {
        match self {
            RenderTask::DenoiseSpecular(t) => Some(&t.common),
            RenderTask::DenoiseDiffuse(t) => Some(&t.common),
            RenderTask::DenoiseSpecularAndDiffuse(t) => Some(&t.common),
            RenderTask::DenoiseDiffuseOcclusion(t) => Some(&t.common),
            RenderTask::DenoiseShadow(t) => Some(&t.common),
            RenderTask::DenoiseMultiShadow(t) => Some(&t.common),
            _ => None,
        }
    }

    /// The shared inputs and main output of a trace task; `None` for other tasks.
    pub fn trace_common(&self) -> Option<(&TraceTaskCommon, &TextureInput)> {
        match self {
            RenderTask::TraceSpecular(t) => Some((&t.common, &t.output)),
            RenderTask::TraceDiffuse(t) => Some((&t.common, &t.output)),
            RenderTask::TraceAmbientOcclusion(t) => Some((&t.common, &t.output)),
            RenderTask::TraceShadow(t) => Some((&t.common, &t.output)),
            RenderTask::TraceMultiShadow(t) => Some((&t.common, &t.output0)),
            _ => None,
        }
    }

    /// The task type's name, as errors report it.
    pub fn name(&self) -> &'static str {
        match self {
            RenderTask::TraceRays(_) => "TraceRaysTask",
            RenderTask::DirectLightingInjection(_) => "DirectLightingInjectionTask",
            RenderTask::DirectLightTransfer(_) => "DirectLightTransferTask",
            RenderTask::TraceSpecular(_) => "TraceSpecularTask",
            RenderTask::TraceDiffuse(_) => "TraceDiffuseTask",
            RenderTask::TraceAmbientOcclusion(_) => "TraceAmbientOcclusionTask",
            RenderTask::TraceShadow(_) => "TraceShadowTask",
            RenderTask::TraceMultiShadow(_) => "TraceMultiShadowTask",
            RenderTask::DenoiseSpecular(_) => "DenoiseSpecularTask",
            RenderTask::DenoiseDiffuse(_) => "DenoiseDiffuseTask",
            RenderTask::DenoiseSpecularAndDiffuse(_) => "DenoiseSpecularAndDiffuseTask",
            RenderTask::DenoiseDiffuseOcclusion(_) => "DenoiseDiffuseOcclusionTask",
            RenderTask::DenoiseShadow(_) => "DenoiseShadowTask",
            RenderTask::DenoiseMultiShadow(_) => "DenoiseMultiShadowTask",
        }
    }
}

/// Output formats the trace and denoise tasks can write.
pub const WRITABLE_OUTPUT_FORMATS: [wgpu::TextureFormat; 4] = [
    wgpu::TextureFormat::Rgba16Float,
    wgpu::TextureFormat::Rgba32Float,
    wgpu::TextureFormat::R32Float,
    wgpu::TextureFormat::Rg32Float,
];
