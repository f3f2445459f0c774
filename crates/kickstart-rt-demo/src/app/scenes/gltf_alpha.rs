//! A glTF material's alpha (`alphaMode`, `alphaCutoff`, `baseColorFactor.a`) and the texture
//! coordinates its base colour texture reads (`texCoord` and `KHR_texture_transform`): what makes
//! a cutout, and where its texels lie on the mesh.

use kickstart_rt_renderer::scene::AlphaMode;

/// The name of material `m` in errors and logs: its index and name, or the default material.
pub fn material_name(m: &gltf::Material) -> String {
    match (m.index(), m.name()) {
        (Some(k), Some(name)) => format!("material {k} ({name:?})"),
        (Some(k), None) => format!("material {k}"),
        (None, _) => "the default material".to_string(),
    }
}

/// The alpha mode of material `m`. A `MASK`'s cutoff (default 0.5) and factor are checked by
/// [`mask_mode`].
pub fn alpha_mode(m: &gltf::Material) -> Result<AlphaMode, String> {
    Ok(match m.alpha_mode() {
        gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
        gltf::material::AlphaMode::Blend => AlphaMode::Blend,
        gltf::material::AlphaMode::Mask => mask_mode(
            &material_name(m),
            m.pbr_metallic_roughness().base_color_factor()[3],
            m.alpha_cutoff().unwrap_or(0.5),
        )?,
    })
}

/// A `MASK` material's mode, refused (naming the material `name`) unless the cutoff is in 0..=1
/// (glTF's own range, and what the SDK takes) and the factor finite and ≥ 0: a NaN would make
/// every texel's comparison false, so the mesh would vanish without a word, and the SDK refuses
/// both, which would end the render later without naming the file.
pub fn mask_mode(name: &str, factor: f32, cutoff: f32) -> Result<AlphaMode, String> {
    // Written so that NaN fails too.
    if !(0.0..=1.0).contains(&cutoff) {
        return Err(format!(
            "{name}: alphaCutoff {cutoff} must be in 0..=1 (alphaMode MASK)"
        ));
    }
    if !(factor.is_finite() && factor >= 0.0) {
        return Err(format!(
            "{name}: baseColorFactor alpha {factor} must be finite and ≥ 0 (alphaMode MASK)"
        ));
    }
    Ok(AlphaMode::Mask { factor, cutoff })
}

/// `KHR_texture_transform` on a texture reference: `uv' = offset + R(rotation) · (scale ⊙ uv)`,
/// the extension's `translation * rotation * scale` matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UvTransform {
    /// Added last.
    pub offset: [f32; 2],
    /// Radians; the extension's matrix has columns (cos, sin) and (−sin, cos).
    pub rotation: f32,
    /// Applied first, per component.
    pub scale: [f32; 2],
}

impl UvTransform {
    /// The transformed coordinates of `uv`.
    pub fn apply(&self, [u, v]: [f32; 2]) -> [f32; 2] {
        let (sin, cos) = self.rotation.sin_cos();
        let (x, y) = (u * self.scale[0], v * self.scale[1]);
        [
            self.offset[0] + cos * x - sin * y,
            self.offset[1] + sin * x + cos * y,
        ]
    }
}

/// The coordinate set the base colour texture of `m` reads (its `texCoord`, or the extension's
/// override) and its `KHR_texture_transform`, if any. Set 0 without a texture.
pub fn base_color_coordinates(m: &gltf::Material) -> (u32, Option<UvTransform>) {
    let Some(info) = m.pbr_metallic_roughness().base_color_texture() else {
        return (0, None);
    };
    match info.texture_transform() {
        Some(t) => (
            t.tex_coord().unwrap_or(info.tex_coord()),
            Some(UvTransform {
                offset: t.offset(),
                rotation: t.rotation(),
                scale: t.scale(),
            }),
        ),
        None => (info.tex_coord(), None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mask_outside_its_ranges_is_refused_by_name() {
        for cutoff in [-0.1, 1.5, f32::NAN, f32::INFINITY] {
            let e = mask_mode("material 2 (\"leaves\")", 1.0, cutoff).unwrap_err();
            assert!(
                e.contains("material 2 (\"leaves\")") && e.contains("alphaCutoff"),
                "{cutoff}: {e}"
            );
        }
        for factor in [-0.5, f32::NAN, f32::INFINITY] {
            let e = mask_mode("material 0", factor, 0.5).unwrap_err();
            assert!(e.contains("material 0: baseColorFactor alpha"), "{e}");
        }
        assert_eq!(
            mask_mode("m", 0.8, 0.0),
            Ok(AlphaMode::Mask {
                factor: 0.8,
                cutoff: 0.0
            })
        );
    }

    #[test]
    fn texture_transforms_scale_then_rotate_then_offset() {
        let t = UvTransform {
            offset: [0.5, 0.25],
            rotation: std::f32::consts::FRAC_PI_2,
            scale: [2.0, 3.0],
        };
        // (1, 1) → scaled (2, 3) → turned a quarter: (−3, 2) → offset (−2.5, 2.25).
        let [u, v] = t.apply([1.0, 1.0]);
        assert!((u + 2.5).abs() < 1e-5 && (v - 2.25).abs() < 1e-5, "{u} {v}");
    }
}
