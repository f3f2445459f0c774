//! Cutout geometry's opacity micro-maps (`crate::ComponentOpacity`): their size, where they live
//! (a range of the triangle pool, so tracing binds nothing more), and the pass that bakes them at
//! ingestion (`shaders/scene/opacity.wgsl`). Layout: `docs/ray-tracing-core.md`, "Cutout
//! geometry".

use crate::gpu::buffers::placeholder_texture;
use crate::gpu::reflect::{ReflectedPipeline, ReflectedShader};
use crate::gpu::Recorder;
use crate::scene::ingest::{component_row, ComponentIngest, OpacityIngest};
use crate::scene::pool::Range;
use crate::tasks::{micromap_words, GeometryInput, UvFormat};

/// Words of the triangle pool a pool element holds: a triangle is 3 `vec4<f32>` (48 bytes,
/// `gpu_scene::TRIANGLE_BYTES`, which imports this module).
const WORDS_PER_ELEMENT: u64 = 12;
/// Invocations of a bake workgroup (`BAKE_WG`).
const WORKGROUP: u32 = 64;

/// A geometry's opacity micro-maps: their range of the triangle pool and their level.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct OpacityMaps {
    /// Elements of the triangle pool holding the maps, triangle `p`'s (by primitive index) at
    /// word `range.start * 12 + p * words`.
    pub range: Range,
    /// Micro-map level of every triangle.
    pub level: u32,
}

impl OpacityMaps {
    /// The geometry record's opacity words: first word in the triangle pool, level, words a
    /// triangle (`GeometryGpu::opacity`).
    pub fn record(&self) -> [u32; 4] {
        let first = u64::from(self.range.start) * WORDS_PER_ELEMENT;
        [
            u32::try_from(first).unwrap_or(u32::MAX),
            self.level,
            micromap_words(self.level),
            0,
        ]
    }
}

/// The record of an opaque geometry: no maps.
pub(crate) const OPAQUE_RECORD: [u32; 4] = [u32::MAX, 0, 0, 0];

/// The micro-map level of `input`'s triangles (its components' largest), or `None` when no
/// component has an opacity source (opaque: no maps).
pub(crate) fn geometry_level(input: &GeometryInput) -> Option<u32> {
    input
        .components
        .iter()
        .filter_map(|c| c.opacity.as_ref().map(|o| o.level()))
        .max()
}

/// Triangle-pool elements the maps of `triangles` triangles at `level` take.
pub(crate) fn elements(triangles: u32, level: u32) -> u32 {
    let words = u64::from(triangles) * u64::from(micromap_words(level));
    u32::try_from(words.div_ceil(WORDS_PER_ELEMENT).max(1)).unwrap_or(u32::MAX)
}

/// `Bake` in `shaders/scene/opacity.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Bake {
    mode: u32,
    level: u32,
    words: u32,
    out_word: u32,
    uv_word: u32,
    uv_shift: u32,
    uv_stride: u32,
    uv_format: u32,
    flag_word: u32,
    channel: u32,
    factor: f32,
    cutoff: f32,
}

/// The bake pass.
pub(crate) struct OpacityBaker {
    pipeline: ReflectedPipeline,
    /// Bound in place of a texture by the modes that read none.
    no_texture: wgpu::TextureView,
}

/// The WGSL of the bake pass, labelled.
pub(crate) fn shader_variants() -> Vec<(String, String)> {
    let shader = ReflectedShader::compose(&["scene/opacity"], &[]);
    vec![("scene/opacity".into(), shader.source().to_string())]
}

impl OpacityBaker {
    /// Creates the pipeline.
    pub fn new(device: &wgpu::Device) -> Self {
        let shader = ReflectedShader::compose(&["scene/opacity"], &[]);
        let no_texture = placeholder_texture(device, "kickstart-rt no opacity texture");
        OpacityBaker {
            pipeline: shader.pipeline(device, "kickstart-rt opacity bake", "opacity_bake"),
            no_texture,
        }
    }

