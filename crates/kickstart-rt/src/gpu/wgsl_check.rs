//! CPU-only checks of composed WGSL (tests only): [`validate`] parses and validates a shader
//! variant with naga, as the device would, and [`assert_wgsl_layout!`] checks a Rust
//! `#[repr(C)]` uniform/storage struct against the WGSL struct it mirrors (size, and the offset
//! of every member). A pass module enumerates the variants it can create and runs both, so a
//! shader edit that breaks a variant, or a Rust struct that drifts from its WGSL twin, fails
//! `cargo test` without a GPU.

use naga::valid::{Capabilities, ValidationFlags, Validator};

/// The capabilities a shader may use: those wgpu grants a WebGPU-compliant adapter without any
/// optional feature (`wgpu-naga-bridge`'s `features_to_naga_capabilities` of
/// `device::required_features()`, which is empty, and `DownlevelFlags::compliant()`). The
/// denoisers' records need `SHADER_FLOAT16_IN_FLOAT32` (`pack2x16float`/`unpack2x16float`).
const CAPABILITIES: Capabilities = Capabilities::SHADER_FLOAT16_IN_FLOAT32
    .union(Capabilities::MULTISAMPLED_SHADING)
    .union(Capabilities::CUBE_ARRAY_TEXTURES);

/// Parses and validates `source` (variant `label`) with naga and every validation flag; panics
/// naming the variant and naga's message with its source location.
pub(crate) fn validate(label: &str, source: &str) -> naga::Module {
    validate_for(label, source, wgpu::Features::empty())
}

/// As [`validate`], for a variant that needs the device `features` (ray queries: the hardware
/// backend's tracing passes), with the capabilities wgpu grants for them.
pub(crate) fn validate_for(label: &str, source: &str, features: wgpu::Features) -> naga::Module {
    let mut capabilities = CAPABILITIES;
    if features.contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY) {
        capabilities |= Capabilities::RAY_QUERY;
    }
    let module = match naga::front::wgsl::parse_str(source) {
        Ok(m) => m,
        Err(e) => panic!(
            "{label}: WGSL does not parse:\n{}",
            e.emit_to_string_with_path(source, label)
        ),
    };
    if let Err(e) = Validator::new(ValidationFlags::all(), capabilities).validate(&module) {
        panic!(
            "{label}: WGSL does not validate:\n{}",
            e.emit_to_string_with_path(source, label)
        );
    }
    module
}

/// One field of a Rust struct as [`assert_layout`] sees it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RustField {
    /// The Rust field's name.
    pub name: &'static str,
    /// The WGSL member it mirrors (the member starting at the same offset).
    pub wgsl: &'static str,
    pub offset: usize,
    pub size: usize,
}

/// The WGSL struct `name` of `module`: its members (name, offset, size) and its span.
fn wgsl_struct(module: &naga::Module, name: &str) -> (Vec<(String, u32, u32)>, u32) {
    let found = module
        .types
        .iter()
        .find(|(_, ty)| ty.name.as_deref() == Some(name));
    let Some((_, ty)) = found else {
        panic!("no WGSL struct {name} in the module");
    };
    let naga::TypeInner::Struct { members, span } = &ty.inner else {
        panic!("WGSL type {name} is not a struct");
    };
    let gctx = module.to_ctx();
    let members = members
        .iter()
        .map(|m| {
            (
                m.name.clone().unwrap_or_default(),
                m.offset,
                module.types[m.ty].inner.size(gctx),
            )
        })
        .collect();
    (members, *span)
}

/// Asserts that the Rust struct `rust` (`size` bytes, `fields` all its fields) has the layout of
/// the WGSL struct `wgsl` of `module`: the same size; each Rust field at the offset of the WGSL
/// member it names; and every WGSL member inside one Rust field (so a Rust array such as
/// `jitter: [f32; 2]` may stand for the WGSL members `jitter_x`, `jitter_y`).
pub(crate) fn assert_layout(
    module: &naga::Module,
    wgsl: &str,
    rust: &str,
    size: usize,
    fields: &[RustField],
) {
    let (members, span) = wgsl_struct(module, wgsl);
    assert_eq!(
        span as usize, size,
        "WGSL {wgsl} is {span} bytes, Rust {rust} {size}"
    );
    for f in fields {
        let Some((_, offset, _)) = members.iter().find(|(n, _, _)| n == f.wgsl) else {
            panic!(
                "Rust {rust}.{}: WGSL {wgsl} has no member {}",
                f.name, f.wgsl
            );
        };
        assert_eq!(
            *offset as usize, f.offset,
            "Rust {rust}.{} is at byte {}, WGSL {wgsl}.{} at {offset}",
            f.name, f.offset, f.wgsl
        );
    }
    for (name, offset, member_size) in &members {
        let (start, end) = (*offset as usize, (offset + member_size) as usize);
        let inside = fields
            .iter()
            .any(|f| f.offset <= start && end <= f.offset + f.size);
        assert!(
            inside,
            "WGSL {wgsl}.{name} (bytes {start}..{end}) lies in no single field of Rust {rust}"
        );
    }
}

/// The size of the field `project` reads (for [`assert_wgsl_layout!`]).
pub(crate) fn field_size<T, F>(_project: fn(&T) -> &F) -> usize {
    std::mem::size_of::<F>()
}

