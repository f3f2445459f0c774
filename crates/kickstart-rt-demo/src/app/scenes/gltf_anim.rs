//! glTF 2.0 animations into the renderer's model: every channel that drives a node's
//! translation, rotation, scale or morph weights, its sampler's keyframe times and values
//! (floats, or normalised integers for rotations and weights, as the specification allows) and
//! its interpolation (`LINEAR`, `STEP`, `CUBICSPLINE`). Accessors are checked for type and
//! place before they are read; the keys by [`Channel::new`] (times finite and increasing, values
//! finite, a whole number of values a key). An error names the animation, the channel and the
//! rule broken.

use gltf::accessor::{DataType, Dimensions};
use gltf::animation::util::ReadOutputs;
use gltf::animation::{Interpolation as GltfInterpolation, Property as GltfProperty};

use kickstart_rt_renderer::scene::animation::{Animation, Channel, Interpolation, Property};

use super::gltf_accessor::{check_accessor, typed};
use super::gltf_skin::morph_target_count;

/// Every animation of the file.
pub fn read_animations(
    file: &gltf::Document,
    buffers: &[Vec<u8>],
) -> Result<Vec<Animation>, String> {
    file.animations()
        .map(|a| {
            let name = a
                .name()
                .map_or_else(|| format!("animation {}", a.index()), str::to_string);
            let channels = a
                .channels()
                .enumerate()
                .map(|(k, c)| {
                    read_channel(&c, buffers).map_err(|e| {
                        format!(
                            "animation {} ({name}): channel {k} (node {}, {:?}): {e}",
                            a.index(),
                            c.target().node().index(),
                            c.target().property()
                        )
                    })
                })
                .collect::<Result<Vec<_>, String>>()?;
            Ok(Animation { name, channels })
        })
        .collect()
}

/// One channel, checked.
fn read_channel(c: &gltf::animation::Channel, buffers: &[Vec<u8>]) -> Result<Channel, String> {
    let sampler = c.sampler();
    let node = c.target().node();
    let (property, weights) = match c.target().property() {
        GltfProperty::Translation => (Property::Translation, 0),
        GltfProperty::Rotation => (Property::Rotation, 0),
        GltfProperty::Scale => (Property::Scale, 0),
        GltfProperty::MorphTargetWeights => {
            let targets =
                morph_target_count(&node).ok_or("a weights channel on a node without a mesh")?;
            (Property::Weights, targets)
        }
    };
    let input = sampler.input();
    typed(&input, &[DataType::F32], Dimensions::Scalar, false)
        .and_then(|()| check_accessor(&input, buffers))
        .map_err(|e| format!("sampler input: {e}"))?;
    let output = sampler.output();
    let (types, dims): (&[DataType], _) = match property {
        Property::Translation | Property::Scale => (&[DataType::F32], Dimensions::Vec3),
        Property::Rotation => (
            &[
                DataType::F32,
                DataType::I8,
                DataType::U8,
                DataType::I16,
                DataType::U16,
            ],
            Dimensions::Vec4,
        ),
        Property::Weights => (
            &[
                DataType::F32,
                DataType::I8,
                DataType::U8,
                DataType::I16,
                DataType::U16,
            ],
            Dimensions::Scalar,
        ),
    };
    typed(&output, types, dims, true)
        .and_then(|()| check_accessor(&output, buffers))
        .map_err(|e| format!("sampler output: {e}"))?;
    let reader = c.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
    let times: Vec<f32> = reader
        .read_inputs()
        .ok_or("the sampler input's data is out of its buffer")?
        .collect();
    let values: Vec<f32> = match reader
        .read_outputs()
        .ok_or("the sampler output's data is out of its buffer")?
    {
        ReadOutputs::Translations(t) => t.flatten().collect(),
        ReadOutputs::Rotations(r) => r.into_f32().flatten().collect(),
        ReadOutputs::Scales(s) => s.flatten().collect(),
        ReadOutputs::MorphTargetWeights(w) => w.into_f32().collect(),
    };
    let interpolation = match sampler.interpolation() {
        GltfInterpolation::Linear => Interpolation::Linear,
        GltfInterpolation::Step => Interpolation::Step,
        GltfInterpolation::CubicSpline => Interpolation::CubicSpline,
    };
    Channel::new(
        node.index(),
        property,
        interpolation,
        times,
        values,
        weights,
    )
}
