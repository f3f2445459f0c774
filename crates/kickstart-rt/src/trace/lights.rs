//! Lights as the shadow passes read them (`TrLight` in `shaders/trace/common.wgsl`).

use crate::tasks::{LightInfo, MAX_MULTI_SHADOW_LIGHTS};
use bytemuck::{Pod, Zeroable};

/// One light in the pass uniform: see `TrLight` for the meaning of each vector.
#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct GpuLight {
    a: [f32; 4],
    b: [f32; 4],
    c: [f32; 4],
}

/// `light` packed. Directions are renormalised (validation allows 1e-3 of slack); a
/// directional light's angular extent becomes the tangent of its half-angle (the radius of the
/// disc its rays are aimed through at unit distance); a spot's apex angle becomes its cosine.
pub(crate) fn pack_light(light: &LightInfo) -> GpuLight {
    match *light {
        LightInfo::Directional {
            direction,
            angular_extent,
        } => GpuLight {
            a: direction
                .normalize()
                .extend((angular_extent * 0.5).tan())
                .to_array(),
            b: [0.0; 4],
            c: [f32::MAX, 0.0, 0.0, 0.0],
        },
        LightInfo::Point {
            position,
            radius,
            range,
        } => GpuLight {
            a: position.extend(radius).to_array(),
            b: [0.0; 4],
            c: [range.min(f32::MAX), 1.0, 0.0, 0.0],
        },
        LightInfo::Spot {
            position,
            direction,
            radius,
            range,
            apex_angle,
        } => GpuLight {
            a: position.extend(radius).to_array(),
            b: direction.normalize().extend(apex_angle.cos()).to_array(),
            c: [range.min(f32::MAX), 2.0, 0.0, 0.0],
        },
    }
}

/// Up to [`MAX_MULTI_SHADOW_LIGHTS`] lights packed (the rest zero; validation caps the count).
pub(crate) fn pack_lights(lights: &[LightInfo]) -> [GpuLight; MAX_MULTI_SHADOW_LIGHTS] {
    let mut out = [GpuLight::default(); MAX_MULTI_SHADOW_LIGHTS];
    for (o, l) in out.iter_mut().zip(lights) {
        *o = pack_light(l);
    }
    out
}

/// Asserts that [`GpuLight`] has the layout of `TrLight` in `module` (a validated pass that
/// includes `shaders/trace/common.wgsl`).
#[cfg(test)]
pub(crate) fn assert_wgsl_layout(module: &naga::Module) {
    crate::gpu::wgsl_check::assert_wgsl_layout!(module, "TrLight", GpuLight { a, b, c });
}
