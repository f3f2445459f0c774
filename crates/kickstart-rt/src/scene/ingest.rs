//! Vertex pulling: decodes application geometry (copied raw into SDK memory by the context) into
//! the triangle soup (`docs/ray-tracing-core.md`). Any vertex format, stride and byte offset,
//! u16/u32/no indices, index ranges, per-component transforms. Bad triangles (out-of-range index,
//! NaN/∞ position before or after the transform) are written as dropped and counted on the GPU.
//!
//! All components of one [`Ingest::record`] call go into one dispatch with a small component
//! table, so scenes of thousands of small geometries do not cost thousands of passes.

use crate::gpu::reflect::{ReflectedPipeline, ReflectedShader};
use crate::gpu::Recorder;
use crate::tasks::{IndexFormat, VertexFormat};

/// Threads per workgroup of `scene/ingest.wgsl` (one triangle each).
const WORKGROUP: u32 = 64;

/// `u32`s per component row of the table (`Component` in `scene/ingest.wgsl`: 112 bytes).
pub(crate) const ROW_WORDS: usize = 28;

/// Where one component's bytes sit in the raw copy buffer, and where its triangles go.
#[derive(Debug, Clone)]
pub(crate) struct ComponentIngest {
    /// Byte offset in `raw` of vertex 0 (any alignment: the app's offset may be unaligned).
    pub vertex_byte_offset: u64,
    /// Bytes between consecutive vertices.
    pub vertex_stride: u64,
    /// Position format.
    pub vertex_format: VertexFormat,
    /// Vertices available; indices at or past it drop their triangle.
    pub vertex_count: u32,
    /// Byte offset in `raw` of index 0 and the index width; `None`: non-indexed (3 consecutive
    /// vertices per triangle).
    pub index: Option<(u64, IndexFormat)>,
    /// Start of the index range (in indices, or vertices when non-indexed).
    pub first_index: u32,
    /// Triangles of the component (after its index range).
    pub triangle_count: u32,
    /// Transform into geometry space, if any.
    pub transform: Option<glam::Affine3A>,
    /// Primitive index of its first triangle (the triangles of earlier components).
    pub primitive_base: u32,
    /// Its opacity source in the raw copy (cutout geometry), if any.
    pub opacity: Option<OpacityIngest>,
}

/// Where a component's opacity source sits in the task's raw copy (`ComponentIngest`).
#[derive(Debug, Clone)]
pub(crate) enum OpacityIngest {
    /// The glTF MASK test of a texture channel at the component's coordinates.
    Texture {
        /// The texture read.
        texture: wgpu::TextureView,
        /// Byte offset in `raw` of vertex 0's coordinates (any alignment).
        uv_byte_offset: u64,
        /// Bytes between vertices' coordinates.
        uv_stride: u64,
        /// Their format.
        uv_format: crate::tasks::UvFormat,
        /// Channel holding alpha.
        channel: u32,
        /// Alpha factor.
        factor: f32,
        /// Opaque at or above it.
        cutoff: f32,
    },
    /// A `u32` flag per triangle from this byte offset in `raw` (4-aligned).
    PerTriangle {
        /// Byte offset of triangle 0's flag.
        byte_offset: u64,
    },
}

/// The vertex-pulling pass (one pipeline, created once).
pub(crate) struct Ingest {
    /// `scene/ingest.wgsl`'s `ingest` entry point.
    pipeline: ReflectedPipeline,
}

/// Per-dispatch parameters (`Params` in `scene/ingest.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    tri_total: u32,
    component_count: u32,
    counter_base: u32,
    pad: u32,
}

/// The WGSL of the ingestion pass, labelled.
pub(crate) fn shader_variants() -> Vec<(String, String)> {
    let shader = ReflectedShader::compose(&["scene/ingest"], &[]);
    vec![("scene/ingest".into(), shader.source().to_string())]
}

impl Ingest {
    /// Creates the pipeline.
    pub fn new(device: &wgpu::Device) -> Self {
        let shader = ReflectedShader::compose(&["scene/ingest"], &[]);
        Ingest {
            pipeline: shader.pipeline(device, "kickstart-rt ingest", "ingest"),
        }
    }

