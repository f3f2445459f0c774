//! Cutout materials: a `StandardMaterial` with `AlphaMode::Mask` is traced as the SDK's cutout
//! geometry, its base colour texture's alpha baked into opacity micro-maps when the mesh is
//! registered; every other alpha mode is traced opaque.

use std::collections::HashSet;

use bevy::asset::AssetId;
use bevy::math::Affine2;
use bevy::mesh::{Mesh, MeshVertexAttribute, UvChannel, VertexFormat as BevyVertexFormat};
use bevy::prelude::*;
use bevy::render::mesh::{RenderMesh, RenderMeshBufferInfo};
use bevy::render::render_asset::RenderAssets;
use bevy::render::texture::GpuImage;
use kickstart_rt as ksrt;

/// How an entity's material lets rays through.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum Opacity {
    /// Every ray hits it: opaque, blended and other non-mask materials, and entities without a
    /// `StandardMaterial`.
    Opaque,
    /// `AlphaMode::Mask` with a base colour texture: the texture decides per texel.
    Cutout(Cutout),
    /// `AlphaMode::Mask` whose whole surface is below its cutoff (no texture and too low a
    /// base colour alpha, or a cutoff above 1): no ray hits it, so it is left out.
    Invisible,
}

/// A masked material's test, as the SDK bakes it: `factor × texture alpha ≥ cutoff` is opaque.
/// The floats are kept as bits so that a geometry can be keyed by them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) struct Cutout {
    /// The base colour texture.
    pub image: AssetId<Image>,
    /// Its UV channel (`Mesh::ATTRIBUTE_UV_0` or `_1`).
    pub uv1: bool,
    factor: u32,
    cutoff: u32,
}

impl Cutout {
    /// The material's base colour alpha, which multiplies the texture's.
    pub fn factor(&self) -> f32 {
        f32::from_bits(self.factor)
    }

    /// The mask's cutoff, in 0..=1.
    pub fn cutoff(&self) -> f32 {
        f32::from_bits(self.cutoff)
    }
}

impl Opacity {
    /// What `material` makes of its meshes for rays; `Err` names why a mask is traced opaque
    /// instead (a case the SDK's model does not cover).
    pub fn of(material: &StandardMaterial) -> Result<Opacity, String> {
        match material.alpha_mode {
            AlphaMode::Mask(cutoff) => Self::mask(material, cutoff),
            // Without MSAA, which a ray-traced camera needs off, Bevy draws this as Mask(0.5).
            AlphaMode::AlphaToCoverage => Self::mask(material, 0.5),
            // Blending has no ray-traced counterpart: the surface is traced as it would be
            // opaque (documented).
            _ => Ok(Opacity::Opaque),
        }
    }

    /// Bevy's mask test: transparent where `base_color.a × texture.a < cutoff`.
    fn mask(material: &StandardMaterial, cutoff: f32) -> Result<Opacity, String> {
        let factor = material.base_color.alpha();
        // Comparisons with NaN are false, so Bevy keeps such a surface opaque; a cutoff of 0 or
        // less passes every alpha, one above 1 none.
        if cutoff.is_nan() || !factor.is_finite() || cutoff <= 0.0 {
            return Ok(Opacity::Opaque);
        }
        if cutoff > 1.0 || factor <= 0.0 {
            return Ok(Opacity::Invisible);
        }
        let Some(texture) = &material.base_color_texture else {
            return Ok(if factor >= cutoff {
                Opacity::Opaque
            } else {
                Opacity::Invisible
            });
        };
        if material.uv_transform != Affine2::IDENTITY {
            return Err(format!(
                "its uv_transform ({:?}) is not applied to the traced coordinates",
                material.uv_transform
            ));
        }
        Ok(Opacity::Cutout(Cutout {
            image: texture.id(),
            uv1: material.base_color_channel == UvChannel::Uv1,
            factor: factor.to_bits(),
            cutoff: cutoff.to_bits(),
        }))
    }
}

/// The opacity of each changed material, warning once per material traced opaque against its
/// alpha mode.
pub(crate) fn material_opacity(
    id: AssetId<StandardMaterial>,
    material: &StandardMaterial,
    warned: &mut HashSet<AssetId<StandardMaterial>>,
) -> Opacity {
    Opacity::of(material).unwrap_or_else(|why| {
        if warned.insert(id) {
            warn!("kickstart-rt: material {id:?} is masked but traced opaque: {why}");
        }
        Opacity::Opaque
    })
}

