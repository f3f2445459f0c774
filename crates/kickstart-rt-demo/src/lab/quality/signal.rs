//! The signals `ksrt quality` measures, and what each needs to know about itself: which SDK
//! outputs hold it, how its reference samples are summed, how a pixel becomes one linear scalar
//! (for the energy ratio and the flicker) and how it becomes 8-bit (for PSNR and FLIP).

use super::accumulate::SampleKind;
use super::linear::luminance;
use super::metrics::{self, Srgb8};
use kickstart_rt_renderer::frame::{Produced, SdkOutputs};

/// One signal the yardstick measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Signal {
    /// Diffuse GI (incoming radiance).
    Diffuse,
    /// Reflections at roughness [`super::run::SPECULAR_ROUGHNESS`] (incoming radiance).
    Specular,
    /// Ambient occlusion: the closest hit distance over the AO radius, 1 unoccluded.
    Ao,
    /// The main light's shadow (visibility).
    Shadow,
}

impl Signal {
    /// Its name in the report and the file names.
    pub fn name(self) -> &'static str {
        match self {
            Signal::Diffuse => "diffuse",
            Signal::Specular => "specular",
            Signal::Ao => "ao",
            Signal::Shadow => "shadow",
        }
    }

    /// The signals a frame that produced `produced` can be measured on, in report order: diffuse
    /// and specular always (the caller checks they were traced and denoised), AO and the shadow
    /// where they were traced and denoised (the shadow needs a light, the SDK may refuse AO).
    pub fn measured(produced: Produced) -> Vec<Signal> {
        let mut signals = vec![Signal::Diffuse, Signal::Specular];
        if produced.ao.1 {
            signals.push(Signal::Ao);
        }
        if produced.shadow.1 {
            signals.push(Signal::Shadow);
        }
        signals
    }

    /// Its raw (1-spp) and denoised SDK outputs.
    pub fn outputs(self, o: &SdkOutputs) -> (&wgpu::Texture, &wgpu::Texture) {
        match self {
            Signal::Diffuse => (&o.diffuse, &o.diffuse_denoised),
            Signal::Specular => (&o.specular, &o.specular_denoised),
            Signal::Ao => (&o.ao, &o.ao_denoised),
            Signal::Shadow => (&o.shadow, &o.shadow_denoised),
        }
    }

    /// How its reference sums the raw output's samples.
    pub fn sample_kind(self) -> SampleKind {
        match self {
            Signal::Diffuse | Signal::Specular => SampleKind::Radiance,
            Signal::Ao => SampleKind::Scalar,
            Signal::Shadow => SampleKind::ShadowHitDistance,
        }
    }

    /// A raw output texel as the linear RGB the reference averages (what
    /// [`Self::sample_kind`] sums): radiance as is, the AO value and the shadow's visibility
    /// (1 where the hit distance is negative, i.e. the light is visible) in every channel.
    pub fn raw_texel(self, t: [f32; 4]) -> [f32; 3] {
        match self {
            Signal::Diffuse | Signal::Specular => [t[0], t[1], t[2]],
            Signal::Ao => [t[0]; 3],
            Signal::Shadow => [if t[0] < 0.0 { 1.0 } else { 0.0 }; 3],
        }
    }

    /// A denoised output texel as linear RGB: radiance as is, the scalar (R) in every channel.
    pub fn denoised_texel(self, t: [f32; 4]) -> [f32; 3] {
        match self {
            Signal::Diffuse | Signal::Specular => [t[0], t[1], t[2]],
            Signal::Ao | Signal::Shadow => [t[0]; 3],
        }
    }

    /// The linear scalar of one pixel that the energy ratio and the flicker compare: luminance
    /// of radiance, the value itself of AO and shadow visibility.
    pub fn scalar(self, rgb: [f32; 3]) -> f32 {
        match self {
            Signal::Diffuse | Signal::Specular => luminance(rgb),
            Signal::Ao | Signal::Shadow => rgb[0],
        }
    }

    /// Every pixel's [`Self::scalar`].
    pub fn scalars(self, rgb: &[[f32; 3]]) -> Vec<f32> {
        rgb.iter().map(|&p| self.scalar(p)).collect()
    }

    /// The 8-bit image PSNR and FLIP compare: radiance tone mapped ([`metrics::tone_map`]), AO
    /// and shadow visibility (values in 0..=1) mapped linearly to 0–255 grey.
    pub fn encode(self, width: u32, height: u32, rgb: &[[f32; 3]]) -> Srgb8 {
        match self {
            Signal::Diffuse | Signal::Specular => metrics::tone_map(width, height, rgb),
            Signal::Ao | Signal::Shadow => unit_image(width, height, rgb),
        }
    }
}

/// An image of values in 0..=1 per pixel as 8-bit grey, linearly.
fn unit_image(width: u32, height: u32, values: &[[f32; 3]]) -> Srgb8 {
    Srgb8 {
        width,
        height,
        pixels: values
            .iter()
            .map(|v| [(v[0].clamp(0.0, 1.0) * 255.0).round() as u8; 3])
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raw_texels_become_what_the_reference_averages() {
        assert_eq!(
            Signal::Diffuse.raw_texel([0.5, 1.0, 2.0, 9.0]),
            [0.5, 1.0, 2.0]
        );
        assert_eq!(Signal::Ao.raw_texel([0.25, 0.25, 0.25, 0.25]), [0.25; 3]);
        assert_eq!(Signal::Shadow.raw_texel([-1.0, 0.0, 0.0, 0.0]), [1.0; 3]);
        assert_eq!(Signal::Shadow.raw_texel([3.0, 0.0, 0.0, 0.0]), [0.0; 3]);
        assert_eq!(Signal::Ao.denoised_texel([0.75, 0.1, 0.2, 0.3]), [0.75; 3]);
    }

    #[test]
    fn scalars_are_luminance_of_radiance_and_the_value_of_ao_and_shadow() {
        assert!((Signal::Specular.scalar([1.0, 0.0, 0.0]) - 0.2126).abs() < 1e-6);
        assert!((Signal::Diffuse.scalar([0.0, 2.0, 0.0]) - 2.0 * 0.7152).abs() < 1e-6);
        assert_eq!(Signal::Ao.scalar([0.3, 0.9, 0.9]), 0.3);
        let img = Signal::Ao.encode(2, 1, &[[0.5; 3], [2.0; 3]]);
        assert_eq!(img.pixels, [[128; 3], [255; 3]]);
    }

    #[test]
    fn ao_and_the_shadow_are_measured_only_where_traced_and_denoised() {
        let all = Produced {
            specular: (true, true),
            diffuse: (true, true),
            ao: (true, true),
            shadow: (true, true),
        };
        assert_eq!(
            Signal::measured(all),
            [
                Signal::Diffuse,
                Signal::Specular,
                Signal::Ao,
                Signal::Shadow
            ]
        );
        let no_ao_denoiser = Produced {
            ao: (true, false),
            shadow: (false, false),
            ..all
        };
        assert_eq!(
            Signal::measured(no_ao_denoiser),
            [Signal::Diffuse, Signal::Specular]
        );
    }
}