    /// Decodes `components` into the triangle soup `out_tris`: component i's triangle j goes to
    /// slot `out_base + primitive_base + j`. Bad triangles are written as dropped and counted with
    /// `atomicAdd` into `counters[counter_base]` (an index ≥ `vertex_count`) or
    /// `counters[counter_base + 1]` (a NaN/∞ coordinate after decoding or after the transform);
    /// each dropped triangle counts once, an out-of-range index first. The caller clears them.
    ///
    /// A component whose addresses do not fit the shader's 32-bit arithmetic (only possible past
    /// 4 GiB, beyond any storage binding) is logged and skipped: its slots are left unwritten.
    #[allow(clippy::too_many_arguments)] // the interface the scene code is written against
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        raw: &wgpu::Buffer,
        components: &[ComponentIngest],
        out_tris: &wgpu::Buffer,
        out_base: u32,
        counters: &wgpu::Buffer,
        counter_base: u32,
    ) {
        self.record_many(
            rec,
            raw,
            &[(components, out_base, counter_base)],
            out_tris,
            counters,
        );
    }

    /// [`Ingest::record`] of several geometries' components `(components, out_base,
    /// counter_base)` in one dispatch (one per 2^32 triangles): a task's ingestions cost one
    /// pass, however many geometries it registers. Each table row names its geometry's
    /// counters.
    pub fn record_many(
        &self,
        rec: &mut Recorder<'_>,
        raw: &wgpu::Buffer,
        ingestions: &[(&[ComponentIngest], u32, u32)],
        out_tris: &wgpu::Buffer,
        counters: &wgpu::Buffer,
    ) {
        let mut table: Vec<u32> = Vec::new();
        let mut total: u32 = 0;
        for &(components, out_base, counter_base) in ingestions {
            for (i, c) in components.iter().enumerate() {
                if c.triangle_count == 0 {
                    continue; // no rows for empty components keeps the search's rows non-empty
                }
                // A dispatch counts its triangles in u32: flush first when this one would
                // overflow.
                if total.checked_add(c.triangle_count).is_none() {
                    self.dispatch(rec, raw, &table, total, out_tris, counters, 0);
                    table.clear();
                    total = 0;
                }
                match component_row(c, out_base, total) {
                    Some(mut row) => {
                        row[COUNTER_WORD] = counter_base;
                        table.extend_from_slice(&row);
                        total += c.triangle_count;
                    }
                    None => log::error!(
                        "kickstart-rt ingest: component {i} does not fit 32-bit GPU addressing \
                         (offsets {:#x}/{:?}, stride {}, out slot {}+{}); its triangles are skipped",
                        c.vertex_byte_offset,
                        c.index,
                        c.vertex_stride,
                        out_base,
                        c.primitive_base
                    ),
                }
            }
        }
        self.dispatch(rec, raw, &table, total, out_tris, counters, 0);
    }

    /// One dispatch over the rows of `table` (`total` triangles).
    #[allow(clippy::too_many_arguments)]
    fn dispatch(
        &self,
        rec: &mut Recorder<'_>,
        raw: &wgpu::Buffer,
        table: &[u32],
        total: u32,
        out_tris: &wgpu::Buffer,
        counters: &wgpu::Buffer,
        counter_base: u32,
    ) {
        if total == 0 {
            return;
        }
        let params = rec.uniform(
            "kickstart-rt ingest params",
            &Params {
                tri_total: total,
                component_count: (table.len() / ROW_WORDS) as u32,
                counter_base,
                pad: 0,
            },
        );
        let rows = rec.storage_init(
            "kickstart-rt ingest components",
            bytemuck::cast_slice(table),
        );
        let bind = self.pipeline.bind_group(
            rec.device,
            "kickstart-rt ingest",
            0,
            &[
                ("params", &params),
                ("components", &rows),
                ("raw", raw),
                ("out_tris", out_tris),
                ("counters", counters),
            ],
        );
        rec.dispatch(
            "ingest",
            &self.pipeline.pipeline,
            &[&bind],
            total.div_ceil(WORKGROUP),
        );
    }
}

/// The table rows of one geometry's `components` (triangle starts from 0, empty components
/// left out), as [`Ingest::record`] dispatches them; `None` when a component does not fit the
/// shader's 32-bit addressing (the ingestion pass then logs and skips it).
pub(crate) fn component_rows(components: &[ComponentIngest], out_base: u32) -> Option<Vec<u32>> {
    let mut table = Vec::new();
    let mut total: u32 = 0;
    for c in components.iter().filter(|c| c.triangle_count > 0) {
        table.extend_from_slice(&component_row(c, out_base, total)?);
        total = total.checked_add(c.triangle_count)?;
    }
    Some(table)
}