/// The SDK's opacity of `cutout` on a mesh whose vertices start at byte `first_vertex` of
/// `buffer`: `Ok(None)` while Bevy has not uploaded the texture, `Err` when the mesh cannot be
/// traced as a cutout (it is then traced opaque).
pub(crate) fn component_opacity(
    cutout: &Cutout,
    mesh: &RenderMesh,
    buffer: &wgpu::Buffer,
    first_vertex: u64,
    images: &RenderAssets<GpuImage>,
) -> Result<Option<ksrt::ComponentOpacity>, String> {
    let Some(image) = images.get(cutout.image) else {
        return Ok(None);
    };
    let (channel, compressed) = if cutout.uv1 {
        (
            &Mesh::ATTRIBUTE_UV_1,
            bevy::mesh::MeshAttributeCompressionFlags::COMPRESS_UV1,
        )
    } else {
        (
            &Mesh::ATTRIBUTE_UV_0,
            bevy::mesh::MeshAttributeCompressionFlags::COMPRESS_UV0,
        )
    };
    let mesh_layout = &mesh.layout.0;
    if mesh_layout.get_attribute_compression().contains(compressed) {
        // Bevy remaps compressed UVs to the mesh's own range, which the SDK cannot undo.
        return Err("its UVs are compressed (Mesh::compress_uvs)".into());
    }
    let layout = mesh_layout.layout();
    let (offset, format) = attribute(mesh_layout, layout, channel)?;
    let format = match format {
        BevyVertexFormat::Float32x2 => ksrt::UvFormat::Float32x2,
        BevyVertexFormat::Float16x2 => ksrt::UvFormat::Float16x2,
        BevyVertexFormat::Unorm16x2 => ksrt::UvFormat::Unorm16x2,
        other => return Err(format!("UV format {other:?}")),
    };
    let wgpu_texture: &wgpu::Texture = &image.texture;
    let size = wgpu_texture.size();
    if wgpu_texture.dimension() != wgpu::TextureDimension::D2 {
        return Err(format!(
            "its base colour texture is {:?}",
            wgpu_texture.dimension()
        ));
    }
    // The SDK reads mip 0 of a 2D view: layer 0 of an array texture, as Bevy's sampling does.
    let texture = wgpu_texture.create_view(&wgpu::TextureViewDescriptor {
        label: Some("kickstart-rt cutout"),
        dimension: Some(wgpu::TextureViewDimension::D2),
        base_mip_level: 0,
        mip_level_count: Some(1),
        base_array_layer: 0,
        array_layer_count: Some(1),
        ..Default::default()
    });
    let uvs = ksrt::UvBufferInput {
        buffer: buffer.clone(),
        offset: first_vertex + offset,
        stride: layout.array_stride,
        format,
    };
    Ok(Some(ksrt::ComponentOpacity {
        micromap_level: micromap_level(triangles(mesh), size.width, size.height),
        ..ksrt::ComponentOpacity::texture(texture, uvs, cutout.factor(), cutout.cutoff())
    }))
}

/// The mesh's triangle count (a triangle list).
fn triangles(mesh: &RenderMesh) -> u32 {
    match &mesh.buffer_info {
        RenderMeshBufferInfo::Indexed { count, .. } => count / 3,
        RenderMeshBufferInfo::NonIndexed => mesh.vertex_count / 3,
    }
}

/// The micro-map level of a cutout of `triangles` triangles over a `width` × `height` texture:
/// the smallest at which a micro-triangle is no larger than a texel, were the mesh's UVs to
/// cover the texture once (the render world holds no UVs to measure; a texture tiled many times
/// over the mesh gets a coarser map than its texels). At most the SDK's maximum.
pub(crate) fn micromap_level(triangles: u32, width: u32, height: u32) -> u32 {
    let texels = f64::from(width) * f64::from(height) / f64::from(triangles.max(1));
    let max = ksrt::ComponentOpacity::MAX_MICROMAP_LEVEL;
    (0..max)
        .find(|&level| 4f64.powi(level as i32) >= texels)
        .unwrap_or(max)
}