    /// Bakes the maps of one geometry's `components` (all of its components, in order: those
    /// without a source get opaque maps) into `maps` of the triangle pool `pool`, read from the
    /// task's `raw` copy. A component whose addresses do not fit 32-bit arithmetic (past 4 GiB)
    /// is skipped, as its ingestion is.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        raw: &wgpu::Buffer,
        components: &[ComponentIngest],
        (pool, maps): (&wgpu::Buffer, OpacityMaps),
    ) {
        let words = micromap_words(maps.level);
        let first = u64::from(maps.range.start) * WORDS_PER_ELEMENT;
        for c in components.iter().filter(|c| c.triangle_count > 0) {
            let out = first + u64::from(c.primitive_base) * u64::from(words);
            let (Ok(out_word), Some(row)) = (u32::try_from(out), component_row(c, 0, 0)) else {
                continue;
            };
            let Some(bake) = bake_params(c, maps.level, words, out_word) else {
                continue;
            };
            let texture = match &c.opacity {
                Some(OpacityIngest::Texture { texture, .. }) => texture,
                _ => &self.no_texture,
            };
            let params = rec.uniform("kickstart-rt opacity bake params", &bake);
            let rows =
                rec.storage_init("kickstart-rt opacity bake row", bytemuck::cast_slice(&row));
            let bind = self.pipeline.bind_resources(
                rec.device,
                "kickstart-rt opacity bake",
                0,
                &[
                    ("bake", params.as_entire_binding()),
                    ("components", rows.as_entire_binding()),
                    ("raw", raw.as_entire_binding()),
                    ("maps", pool.as_entire_binding()),
                    (
                        "opacity_texture",
                        wgpu::BindingResource::TextureView(texture),
                    ),
                ],
            );
            let invocations = u64::from(c.triangle_count) * u64::from(words);
            let Ok(invocations) = u32::try_from(invocations) else {
                continue;
            };
            rec.dispatch(
                "opacity bake",
                &self.pipeline.pipeline,
                &[&bind],
                invocations.div_ceil(WORKGROUP),
            );
        }
    }
}

/// The bake parameters of component `c` (`None` when its coordinates' addresses do not fit
/// 32-bit arithmetic).
fn bake_params(c: &ComponentIngest, level: u32, words: u32, out_word: u32) -> Option<Bake> {
    let mut b = Bake {
        mode: 0,
        level,
        words,
        out_word,
        uv_word: 0,
        uv_shift: 0,
        uv_stride: 0,
        uv_format: 0,
        flag_word: 0,
        channel: 0,
        factor: 0.0,
        cutoff: 0.0,
    };
    match &c.opacity {
        None => {}
        Some(OpacityIngest::PerTriangle { byte_offset }) => {
            b.mode = 2;
            b.flag_word = u32::try_from(byte_offset / 4).ok()?;
        }
        Some(OpacityIngest::Texture {
            uv_byte_offset,
            uv_stride,
            uv_format,
            channel,
            factor,
            cutoff,
            ..
        }) => {
            // The shader addresses `shift + v * stride + 4` bytes past the word base.
            let end = u64::from(c.vertex_count.max(1) - 1) * uv_stride + uv_byte_offset % 4 + 8;
            u32::try_from(end).ok()?;
            b.mode = 1;
            b.uv_word = u32::try_from(uv_byte_offset / 4).ok()?;
            b.uv_shift = (uv_byte_offset % 4) as u32;
            b.uv_stride = u32::try_from(*uv_stride).ok()?;
            b.uv_format = match uv_format {
                UvFormat::Float32x2 => 0,
                UvFormat::Float16x2 => 1,
                UvFormat::Unorm16x2 => 2,
            };
            b.channel = *channel;
            b.factor = *factor;
            b.cutoff = *cutoff;
        }
    }
    Some(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_take_a_word_a_triangle_up_to_level_2_then_a_bit_a_micro_triangle() {
        assert_eq!(micromap_words(0), 1);
        assert_eq!(micromap_words(2), 1);
        assert_eq!(micromap_words(3), 2);
        assert_eq!(micromap_words(6), 128);
        // 12 words an element of the pool.
        assert_eq!(elements(12, 0), 1);
        assert_eq!(elements(13, 0), 2);
        assert_eq!(elements(3, 6), 32);
        assert_eq!(elements(0, 4), 1);
    }

    #[test]
    fn the_shader_validates() {
        let source = ReflectedShader::compose(&["scene/opacity"], &[]);
        assert!(source.source().contains("fn opacity_bake"));
    }
}