/// The word of a table row holding its geometry's first dropped-triangle counter (`counter`
/// of `Component` in `scene/ingest_decode.wgsl`).
const COUNTER_WORD: usize = 14;

/// The table row of `c` (`Component` in `scene/ingest.wgsl`), its triangles starting at `tri_start`
/// within the dispatch; `None` when an address the shader computes would overflow `u32`.
pub(crate) fn component_row(
    c: &ComponentIngest,
    out_base: u32,
    tri_start: u32,
) -> Option<[u32; ROW_WORDS]> {
    let vtx_format = match c.vertex_format {
        VertexFormat::Float32x3 => 0,
        VertexFormat::Float32x4 => 1,
        VertexFormat::Float16x4 => 2,
        VertexFormat::Snorm16x4 => 3,
    };
    // The shader addresses bytes relative to a word base: `shift + v * stride (+ 12)` must fit.
    let vtx_shift = c.vertex_byte_offset % 4;
    let last_vertex_end = u64::from(c.vertex_count.max(1) - 1) * c.vertex_stride + vtx_shift + 16;
    u32::try_from(last_vertex_end).ok()?;
    let vtx_word = u32::try_from(c.vertex_byte_offset / 4).ok()?;
    let vtx_stride = u32::try_from(c.vertex_stride).ok()?;
    let end_index = u64::from(c.first_index) + 3 * u64::from(c.triangle_count);
    let (idx_word, idx_shift, idx_format) = match c.index {
        None => {
            u32::try_from(end_index).ok()?;
            (0, 0, 0)
        }
        Some((offset, format)) => {
            let (size, code) = match format {
                IndexFormat::Uint16 => (2, 1),
                IndexFormat::Uint32 => (4, 2),
            };
            u32::try_from(end_index * size + offset % 4 + 4).ok()?;
            (u32::try_from(offset / 4).ok()?, (offset % 4) as u32, code)
        }
    };
    let out_first = out_base.checked_add(c.primitive_base)?;
    // Slot index * 3 (vec4 entries) of its last triangle must fit too.
    u32::try_from((u64::from(out_first) + u64::from(c.triangle_count)) * 3).ok()?;
    c.primitive_base
        .checked_add(c.triangle_count.saturating_sub(1))?;
    let (has_transform, rows) = match c.transform {
        Some(t) => {
            let m = t.matrix3;
            let row = |r: usize| {
                [
                    m.x_axis[r].to_bits(),
                    m.y_axis[r].to_bits(),
                    m.z_axis[r].to_bits(),
                    t.translation[r].to_bits(),
                ]
            };
            (1, [row(0), row(1), row(2)])
        }
        None => (0, [[0; 4]; 3]),
    };
    let head = [
        tri_start,
        c.triangle_count,
        out_first,
        c.primitive_base,
        vtx_word,
        vtx_shift as u32,
        vtx_stride,
        vtx_format,
        c.vertex_count,
        idx_word,
        idx_shift,
        idx_format,
        c.first_index,
        has_transform,
        0,
        0,
    ];
    let mut row = [0u32; ROW_WORDS];
    row[..16].copy_from_slice(&head);
    for (r, values) in rows.iter().enumerate() {
        row[16 + 4 * r..20 + 4 * r].copy_from_slice(values);
    }
    Some(row)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::testing::{buffer, buffer_with, gpu, read_back, run, Rng};
    use glam::{Affine3A, Quat, Vec3};

    /// The pass composed and validated with naga without a device; its uniform, its component
    /// rows and its workgroup size checked against the WGSL.
    #[test]
    fn the_shader_validates_and_matches_the_rust_side() {
        use crate::gpu::compose::compose;
        use crate::gpu::wgsl_check::{assert_wgsl_layout, const_u32, storage_stride, validate};
        let module = validate("scene/ingest", &compose(&["scene/ingest"], &[]));
        assert_wgsl_layout!(
            module,
            "Params",
            Params {
                tri_total,
                component_count,
                counter_base,
                pad
            }
        );
        assert_eq!(
            storage_stride(&module, "components") as usize,
            ROW_WORDS * 4
        );
        assert_eq!(const_u32(&module, "WG"), WORKGROUP);
    }

    /// Sentinel of untouched output words.
    const SENTINEL: u32 = 0xdead_beef;

    /// f16 → f32 by arithmetic (independent of the shader's bit manipulation).
    fn f16_to_f32(h: u16) -> f32 {
        let sign = if h & 0x8000 != 0 { -1.0f32 } else { 1.0 };
        let e = i32::from((h >> 10) & 0x1f);
        let m = f32::from(h & 0x3ff);
        match e {
            0 => sign * m * 2f32.powi(-24),
            31 if m == 0.0 => sign * f32::INFINITY,
            31 => f32::NAN,
            _ => sign * (1024.0 + m) * 2f32.powi(e - 25),
        }
    }

    /// The CPU decoding of one position at byte `at` of `raw`.
    fn decode(raw: &[u8], at: usize, format: VertexFormat) -> [f32; 3] {
        let u16_at = |i: usize| u16::from_le_bytes([raw[at + 2 * i], raw[at + 2 * i + 1]]);
        let f32_at = |i: usize| {
            f32::from_le_bytes([
                raw[at + 4 * i],
                raw[at + 4 * i + 1],
                raw[at + 4 * i + 2],
                raw[at + 4 * i + 3],
            ])
        };
        match format {
            VertexFormat::Float32x3 | VertexFormat::Float32x4 => [f32_at(0), f32_at(1), f32_at(2)],
            VertexFormat::Float16x4 => [0, 1, 2].map(|i| f16_to_f32(u16_at(i))),
            VertexFormat::Snorm16x4 => {
                [0, 1, 2].map(|i| (f32::from(u16_at(i) as i16) / 32767.0).max(-1.0))
            }
        }
    }

    /// Expected triangle of one slot: entry bits, and per-vertex tolerance (0: bit-exact).
    struct Expected {
        bits: [[u32; 4]; 3],
        tol: [[f32; 3]; 3],
    }

    /// The CPU oracle: expected slots (by slot index) and the two counters.
    fn cpu_ingest(
        raw: &[u8],
        comps: &[ComponentIngest],
        out_base: u32,
    ) -> (Vec<(u32, Expected)>, [u32; 2]) {
        let mut out = Vec::new();
        let mut counters = [0u32; 2];
        for c in comps {
            for j in 0..c.triangle_count {
                let mut status = 0; // 0 ok, 1 bad index, 2 non-finite
                let mut pos = [[0f32; 3]; 3];
                let mut tol = [[0f32; 3]; 3];
                for k in 0..3 {
                    let n = (c.first_index + 3 * j + k) as usize;
                    let v = match c.index {
                        None => n as u32,
                        Some((o, IndexFormat::Uint16)) => {
                            let a = o as usize + 2 * n;
                            u32::from(u16::from_le_bytes([raw[a], raw[a + 1]]))
                        }
                        Some((o, IndexFormat::Uint32)) => {
                            let a = o as usize + 4 * n;
                            u32::from_le_bytes([raw[a], raw[a + 1], raw[a + 2], raw[a + 3]])
                        }
                    };
                    if v >= c.vertex_count {
                        status |= 1;
                        continue;
                    }
                    let at = (c.vertex_byte_offset + u64::from(v) * c.vertex_stride) as usize;
                    let p = decode(raw, at, c.vertex_format);
                    if p.iter().any(|x| !x.is_finite()) {
                        status |= 2;
                        continue;
                    }
                    pos[k as usize] = p;
                    if let Some(t) = c.transform {
                        let q = t.transform_point3(Vec3::from(p));
                        if !q.is_finite() {
                            status |= 2;
                            continue;
                        }
                        pos[k as usize] = q.into();
                        // Rounding scale: the magnitudes of the terms of each row.
                        for (r, tol_r) in tol[k as usize].iter_mut().enumerate() {
                            let m = t.matrix3;
                            let mag = (m.x_axis[r] * p[0]).abs()
                                + (m.y_axis[r] * p[1]).abs()
                                + (m.z_axis[r] * p[2]).abs()
                                + t.translation[r].abs();
                            *tol_r = 4.0 * f32::EPSILON * mag;
                        }
                    }
                }
                let prim = c.primitive_base + j;
                let bits = if status == 0 {
                    let b = |k: usize, w: u32| {
                        [
                            pos[k][0].to_bits(),
                            pos[k][1].to_bits(),
                            pos[k][2].to_bits(),
                            w,
                        ]
                    };
                    [b(0, prim), b(1, 0), b(2, 0)]
                } else {
                    counters[if status & 1 != 0 { 0 } else { 1 }] += 1;
                    tol = [[0.0; 3]; 3];
                    [[0, 0, 0, prim], [0, 0, 0, 1], [0; 4]]
                };
                out.push((out_base + c.primitive_base + j, Expected { bits, tol }));
            }
        }
        (out, counters)
    }

    /// Runs the GPU ingestion of `comps` over `raw` into a sentinel-filled soup of `slots`
    /// triangles, compares every slot with the CPU oracle (untouched slots keep the sentinel) and
    /// the counters at `counter_base` (neighbours stay 0). Returns the GPU soup and counters.
    fn check(
        raw: &[u8],
        comps: &[ComponentIngest],
        out_base: u32,
        slots: u32,
        counter_base: u32,
    ) -> (Vec<[u32; 4]>, [u32; 2]) {
        let g = gpu();
        let mut padded = raw.to_vec();
        padded.resize(raw.len().div_ceil(4) * 4, 0);
        let raw_buf = buffer_with(&padded);
        let out = buffer_with(bytemuck::cast_slice(&vec![SENTINEL; slots as usize * 12]));
        let n_counters = counter_base as u64 + 3;
        let counters = buffer(n_counters * 4);
        let ingest = Ingest::new(&g.device);
        run(|rec| {
            rec.encoder.clear_buffer(&counters, 0, None);
            ingest.record(
                rec,
                &raw_buf,
                comps,
                &out,
                out_base,
                &counters,
                counter_base,
            );
        });
        let got: Vec<[u32; 4]> =
            bytemuck::cast_slice(&read_back(&out, 0, u64::from(slots) * 48)).to_vec();
        let cnt: Vec<u32> = bytemuck::cast_slice(&read_back(&counters, 0, n_counters * 4)).to_vec();
        let (expected, want_counters) = cpu_ingest(raw, comps, out_base);
        let mut touched = vec![false; slots as usize];
        for (slot, e) in &expected {
            touched[*slot as usize] = true;
            for k in 0..3 {
                let gv = got[3 * *slot as usize + k];
                assert_eq!(gv[3], e.bits[k][3], "slot {slot} vertex {k} w");
                for (r, &g_bits) in gv.iter().take(3).enumerate() {
                    let (a, b) = (f32::from_bits(g_bits), f32::from_bits(e.bits[k][r]));
                    if e.tol[k][r] == 0.0 {
                        assert_eq!(
                            g_bits, e.bits[k][r],
                            "slot {slot} vertex {k}[{r}]: gpu {a} cpu {b}"
                        );
                    } else {
                        assert!(
                            (a - b).abs() <= e.tol[k][r],
                            "slot {slot} vertex {k}[{r}]: gpu {a} cpu {b}"
                        );
                    }
                }
            }
        }
        for (s, t) in touched.iter().enumerate() {
            if !t {
                assert!(
                    got[3 * s..3 * s + 3].iter().all(|v| *v == [SENTINEL; 4]),
                    "slot {s} written"
                );
            }
        }
        let cb = counter_base as usize;
        assert_eq!([cnt[cb], cnt[cb + 1]], want_counters, "counters");
        assert!(
            cnt[..cb].iter().chain(&cnt[cb + 2..]).all(|&c| c == 0),
            "other counters"
        );
        (got, want_counters)
    }

    /// Appends `n` junk bytes.
    fn junk(raw: &mut Vec<u8>, rng: &mut Rng, n: usize) {
        raw.extend((0..n).map(|_| rng.next() as u8));
    }

    /// Appends vertex data (`stride` bytes each, junk between) at an offset with `offset % 4 ==
    /// align`; position bytes from `coord(vertex, axis)` (4 or 2 bytes by the format). Returns the
    /// offset.
    fn put_vertices(
        raw: &mut Vec<u8>,
        rng: &mut Rng,
        align: usize,
        stride: usize,
        format: VertexFormat,
        count: u32,
        mut coord: impl FnMut(&mut Rng, u32, usize) -> u32,
    ) -> u64 {
        junk(raw, rng, (align + 4 - raw.len() % 4) % 4);
        let start = raw.len();
        for v in 0..count {
            let at = raw.len();
            junk(raw, rng, stride);
            for axis in 0..3 {
                let bits = coord(rng, v, axis);
                match format {
                    VertexFormat::Float32x3 | VertexFormat::Float32x4 => {
                        raw[at + 4 * axis..at + 4 * axis + 4].copy_from_slice(&bits.to_le_bytes())
                    }
                    _ => raw[at + 2 * axis..at + 2 * axis + 2]
                        .copy_from_slice(&(bits as u16).to_le_bytes()),
                }
            }
        }
        junk(raw, rng, 3);
        start as u64
    }

    /// Appends indices at an offset with `offset % 4 == align` (a multiple of the index size).
    fn put_indices(
        raw: &mut Vec<u8>,
        rng: &mut Rng,
        align: usize,
        format: IndexFormat,
        indices: &[u32],
    ) -> u64 {
        junk(raw, rng, (align + 4 - raw.len() % 4) % 4);
        let start = raw.len();
        for &i in indices {
            match format {
                IndexFormat::Uint16 => raw.extend((i as u16).to_le_bytes()),
                IndexFormat::Uint32 => raw.extend(i.to_le_bytes()),
            }
        }
        junk(raw, rng, 2);
        start as u64
    }

    /// A finite f32 coordinate in [-100, 100].
    fn coord_f32(rng: &mut Rng, _: u32, _: usize) -> u32 {
        rng.range(-100.0, 100.0).to_bits()
    }

    /// A non-indexed, untransformed component over all of its vertices.
    fn component(
        vertex_byte_offset: u64,
        vertex_stride: u64,
        vertex_format: VertexFormat,
        vertex_count: u32,
        triangle_count: u32,
    ) -> ComponentIngest {
        ComponentIngest {
            vertex_byte_offset,
            vertex_stride,
            vertex_format,
            vertex_count,
            index: None,
            first_index: 0,
            triangle_count,
            transform: None,
            primitive_base: 0,
            opacity: None,
        }
    }

    #[test]
    fn float32x3_unaligned_offset_odd_stride_u32_indices() {
        let mut rng = Rng(1);
        let mut raw = Vec::new();
        let vo = put_vertices(
            &mut raw,
            &mut rng,
            3,
            17,
            VertexFormat::Float32x3,
            50,
            coord_f32,
        );
        let idx: Vec<u32> = (0..90).map(|_| rng.below(50)).collect();
        let io = put_indices(&mut raw, &mut rng, 0, IndexFormat::Uint32, &idx);
        let mut c = component(vo, 17, VertexFormat::Float32x3, 50, 30);
        c.index = Some((io, IndexFormat::Uint32));
        let (_, counters) = check(&raw, &[c], 0, 30, 0);
        assert_eq!(counters, [0, 0]);
    }

    #[test]
    fn float32x4_u16_indices_at_byte_6_with_index_range() {
        let mut rng = Rng(2);
        let mut raw = Vec::new();
        let vo = put_vertices(
            &mut raw,
            &mut rng,
            1,
            20,
            VertexFormat::Float32x4,
            40,
            coord_f32,
        );
        let idx: Vec<u32> = (0..60).map(|_| rng.below(40)).collect();
        junk(&mut raw, &mut rng, 5);
        let io = put_indices(&mut raw, &mut rng, 2, IndexFormat::Uint16, &idx);
        assert_eq!(io % 4, 2);
        let mut c = component(vo, 20, VertexFormat::Float32x4, 40, 14);
        c.index = Some((io, IndexFormat::Uint16));
        c.first_index = 6; // index_range (6, 42)
        check(&raw, &[c], 3, 20, 0);
        // u16 indices at raw byte 6 exactly.
        let mut raw = vec![0u8; 6];
        raw.extend([0u16, 1, 2, 2, 1, 0].iter().flat_map(|i| i.to_le_bytes()));
        let vo = put_vertices(
            &mut raw,
            &mut rng,
            0,
            16,
            VertexFormat::Float32x4,
            3,
            coord_f32,
        );
        let mut c = component(vo, 16, VertexFormat::Float32x4, 3, 2);
        c.index = Some((6, IndexFormat::Uint16));
        check(&raw, &[c], 0, 2, 0);
    }

    #[test]
    fn float16x4_every_value_at_byte_2_matches_cpu_decode() {
        let mut rng = Rng(3);
        let mut raw = vec![0u8; 2];
        // Every f16 bit pattern appears in some coordinate; non-finite ones drop their triangle.
        let count = 65536u32.div_ceil(3).div_ceil(3) * 3;
        let vo = put_vertices(
            &mut raw,
            &mut rng,
            2,
            8,
            VertexFormat::Float16x4,
            count,
            |_, v, a| (3 * v + a as u32) & 0xffff,
        );
        assert_eq!(vo, 2);
        let (_, counters) = check(
            &raw,
            &[component(vo, 8, VertexFormat::Float16x4, count, count / 3)],
            0,
            count / 3,
            0,
        );
        assert!(counters[1] > 0 && counters[0] == 0);
    }

    #[test]
    fn snorm16x4_every_value_at_byte_2_stride_10_matches_cpu_decode() {
        let mut rng = Rng(4);
        let mut raw = vec![0u8; 2];
        let count = 65536u32.div_ceil(3).div_ceil(3) * 3;
        let vo = put_vertices(
            &mut raw,
            &mut rng,
            2,
            10,
            VertexFormat::Snorm16x4,
            count,
            |_, v, a| (3 * v + a as u32) & 0xffff,
        );
        let (_, counters) = check(
            &raw,
            &[component(vo, 10, VertexFormat::Snorm16x4, count, count / 3)],
            0,
            count / 3,
            0,
        );
        assert_eq!(counters, [0, 0]);
    }

    #[test]
    fn two_components_with_transforms_and_primitive_base() {
        let mut rng = Rng(5);
        let mut raw = Vec::new();
        let vo_a = put_vertices(
            &mut raw,
            &mut rng,
            0,
            12,
            VertexFormat::Float32x3,
            30,
            coord_f32,
        );
        let vo_b = put_vertices(
            &mut raw,
            &mut rng,
            2,
            8,
            VertexFormat::Float16x4,
            20,
            |r, _, _| u32::from(r.below(0x7800) as u16 | (r.below(2) as u16) << 15),
        );
        let idx: Vec<u32> = (0..36).map(|_| rng.below(20)).collect();
        let io = put_indices(&mut raw, &mut rng, 2, IndexFormat::Uint16, &idx);
        let mut a = component(vo_a, 12, VertexFormat::Float32x3, 30, 8);
        a.first_index = 3; // non-indexed range (3, 24)
        a.transform = Some(Affine3A::from_scale_rotation_translation(
            Vec3::new(2.0, 0.5, 3.0),
            Quat::from_rotation_y(0.7),
            Vec3::new(10.0, -4.0, 1.0),
        ));
        let mut b = component(vo_b, 8, VertexFormat::Float16x4, 20, 12);
        b.index = Some((io, IndexFormat::Uint16));
        b.transform = Some(Affine3A::from_rotation_translation(
            Quat::from_rotation_x(-1.2),
            Vec3::new(0.0, 5.0, 0.0),
        ));
        b.primitive_base = 8;
        let (got, _) = check(&raw, &[a, b], 4, 30, 1);
        for p in 0..20u32 {
            assert_eq!(got[3 * (4 + p) as usize][3], p, "primitive index in w");
        }
    }

    #[test]
    fn bad_indices_and_non_finite_positions_are_dropped_and_counted() {
        let mut rng = Rng(6);
        let mut raw = Vec::new();
        let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
        // Vertices 3, 7, 11: NaN, +∞, -∞ in one axis; the rest finite.
        let vo = put_vertices(
            &mut raw,
            &mut rng,
            1,
            12,
            VertexFormat::Float32x3,
            16,
            |r, v, a| {
                if v < 12 && v % 4 == 3 && a == v as usize / 4 {
                    bad[v as usize / 4].to_bits()
                } else {
                    coord_f32(r, v, a)
                }
            },
        );
        // 8 triangles: 0 ok, 1 index 16 (= count), 2 index 0xffffffff, 3 NaN, 4 +∞, 5 -∞, 6 bad
        // index and NaN (counted once, as an index), 7 ok.
        let idx = [
            0,
            1,
            2,
            0,
            16,
            2,
            u32::MAX,
            1,
            2,
            3,
            4,
            5,
            6,
            7,
            8,
            9,
            10,
            11,
            3,
            99,
            5,
            12,
            13,
            14,
        ];
        let io = put_indices(&mut raw, &mut rng, 0, IndexFormat::Uint32, &idx);
        let mut c = component(vo, 12, VertexFormat::Float32x3, 16, 8);
        c.index = Some((io, IndexFormat::Uint32));
        // A second component whose transform overflows large (finite) positions to ∞.
        let vo2 = put_vertices(
            &mut raw,
            &mut rng,
            0,
            12,
            VertexFormat::Float32x3,
            6,
            |_, v, _| if v < 3 { 1e10f32 } else { 1.0f32 }.to_bits(),
        );
        let mut c2 = component(vo2, 12, VertexFormat::Float32x3, 6, 2);
        c2.transform = Some(Affine3A::from_scale(Vec3::splat(1e30)));
        c2.primitive_base = 8;
        let (got, counters) = check(&raw, &[c, c2], 2, 12, 3);
        assert_eq!(counters, [3, 4]);
        for t in [1usize, 2, 3, 4, 5, 6, 8] {
            let s = 3 * (2 + t);
            assert_eq!(got[s], [0, 0, 0, t as u32]);
            assert_eq!(got[s + 1], [0, 0, 0, 1]);
            assert_eq!(got[s + 2], [0; 4]);
        }
        assert_eq!(
            got[3 * (2 + 9) + 1][3],
            0,
            "the small-position triangle survives"
        );
    }

    #[test]
    fn many_random_components_in_one_call() {
        let mut rng = Rng(7);
        let mut raw = Vec::new();
        let mut comps = Vec::new();
        let mut prim = 0;
        let formats = [
            VertexFormat::Float32x3,
            VertexFormat::Float32x4,
            VertexFormat::Float16x4,
            VertexFormat::Snorm16x4,
        ];
        for i in 0..300 {
            let format = formats[rng.below(4) as usize];
            let stride = format.size() + u64::from(rng.below(4)) * if i % 2 == 0 { 1 } else { 4 };
            let vcount = 3 + rng.below(30);
            let align = rng.below(4) as usize;
            let vo = put_vertices(
                &mut raw,
                &mut rng,
                align,
                stride as usize,
                format,
                vcount,
                |r, v, a| match format {
                    VertexFormat::Float32x3 | VertexFormat::Float32x4 if r.below(200) == 0 => {
                        f32::NAN.to_bits()
                    }
                    VertexFormat::Float32x3 | VertexFormat::Float32x4 => coord_f32(r, v, a),
                    VertexFormat::Float16x4 => r.below(0x10000),
                    VertexFormat::Snorm16x4 => r.below(0x10000),
                },
            );
            let tris = rng.below(12); // some components are empty
            let first = 3 * rng.below(3);
            let mut c = component(vo, stride, format, vcount, tris);
            c.first_index = first;
            match rng.below(3) {
                0 => {}
                n => {
                    let f = if n == 1 {
                        IndexFormat::Uint16
                    } else {
                        IndexFormat::Uint32
                    };
                    let idx: Vec<u32> = (0..first + 3 * tris)
                        .map(|_| rng.below(vcount + 1))
                        .collect();
                    let align = if f == IndexFormat::Uint16 {
                        2 * rng.below(2) as usize
                    } else {
                        0
                    };
                    c.index = Some((put_indices(&mut raw, &mut rng, align, f, &idx), f));
                }
            }
            if c.index.is_none() {
                // Vertices must exist for the range: rebuild the data with enough of them.
                c.vertex_count = first + 3 * tris;
                c.vertex_byte_offset = put_vertices(
                    &mut raw,
                    &mut rng,
                    0,
                    stride as usize,
                    format,
                    c.vertex_count.max(1),
                    |r, v, a| match format {
                        VertexFormat::Float32x3 | VertexFormat::Float32x4 => coord_f32(r, v, a),
                        _ => r.below(0x10000),
                    },
                );
            }
            if rng.below(2) == 0 {
                c.transform = Some(Affine3A::from_scale_rotation_translation(
                    Vec3::splat(rng.range(0.1, 4.0)),
                    Quat::from_rotation_z(rng.range(-3.0, 3.0)),
                    Vec3::new(rng.range(-9.0, 9.0), 1.0, -2.0),
                ));
            }
            c.primitive_base = prim;
            prim += tris;
            comps.push(c);
        }
        let (_, counters) = check(&raw, &comps, 7, prim + 10, 0);
        assert!(counters[0] > 0 && counters[1] > 0, "{counters:?}");
    }
}
