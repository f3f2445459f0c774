//! Geometry validation fuzzed with extreme values (strides, offsets and counts up to the ends of
//! their types) against an oracle that computes every byte span in `u128`, where nothing can
//! overflow: validation accepts exactly the inputs the oracle finds inside their buffers, and
//! then copies exactly the bytes it computes. Run with overflow checks on (debug: a wrap would
//! panic) and off (release: a wrap would pass silently); CI runs both.

use super::{geometry_input, COPY_ALIGN};
use crate::gpu::testing;
use crate::tasks::*;
use proptest::prelude::*;

/// Sizes of the buffers the cases point into.
const BUFFER_SIZES: [u64; 4] = [48, 100, 4096, 1 << 20];

/// Cases per run: the validation is pure arithmetic, so many are cheap.
const CASES: u32 = 100_000;

fn buffers() -> &'static [wgpu::Buffer] {
    static BUFFERS: std::sync::OnceLock<Vec<wgpu::Buffer>> = std::sync::OnceLock::new();
    BUFFERS.get_or_init(|| {
        BUFFER_SIZES
            .iter()
            .map(|&size| {
                testing::gpu()
                    .device
                    .create_buffer(&wgpu::BufferDescriptor {
                        label: Some("validation fuzz"),
                        size,
                        usage: wgpu::BufferUsages::COPY_SRC,
                        mapped_at_creation: false,
                    })
            })
            .collect()
    })
}

/// A `u64` field: mostly small, sometimes near the type's end.
fn wide() -> impl Strategy<Value = u64> {
    prop_oneof![6 => 0u64..5000, 1 => (u64::MAX - 5000)..=u64::MAX, 1 => any::<u64>()]
}

/// A `u32` count: mostly small, sometimes near the type's end, sometimes one past a power of
/// two (the vertex span multiplies the stride by count − 1).
fn count() -> impl Strategy<Value = u32> {
    prop_oneof![
        6 => 0u32..2000,
        1 => (u32::MAX - 5000)..=u32::MAX,
        1 => any::<u32>(),
        2 => (0u32..31).prop_map(|k| (1 << k) + 1),
    ]
}

/// A stride: mostly small, sometimes wide, sometimes just past 2^64 / 2^k, whose product with
/// a count of 2^k + 1 wraps to a few bytes (what an unchecked multiply would accept).
fn stride() -> impl Strategy<Value = u64> {
    prop_oneof![
        4 => 0u64..64,
        1 => wide(),
        2 => (1u32..12, 0u64..16).prop_map(|(k, r)| (1u64 << (64 - k)) + r),
    ]
}

/// One component's fields (buffers by index into [`BUFFER_SIZES`]).
#[derive(Debug, Clone)]
struct Case {
    vertex: (usize, u64, u64, u32, VertexFormat),
    index: Option<(usize, u64, u32, IndexFormat)>,
    range: Option<(u32, u32)>,
}

fn case() -> impl Strategy<Value = Case> {
    let format = prop::sample::select(vec![
        VertexFormat::Float32x3,
        VertexFormat::Float32x4,
        VertexFormat::Float16x4,
        VertexFormat::Snorm16x4,
    ]);
    let index_format = prop::sample::select(vec![IndexFormat::Uint16, IndexFormat::Uint32]);
    (
        (0..BUFFER_SIZES.len(), wide(), stride(), count(), format),
        prop::option::of((0..BUFFER_SIZES.len(), wide(), count(), index_format)),
        prop::option::of((count(), count())),
    )
        .prop_map(|(vertex, index, range)| Case {
            vertex,
            index,
            range,
        })
}

/// The aligned copy span of `len` bytes at `offset` in a buffer of `size`, computed in `u128`;
/// `None` when it does not fit.
fn span(offset: u64, len: u128, size: u64) -> Option<(u64, u64)> {
    let end = u128::from(offset) + len;
    let align = u128::from(COPY_ALIGN);
    let aligned_end = end.div_ceil(align) * align;
    (aligned_end <= u128::from(size)).then(|| (offset - offset % COPY_ALIGN, aligned_end as u64))
}