/// The element stride of the runtime-sized storage array bound as the global `name` of
/// `module` (a record layout the Rust side sizes buffers by).
pub(crate) fn storage_stride(module: &naga::Module, name: &str) -> u32 {
    let Some((_, var)) = module
        .global_variables
        .iter()
        .find(|(_, v)| v.name.as_deref() == Some(name))
    else {
        panic!("no WGSL global {name} in the module");
    };
    match module.types[var.ty].inner {
        naga::TypeInner::Array { stride, .. } => stride,
        ref other => panic!("WGSL global {name} is not an array: {other:?}"),
    }
}

/// The value of the WGSL `const NAME: u32` of `module` (a constant the Rust side mirrors).
pub(crate) fn const_u32(module: &naga::Module, name: &str) -> u32 {
    let Some((_, c)) = module
        .constants
        .iter()
        .find(|(_, c)| c.name.as_deref() == Some(name))
    else {
        panic!("no WGSL const {name} in the module");
    };
    match module.global_expressions[c.init] {
        naga::Expression::Literal(naga::Literal::U32(v)) => v,
        ref other => panic!("WGSL const {name} is not a u32 literal: {other:?}"),
    }
}

/// `assert_wgsl_layout!(module, "WgslName", RustType { field, other => "wgsl_member", … })`:
/// checks `RustType` against the WGSL struct `WgslName` of the validated `module` (see
/// [`assert_layout`]). Every field of `RustType` must be listed (the macro destructures the type
/// without `..`, so a new Rust field that is not mapped fails to compile); a field mirrors the
/// WGSL member of its own name unless `=> "name"` says otherwise.
macro_rules! assert_wgsl_layout {
    ($module:expr, $wgsl:literal, $ty:ident { $($field:ident $(=> $member:literal)?),+ $(,)? }) => {{
        #[allow(dead_code)]
        fn every_field_is_listed(v: &$ty) {
            let $ty { $($field: _),+ } = v;
        }
        $crate::gpu::wgsl_check::assert_layout(
            &$module,
            $wgsl,
            stringify!($ty),
            ::std::mem::size_of::<$ty>(),
            &[$($crate::gpu::wgsl_check::RustField {
                name: stringify!($field),
                wgsl: $crate::gpu::wgsl_check::wgsl_member!($field $(, $member)?),
                offset: ::std::mem::offset_of!($ty, $field),
                size: $crate::gpu::wgsl_check::field_size(|v: &$ty| &v.$field),
            }),+],
        )
    }};
}

/// The WGSL member a Rust field mirrors: its own name, or the one given.
macro_rules! wgsl_member {
    ($field:ident) => {
        stringify!($field)
    };
    ($field:ident, $member:literal) => {
        $member
    };
}

pub(crate) use assert_wgsl_layout;
pub(crate) use wgsl_member;

#[cfg(test)]
mod tests {
    use super::*;

    const SOURCE: &str = "
        struct Params {
            a: vec4<f32>,
            count: u32,
            scale_x: f32,
            scale_y: f32,
            pad0: u32,
        }
        @group(0) @binding(0) var<uniform> params: Params;
        @group(0) @binding(1) var<storage, read_write> out: array<vec2<u32>>;
        @compute @workgroup_size(1)
        fn main() {
            out[0] = vec2<u32>(params.count, u32(params.a.x * params.scale_x * params.scale_y));
        }
    ";

    #[repr(C)]
    struct Params {
        a: [f32; 4],
        count: u32,
        scale: [f32; 2],
        pad: u32,
    }

    /// `Params` with two fields swapped.
    #[repr(C)]
    struct Swapped {
        a: [f32; 4],
        scale: [f32; 2],
        count: u32,
        pad: u32,
    }

    /// `Params` without its padding.
    #[repr(C)]
    struct Short {
        a: [f32; 4],
        count: u32,
        scale: [f32; 2],
    }

    #[test]
    fn a_matching_struct_passes_with_renamed_members() {
        let module = validate("test", SOURCE);
        assert_wgsl_layout!(module, "Params", Params { a, count, scale => "scale_x", pad => "pad0" });
        assert_eq!(storage_stride(&module, "out"), 8);
        assert_eq!(const_u32(&validate("const", "const N: u32 = 7u;"), "N"), 7);
    }

    #[test]
    #[should_panic(expected = "Rust Swapped.scale is at byte 16, WGSL Params.scale_x at 20")]
    fn swapped_fields_fail() {
        let module = validate("test", SOURCE);
        assert_wgsl_layout!(module, "Params", Swapped { a, scale => "scale_x", count, pad => "pad0" });
    }

    #[test]
    #[should_panic(expected = "WGSL Params is 32 bytes, Rust Short 28")]
    fn a_missing_field_fails() {
        let module = validate("test", SOURCE);
        assert_wgsl_layout!(module, "Params", Short { a, count, scale => "scale_x" });
    }

    #[test]
    #[should_panic(expected = "WGSL Params has no member pad")]
    fn an_unmapped_rename_fails() {
        let module = validate("test", SOURCE);
        assert_wgsl_layout!(module, "Params", Params { a, count, scale => "scale_x", pad });
    }

    #[test]
    #[should_panic(expected = "broken variant: WGSL does not validate")]
    fn a_type_error_names_the_variant() {
        validate(
            "broken variant",
            &SOURCE.replace("params.count,", "params.scale_x,"),
        );
    }

    #[test]
    #[should_panic(expected = "broken variant: WGSL does not parse")]
    fn a_syntax_error_names_the_variant() {
        validate("broken variant", &SOURCE.replace("fn main()", "fn main("));
    }
}
