//! Keyframe animations (glTF 2.0's model): channels that drive a node's translation, rotation
//! or scale, or the morph weights of the mesh on it, each sampled with `STEP`, `LINEAR`
//! (rotations: spherical) or `CUBICSPLINE` (Hermite) interpolation.

use glam::{Quat, Vec4};

/// How a channel interpolates between keyframes (glTF `sampler.interpolation`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interpolation {
    /// The previous keyframe's value until the next one.
    Step,
    /// Linear; rotations by spherical linear interpolation.
    Linear,
    /// A cubic Hermite spline: each keyframe stores an in-tangent, the value and an
    /// out-tangent (rotations are normalised after).
    CubicSpline,
}

/// What a channel drives (glTF `channel.target.path`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Property {
    /// The node's translation, 3 values a key.
    Translation,
    /// The node's rotation, a quaternion `x, y, z, w` a key.
    Rotation,
    /// The node's scale, 3 values a key.
    Scale,
    /// The morph weights of the node's mesh, one value a morph target a key.
    Weights,
}

/// One animated property of one node.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// Index into `Scene::nodes` of the node driven.
    pub node: usize,
    /// What of it.
    pub property: Property,
    /// How to interpolate.
    pub interpolation: Interpolation,
    /// Keyframe times, seconds: finite, ≥ 0 and strictly increasing.
    pub times: Vec<f32>,
    /// Keyframe values, flat: `width` a key ([`Interpolation::CubicSpline`]: in-tangent, value,
    /// out-tangent, `3 × width` a key).
    pub values: Vec<f32>,
}

impl Channel {
    /// A checked channel: at least one key, times finite, ≥ 0 and strictly increasing, every
    /// value finite, and a whole number of values a key of the property's width (for weights:
    /// the count of morph targets, `weights`). The error says which rule failed.
    pub fn new(
        node: usize,
        property: Property,
        interpolation: Interpolation,
        times: Vec<f32>,
        values: Vec<f32>,
        weights: usize,
    ) -> Result<Channel, String> {
        if times.is_empty() {
            return Err("no keyframes".into());
        }
        if let Some(t) = times.iter().find(|t| !t.is_finite() || **t < 0.0) {
            return Err(format!("keyframe time {t} is not a finite time ≥ 0"));
        }
        if let Some(k) = times.windows(2).position(|w| w[1] <= w[0]) {
            return Err(format!(
                "keyframe times must increase: {} then {}",
                times[k],
                times[k + 1]
            ));
        }
        if values.iter().any(|v| !v.is_finite()) {
            return Err("a keyframe value is not finite".into());
        }
        let c = Channel {
            node,
            property,
            interpolation,
            times,
            values,
        };
        let width = match property {
            Property::Translation | Property::Scale => 3,
            Property::Rotation => 4,
            Property::Weights => weights,
        };
        let want = c.times.len() * width * c.elements_per_key();
        if width == 0 || c.values.len() != want {
            return Err(format!(
                "{} values for {} keys of {width} ({:?}, {:?}): expected {want}",
                c.values.len(),
                c.times.len(),
                c.property,
                c.interpolation
            ));
        }
        Ok(c)
    }

    /// Values stored a key and component: 3 for a cubic spline's tangents and value, else 1.
    fn elements_per_key(&self) -> usize {
        if self.interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        }
    }

    /// Values a key's value has (3, 4, or the count of morph targets).
    pub fn width(&self) -> usize {
        self.values.len() / (self.times.len() * self.elements_per_key()).max(1)
    }

    /// Time of the last keyframe.
    pub fn end(&self) -> f32 {
        self.times.last().copied().unwrap_or(0.0)
    }

    /// Element `e` (0: in-tangent, 1: value, 2: out-tangent for a cubic spline; else 0) of key
    /// `k`.
    fn element(&self, k: usize, e: usize) -> &[f32] {
        let w = self.width();
        let per = self.elements_per_key();
        let e = if per == 1 { 0 } else { e };
        let at = (k * per + e) * w;
        &self.values[at..at + w]
    }

    /// The value at time `t`: the first key's before it, the last key's after it (glTF's clamp),
    /// interpolated in between.
    pub fn sample(&self, t: f32) -> Vec<f32> {
        let last = self.times.len() - 1;
        let value = |k: usize| self.element(k, 1).to_vec();
        if t <= self.times[0] || last == 0 {
            return value(0);
        }
        if t >= self.times[last] {
            return value(last);
        }
        // The segment [times[k], times[k + 1]) holding t.
        let k = self.times.partition_point(|&x| x <= t) - 1;
        let dt = self.times[k + 1] - self.times[k];
        let s = (t - self.times[k]) / dt;
        let out = match self.interpolation {
            Interpolation::Step => value(k),
            Interpolation::Linear if self.property == Property::Rotation => {
                let q = |k: usize| Quat::from_vec4(Vec4::from_slice(self.element(k, 1)));
                q(k).normalize()
                    .slerp(q(k + 1).normalize(), s)
                    .to_array()
                    .to_vec()
            }
            Interpolation::Linear => {
                let (a, b) = (self.element(k, 1), self.element(k + 1, 1));
                a.iter().zip(b).map(|(a, b)| a + (b - a) * s).collect()
            }
            Interpolation::CubicSpline => {
                let (s2, s3) = (s * s, s * s * s);
                let (h00, h10) = (2.0 * s3 - 3.0 * s2 + 1.0, s3 - 2.0 * s2 + s);
                let (h01, h11) = (-2.0 * s3 + 3.0 * s2, s3 - s2);
                let (v0, b0) = (self.element(k, 1), self.element(k, 2));
                let (v1, a1) = (self.element(k + 1, 1), self.element(k + 1, 0));
                (0..self.width())
                    .map(|i| h00 * v0[i] + h10 * dt * b0[i] + h01 * v1[i] + h11 * dt * a1[i])
                    .collect()
            }
        };
        if self.property == Property::Rotation {
            let q = Quat::from_vec4(Vec4::from_slice(&out)).normalize();
            return q.to_array().to_vec();
        }
        out
    }
}