/// What validation makes of an accepted component: its vertex span, index span and triangles.
type Accepted = ((u64, u64), Option<(u64, u64)>, u32);

/// What validation must make of `c`, or `None` when some rule refuses it.
fn oracle(c: &Case) -> Option<Accepted> {
    let (vb, offset, stride, vcount, format) = c.vertex;
    if stride < format.size() || vcount == 0 {
        return None;
    }
    let vlen = u128::from(stride) * u128::from(vcount - 1) + u128::from(format.size());
    let vspan = span(offset, vlen, BUFFER_SIZES[vb])?;
    let (total, ispan) = match c.index {
        Some((ib, ioffset, icount, iformat)) => {
            if ioffset % iformat.size() != 0 || icount == 0 || icount % 3 != 0 {
                return None;
            }
            let ilen = u128::from(icount) * u128::from(iformat.size());
            (icount, Some(span(ioffset, ilen, BUFFER_SIZES[ib])?))
        }
        None if vcount % 3 == 0 => (vcount, None),
        None => return None,
    };
    let triangles = match c.range {
        Some((first, n)) => {
            let fits = u64::from(first) + u64::from(n) <= u64::from(total);
            if first % 3 != 0 || n % 3 != 0 || n == 0 || !fits {
                return None;
            }
            n / 3
        }
        None => total / 3,
    };
    Some((vspan, ispan, triangles))
}

fn input(c: &Case) -> GeometryInput {
    let b = buffers();
    let (vb, offset, stride, vcount, format) = c.vertex;
    GeometryInput {
        name: "fuzz".into(),
        components: vec![GeometryComponent {
            vertex_buffer: VertexBufferInput {
                buffer: b[vb].clone(),
                offset,
                stride,
                count: vcount,
                format,
            },
            index_buffer: c.index.map(|(ib, offset, count, format)| IndexBufferInput {
                buffer: b[ib].clone(),
                offset,
                count,
                format,
            }),
            transform: None,
            index_range: c.range,
            opacity: None,
        }],
        ..GeometryInput::default()
    }
}

fn config() -> proptest::test_runner::Config {
    let seed = std::env::var("PROPTEST_RNG_SEED")
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(0x6b73_7274_7661_6c69);
    eprintln!("validation fuzz seed {seed} (PROPTEST_RNG_SEED={seed} replays it)");
    proptest::test_runner::Config {
        cases: CASES,
        rng_seed: proptest::test_runner::RngSeed::Fixed(seed),
        failure_persistence: None,
        ..proptest::test_runner::Config::default()
    }
}

proptest! {
    #![proptest_config(config())]

    /// Validation accepts a component exactly when its bytes lie inside its buffers (by the
    /// `u128` oracle), naming a field of the component when it refuses, and copies the span
    /// the oracle computes when it accepts.
    #[test]
    fn geometry_validation_equals_the_wide_arithmetic_oracle(c in case()) {
        match (geometry_input(&input(&c)), oracle(&c)) {
            (Ok(extents), Some((vspan, ispan, triangles))) => {
                prop_assert_eq!(extents.len(), 1);
                prop_assert_eq!(extents[0].vertex_bytes, vspan);
                prop_assert_eq!(extents[0].index_bytes, ispan);
                prop_assert_eq!(extents[0].triangles, triangles);
            }
            (Err(crate::Error::InvalidInput { task, field, .. }), None) => {
                prop_assert_eq!(task, "GeometryTask");
                prop_assert!(field.starts_with("input.components[0]."), "{}", field);
            }
            (got, want) => prop_assert!(false, "validation {:?}, oracle {:?}", got.map(|e| e.len()), want),
        }
    }
}
