//! How a photo's pixels become the model's input, and how its output becomes probabilities:
//! channel order, value range, mean and standard deviation per channel, and the output's
//! activation. The defaults are the shared crack model's (`crack_unet_crackpot/SOURCE.md`: RGB in
//! [0, 1], its output already a probability); an ImageNet-normalised model is
//! `--range 1 --mean 0.485,0.456,0.406 --std 0.229,0.224,0.225`, a Caffe-style one
//! `--channels bgr --range 255 --mean 103.94,116.78,123.68`.

use serde::{Deserialize, Serialize};

use crate::segment::SegmentError;

/// The order of the colour planes the model expects.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ChannelOrder {
    #[default]
    Rgb,
    /// OpenCV's order (models trained on `cv2.imread` without a conversion).
    Bgr,
}

impl std::str::FromStr for ChannelOrder {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text.to_ascii_lowercase().as_str() {
            "rgb" => Ok(ChannelOrder::Rgb),
            "bgr" => Ok(ChannelOrder::Bgr),
            _ => Err(format!("unknown channel order {text:?}: use rgb or bgr")),
        }
    }
}

/// What turns the model's output channels into probabilities.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    /// The output already is a probability per channel (a sigmoid inside the model).
    #[default]
    None,
    /// Logits, one independent probability per channel.
    Sigmoid,
    /// Logits of mutually exclusive classes (a background channel among them): softmax over
    /// the channels at each pixel.
    Softmax,
}

impl std::str::FromStr for Activation {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text.to_ascii_lowercase().as_str() {
            "none" => Ok(Activation::None),
            "sigmoid" => Ok(Activation::Sigmoid),
            "softmax" => Ok(Activation::Softmax),
            _ => Err(format!(
                "unknown activation {text:?}: use none, sigmoid or softmax"
            )),
        }
    }
}

/// A photo's pixel `p` (RGB in [0, 1]) enters the model as `(p · range − mean) / std` per
/// channel, in `order`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Preprocess {
    pub order: ChannelOrder,
    /// 1 for inputs in [0, 1], 255 for inputs in [0, 255].
    pub range: f32,
    /// Per channel, in the model's order.
    pub mean: [f32; 3],
    /// Per channel, in the model's order; each above 0.
    pub std: [f32; 3],
    pub activation: Activation,
}

impl Default for Preprocess {
    /// The shared crack model's: RGB in [0, 1], no normalisation, probabilities out.
    fn default() -> Self {
        Preprocess {
            order: ChannelOrder::Rgb,
            range: 1.0,
            mean: [0.0; 3],
            std: [1.0; 3],
            activation: Activation::None,
        }
    }
}

impl Preprocess {
    /// A range and standard deviations that can divide: finite, above zero.
    pub fn check(&self) -> Result<(), SegmentError> {
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
        if !(self.range > 0.0) || !finite(&[self.range]) {
            return Err(SegmentError::Settings(format!(
                "the input range must be above 0, not {}",
                self.range
            )));
        }
        if !finite(&self.mean) || !self.std.iter().all(|&s| s > 0.0 && s.is_finite()) {
            return Err(SegmentError::Settings(format!(
                "mean {:?} and std {:?}: every value finite, every std above 0",
                self.mean, self.std
            )));
        }
        Ok(())
    }

    /// The model's three input values for photo pixel `rgb`.
    pub fn input(&self, rgb: [f32; 3]) -> [f32; 3] {
        let ordered = match self.order {
            ChannelOrder::Rgb => rgb,
            ChannelOrder::Bgr => [rgb[2], rgb[1], rgb[0]],
        };
        std::array::from_fn(|c| (ordered[c] * self.range - self.mean[c]) / self.std[c])
    }

    /// The probabilities of one pixel's output `values` (one per channel), in place.
    pub fn activate(&self, values: &mut [f32]) {
        match self.activation {
            Activation::None => {}
            Activation::Sigmoid => {
                for v in values.iter_mut() {
                    *v = 1.0 / (1.0 + (-*v).exp());
                }
            }
            Activation::Softmax => {
                let max = values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                let mut sum = 0.0;
                for v in values.iter_mut() {
                    *v = (*v - max).exp();
                    sum += *v;
                }
                if sum > 0.0 {
                    for v in values.iter_mut() {
                        *v /= sum;
                    }
                }
            }
        }
    }
}

/// Parses `a,b,c` (three numbers), for `--mean` and `--std`.
pub fn parse_triple(text: &str) -> Result<[f32; 3], String> {
    let parts: Vec<f32> = text
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("bad value {text:?}: use three numbers a,b,c"))?;
    match parts[..] {
        [a, b, c] => Ok([a, b, c]),
        _ => Err(format!("bad value {text:?}: use three numbers a,b,c")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_feeds_rgb_in_zero_one() {
        assert_eq!(
            Preprocess::default().input([0.1, 0.2, 0.3]),
            [0.1, 0.2, 0.3]
        );
    }

    #[test]
    fn bgr_range_and_normalisation_apply_in_the_models_order() {
        let caffe = Preprocess {
            order: ChannelOrder::Bgr,
            range: 255.0,
            mean: [100.0, 110.0, 120.0],
            std: [2.0, 1.0, 1.0],
            ..Preprocess::default()
        };
        let v = caffe.input([1.0, 0.5, 0.0]);
        assert_eq!(v, [(0.0 - 100.0) / 2.0, 127.5 - 110.0, 255.0 - 120.0]);
    }

    #[test]
    fn softmax_sums_to_one_and_sigmoid_maps_zero_to_a_half() {
        let mut logits = [1.0, 2.0, 3.0];
        Preprocess {
            activation: Activation::Softmax,
            ..Preprocess::default()
        }
        .activate(&mut logits);
        assert!((logits.iter().sum::<f32>() - 1.0).abs() < 1e-6 && logits[2] > logits[1]);
        let mut zero = [0.0];
        Preprocess {
            activation: Activation::Sigmoid,
            ..Preprocess::default()
        }
        .activate(&mut zero);
        assert_eq!(zero, [0.5]);
    }

    #[test]
    fn a_zero_std_and_a_bad_triple_are_refused() {
        let bad = Preprocess {
            std: [1.0, 0.0, 1.0],
            ..Preprocess::default()
        };
        assert!(bad.check().is_err());
        assert!(parse_triple("1,2").is_err() && parse_triple("1,x,3").is_err());
        assert_eq!(parse_triple("0.5, 1, 2"), Ok([0.5, 1.0, 2.0]));
    }
}