/// A named set of channels played together.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Animation {
    /// A name for logs.
    pub name: String,
    /// The channels.
    pub channels: Vec<Channel>,
}

impl Animation {
    /// Its length: the last keyframe of any channel, seconds (0 without channels).
    pub fn duration(&self) -> f32 {
        self.channels.iter().map(Channel::end).fold(0.0, f32::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channel(property: Property, interpolation: Interpolation, values: Vec<f32>) -> Channel {
        Channel::new(0, property, interpolation, vec![1.0, 3.0], values, 2)
            .unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn step_and_linear_clamp_outside_the_keys() {
        let c = channel(
            Property::Translation,
            Interpolation::Linear,
            vec![0.0, 0.0, 0.0, 2.0, 4.0, 6.0],
        );
        assert_eq!(c.sample(0.0), vec![0.0; 3]);
        assert_eq!(c.sample(2.0), vec![1.0, 2.0, 3.0]);
        assert_eq!(c.sample(9.0), vec![2.0, 4.0, 6.0]);
        let s = Channel {
            interpolation: Interpolation::Step,
            ..c
        };
        assert_eq!(s.sample(2.9), vec![0.0; 3]);
        assert_eq!(s.sample(3.0), vec![2.0, 4.0, 6.0]);
    }

    #[test]
    fn rotations_slerp_and_weights_have_the_targets_width() {
        let q = Quat::from_rotation_y(1.0);
        let mut v = Quat::IDENTITY.to_array().to_vec();
        v.extend(q.to_array());
        let c = channel(Property::Rotation, Interpolation::Linear, v);
        let half = Quat::from_vec4(Vec4::from_slice(&c.sample(2.0)));
        assert!(half.angle_between(Quat::from_rotation_y(0.5)) < 1e-5);
        let w = channel(
            Property::Weights,
            Interpolation::Linear,
            vec![0.0, 1.0, 1.0, 0.0],
        );
        assert_eq!(w.width(), 2);
        assert_eq!(w.sample(1.5), vec![0.25, 0.75]);
    }

    #[test]
    fn cubic_splines_pass_the_keys_with_their_tangents() {
        // Scalar weight: key 0 value 0, out-tangent 1; key 1 value 1, in-tangent 0 (per second).
        let c = Channel::new(
            0,
            Property::Weights,
            Interpolation::CubicSpline,
            vec![0.0, 2.0],
            vec![9.0, 0.0, 1.0, 0.0, 1.0, 9.0],
            1,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.sample(0.0), vec![0.0]);
        assert_eq!(c.sample(2.0), vec![1.0]);
        // s = 0.5: h00·0 + h10·2·1 + h01·1 + h11·2·0 = 0.125·2 + 0.5.
        assert!((c.sample(1.0)[0] - 0.75).abs() < 1e-6);
    }

    #[test]
    fn bad_channels_are_refused_with_the_rule() {
        let bad = |times: Vec<f32>, values: Vec<f32>| {
            Channel::new(0, Property::Scale, Interpolation::Linear, times, values, 0).unwrap_err()
        };
        assert!(bad(vec![], vec![]).contains("no keyframes"));
        assert!(bad(vec![1.0, 1.0], vec![0.0; 6]).contains("must increase"));
        assert!(bad(vec![f32::NAN], vec![0.0; 3]).contains("finite time"));
        assert!(bad(vec![0.0], vec![f32::NAN; 3]).contains("not finite"));
        assert!(bad(vec![0.0, 1.0], vec![0.0; 5]).contains("expected 6"));
    }
}
