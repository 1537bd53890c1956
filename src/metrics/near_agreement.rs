//! Agreement of thin structures (cracks) with a distance tolerance: a predicted pixel is right
//! when a reference pixel lies within `radius` pixels of it (Chebyshev: the `2r+1` square), a
//! reference pixel is found when a predicted one lies within `radius`. A crack traced one pixel
//! off its annotation is neither a miss nor a false alarm, as crack-detection papers count (and
//! as `crack_unet_crackpot/SOURCE.md`'s "within 2 px" figures do: its 0.76 / 0.73 are per-image
//! means of these with radius 2).

use crate::metrics::mask_agreement::ratio_or_one;
use serde::{Deserialize, Serialize};

/// Counts of one or more mask pairs; add them with `add`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct NearAgreement {
    pub predicted: u64,
    pub predicted_near_reference: u64,
    pub reference: u64,
    pub reference_near_predicted: u64,
}

/// `mask` (row-major, `width × height`, non-zero = set) grown by `radius` in every direction
/// (a square: a row pass then a column pass).
fn dilate(mask: &[bool], width: usize, height: usize, radius: usize) -> Vec<bool> {
    let mut rows = vec![false; mask.len()];
    for y in 0..height {
        let row = &mask[y * width..(y + 1) * width];
        for x in 0..width {
            let (a, b) = (x.saturating_sub(radius), (x + radius).min(width - 1));
            rows[y * width + x] = row[a..=b].iter().any(|&v| v);
        }
    }
    let mut out = vec![false; mask.len()];
    for x in 0..width {
        for y in 0..height {
            let (a, b) = (y.saturating_sub(radius), (y + radius).min(height - 1));
            out[y * width + x] = (a..=b).any(|yy| rows[yy * width + x]);
        }
    }
    out
}

impl NearAgreement {
    /// Counts one mask pair of `width × height` (equal lengths).
    pub fn measure(
        predicted: &[bool],
        reference: &[bool],
        width: usize,
        height: usize,
        radius: usize,
    ) -> NearAgreement {
        assert_eq!(predicted.len(), width * height, "predicted mask size");
        assert_eq!(reference.len(), width * height, "reference mask size");
        let near_reference = dilate(reference, width, height, radius);
        let near_predicted = dilate(predicted, width, height, radius);
        let count = |a: &[bool], b: &[bool]| a.iter().zip(b).filter(|(x, y)| **x && **y).count();
        NearAgreement {
            predicted: predicted.iter().filter(|&&v| v).count() as u64,
            predicted_near_reference: count(predicted, &near_reference) as u64,
            reference: reference.iter().filter(|&&v| v).count() as u64,
            reference_near_predicted: count(reference, &near_predicted) as u64,
        }
    }

    pub fn add(&mut self, other: &NearAgreement) {
        self.predicted += other.predicted;
        self.predicted_near_reference += other.predicted_near_reference;
        self.reference += other.reference;
        self.reference_near_predicted += other.reference_near_predicted;
    }

    /// Predicted pixels near the reference over predicted pixels (1 when nothing is predicted).
    pub fn precision(&self) -> f64 {
        ratio_or_one(self.predicted_near_reference, self.predicted)
    }

    /// Reference pixels near a prediction over reference pixels (1 when there is no reference).
    pub fn recall(&self) -> f64 {
        ratio_or_one(self.reference_near_predicted, self.reference)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_two_pixels_off_counts_at_radius_two_and_not_at_one() {
        let (w, h) = (10, 10);
        let mut truth = vec![false; w * h];
        let mut found = vec![false; w * h];
        for x in 0..w {
            truth[4 * w + x] = true;
            found[6 * w + x] = true;
        }
        let near = NearAgreement::measure(&found, &truth, w, h, 2);
        assert_eq!((near.precision(), near.recall()), (1.0, 1.0));
        let strict = NearAgreement::measure(&found, &truth, w, h, 1);
        assert_eq!((strict.precision(), strict.recall()), (0.0, 0.0));
        // Diagonal neighbours count (a square, not a disc).
        let mut corner = vec![false; w * h];
        corner[2 * w + 2] = true;
        let mut diagonal = vec![false; w * h];
        diagonal[4 * w + 4] = true;
        assert_eq!(
            NearAgreement::measure(&diagonal, &corner, w, h, 2).precision(),
            1.0
        );
    }
}
