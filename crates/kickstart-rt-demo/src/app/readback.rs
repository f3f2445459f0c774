//! Reading the renderer's textures back to the CPU, and turning channels into images: display
//! PNGs (tone mapped as the composite does) and linear EXRs.

use crate::app::gpu;
use kickstart_rt_renderer::error::AnyResult;

/// RGBA texels of a `width`×`height` image, row 0 at the top, linear values.
pub struct Texels {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Texels, row-major.
    pub data: Vec<[f32; 4]>,
}

/// An IEEE half to f32 (every finite value, infinities and NaN).
pub fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = (h >> 10) & 0x1f;
    let frac = (h & 0x3ff) as f32;
    sign * match exp {
        0 => frac * 2f32.powi(-24),
        31 if frac == 0.0 => f32::INFINITY,
        31 => f32::NAN,
        e => (1.0 + frac / 1024.0) * 2f32.powi(e as i32 - 15),
    }
}

/// Copies `texture` (`Rgba16Float`, `Rg16Float`, `Rgba8Unorm[Srgb]`, `R32Float`, `Depth32Float`
/// or `Rgba32Float`) to the CPU, blocking until the GPU is done. sRGB texels are returned as
/// their stored (encoded) values / 255.
pub fn read_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
) -> AnyResult<Texels> {
    use wgpu::TextureFormat as F;
    let format = texture.format();
    let bpp: u32 = match format {
        F::Rgba16Float => 8,
        F::Rgba32Float => 16,
        F::Rg16Float | F::Rgba8Unorm | F::Rgba8UnormSrgb | F::R32Float | F::Depth32Float => 4,
        F::Bgra8Unorm | F::Bgra8UnormSrgb => 4,
        other => return Err(format!("cannot read back {other:?} textures").into()),
    };
    let (width, height) = (texture.width(), texture.height());
    let row = width * bpp;
    let padded =
        row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = gpu::readback_buffer(device, padded as u64 * height as u64);
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: None,
            },
        },
        wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
    );
    queue.submit([encoder.finish()]);
    let bytes = gpu::map_read(device, &buffer)?;
    let mut data = Vec::with_capacity((width * height) as usize);
    let half = |b: &[u8], k: usize| f16_to_f32(u16::from_le_bytes([b[2 * k], b[2 * k + 1]]));
    let float = |b: &[u8], k: usize| {
        f32::from_le_bytes([b[4 * k], b[4 * k + 1], b[4 * k + 2], b[4 * k + 3]])
    };
    for y in 0..height as usize {
        let start = y * padded as usize;
        for t in bytes[start..start + row as usize].chunks_exact(bpp as usize) {
            data.push(match format {
                F::Rgba16Float => [half(t, 0), half(t, 1), half(t, 2), half(t, 3)],
                F::Rg16Float => [half(t, 0), half(t, 1), 0.0, 1.0],
                F::Rgba32Float => [float(t, 0), float(t, 1), float(t, 2), float(t, 3)],
                F::R32Float | F::Depth32Float => [float(t, 0), 0.0, 0.0, 1.0],
                F::Bgra8Unorm | F::Bgra8UnormSrgb => {
                    [t[2], t[1], t[0], t[3]].map(|v| v as f32 / 255.0)
                }
                _ => [t[0], t[1], t[2], t[3]].map(|v| v as f32 / 255.0),
            });
        }
    }
    Ok(Texels {
        width,
        height,
        data,
    })
}

/// The composite's tone mapping (fixed exposure, ACES fit) and sRGB encoding, on the CPU, for
/// the channel images.
pub fn display(linear: f32) -> u8 {
    let x = (linear * kickstart_rt_renderer::composite::EXPOSURE).max(0.0);
    let t = ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0);
    let s = if t <= 0.003_130_8 {
        t * 12.92
    } else {
        1.055 * t.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// How a channel's texels become an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// Radiance (RGB): tone mapped like the final image.
    Radiance,
    /// A value in R in 0..=1 (AO, denoised shadow visibility): grey.
    Unit,
    /// The raw shadow trace (R < 0 where the light is visible): white lit, black shadowed.
    ShadowHitDistance,
    /// Display values already (the LDR composite): copied.
    Display,
}

/// An 8-bit RGB image of a channel.
pub fn to_png(t: &Texels, encoding: Encoding) -> image::RgbImage {
    let byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    let mut img = image::RgbImage::new(t.width, t.height);
    for (p, v) in img.pixels_mut().zip(&t.data) {
        p.0 = match encoding {
            Encoding::Radiance => [display(v[0]), display(v[1]), display(v[2])],
            Encoding::Unit => [byte(v[0]); 3],
            Encoding::ShadowHitDistance => [if v[0] < 0.0 { 255 } else { 0 }; 3],
            Encoding::Display => [byte(v[0]), byte(v[1]), byte(v[2])],
        };
    }
    img
}

/// A linear float RGB image of a channel (what `--hdr` writes as EXR): radiance as is, the
/// scalar channels as grey.
pub fn to_hdr(t: &Texels, encoding: Encoding) -> image::Rgb32FImage {
    let mut img = image::Rgb32FImage::new(t.width, t.height);
    for (p, v) in img.pixels_mut().zip(&t.data) {
        p.0 = match encoding {
            Encoding::Radiance | Encoding::Display => [v[0], v[1], v[2]],
            Encoding::Unit => [v[0]; 3],
            Encoding::ShadowHitDistance => [if v[0] < 0.0 { 1.0 } else { 0.0 }; 3],
        };
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halves_decode() {
        assert_eq!(f16_to_f32(0x3c00), 1.0);
        assert_eq!(f16_to_f32(0xc000), -2.0);
        assert_eq!(f16_to_f32(0x0000), 0.0);
        assert_eq!(f16_to_f32(0x7bff), 65504.0);
        assert!((f16_to_f32(0x0001) - 5.96e-8).abs() < 1e-9);
        assert_eq!(f16_to_f32(0x7c00), f32::INFINITY);
        assert!(f16_to_f32(0x7e00).is_nan());
    }

    #[test]
    fn tone_mapping_is_monotonic_from_black_to_white() {
        assert_eq!(display(0.0), 0);
        assert_eq!(display(100.0), 255);
        let mut last = 0;
        for k in 0..100 {
            let v = display(k as f32 * 0.05);
            assert!(v >= last);
            last = v;
        }
    }
}