/// Byte offset and format of `attribute` in a Bevy vertex layout.
pub(crate) fn attribute(
    mesh_layout: &bevy::mesh::MeshVertexBufferLayout,
    layout: &bevy::mesh::VertexBufferLayout,
    attribute: &MeshVertexAttribute,
) -> Result<(u64, BevyVertexFormat), String> {
    let slot = mesh_layout
        .attribute_ids()
        .iter()
        .position(|id| *id == attribute.id)
        .ok_or_else(|| format!("it has no {} attribute", attribute.name))?;
    let found = layout
        .attributes
        .get(slot)
        .ok_or("its layout lists fewer attributes than ids")?;
    Ok((found.offset, found.format))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn masked(alpha: f32, cutoff: f32, texture: bool) -> StandardMaterial {
        StandardMaterial {
            base_color: Color::linear_rgba(1.0, 1.0, 1.0, alpha),
            alpha_mode: AlphaMode::Mask(cutoff),
            base_color_texture: texture.then(Handle::<Image>::default),
            ..default()
        }
    }

    #[test]
    fn bevy_alpha_modes_map_to_the_sdks_opacity() {
        let opaque = StandardMaterial::default();
        assert_eq!(Opacity::of(&opaque), Ok(Opacity::Opaque));
        for mode in [AlphaMode::Blend, AlphaMode::Premultiplied, AlphaMode::Add] {
            let blended = StandardMaterial {
                alpha_mode: mode,
                ..masked(0.1, 0.5, true)
            };
            assert_eq!(Opacity::of(&blended), Ok(Opacity::Opaque), "{mode:?}");
        }
        // Without a texture, the base colour's alpha alone passes or fails the mask.
        assert_eq!(Opacity::of(&masked(0.6, 0.5, false)), Ok(Opacity::Opaque));
        assert_eq!(
            Opacity::of(&masked(0.4, 0.5, false)),
            Ok(Opacity::Invisible)
        );
        // A cutoff Bevy passes everywhere or nowhere.
        assert_eq!(Opacity::of(&masked(0.1, 0.0, true)), Ok(Opacity::Opaque));
        assert_eq!(
            Opacity::of(&masked(0.1, f32::NAN, true)),
            Ok(Opacity::Opaque)
        );
        assert_eq!(Opacity::of(&masked(1.0, 1.5, true)), Ok(Opacity::Invisible));
        // With a texture: the SDK's test with the factor and cutoff.
        let Ok(Opacity::Cutout(c)) = Opacity::of(&masked(0.8, 0.25, true)) else {
            panic!("a textured mask is a cutout");
        };
        assert_eq!((c.factor(), c.cutoff(), c.uv1), (0.8, 0.25, false));
        let coverage = StandardMaterial {
            alpha_mode: AlphaMode::AlphaToCoverage,
            ..masked(1.0, 0.9, true)
        };
        let Ok(Opacity::Cutout(c)) = Opacity::of(&coverage) else {
            panic!("alpha to coverage without MSAA is a mask");
        };
        assert_eq!(c.cutoff(), 0.5);
        // A texture transform the SDK would not apply: refused (traced opaque).
        let transformed = StandardMaterial {
            uv_transform: Affine2::from_scale(Vec2::splat(2.0)),
            ..masked(1.0, 0.5, true)
        };
        assert!(
            Opacity::of(&transformed)
                .unwrap_err()
                .contains("uv_transform")
        );
    }

    #[test]
    fn micromap_level_gives_a_micro_triangle_per_texel() {
        // A two-triangle card over 64 × 64 texels: 2048 texels a triangle → level 6 (4096).
        assert_eq!(micromap_level(2, 64, 64), 6);
        // 8 × 8 texels on two triangles: 32 → level 3 (64).
        assert_eq!(micromap_level(2, 8, 8), 3);
        // Many triangles on a small texture: level 0; a huge texture: the SDK's maximum.
        assert_eq!(micromap_level(10_000, 16, 16), 0);
        assert_eq!(micromap_level(2, 4096, 4096), 6);
        assert_eq!(micromap_level(0, 4, 4), 2);
    }
}
