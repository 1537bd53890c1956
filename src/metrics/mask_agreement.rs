//! Agreement of a predicted binary mask with a reference mask, accumulated over many views.

use serde::{Deserialize, Serialize};

/// Pixel counts of a predicted mask against a reference; add views with `accumulate`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MaskAgreement {
    pub true_positive: u64,
    pub false_positive: u64,
    pub false_negative: u64,
    pub true_negative: u64,
}

impl MaskAgreement {
    /// Counts one view. `predicted` and `reference` are per-pixel booleans of equal length.
    pub fn accumulate(
        &mut self,
        predicted: impl IntoIterator<Item = bool>,
        reference: impl IntoIterator<Item = bool>,
    ) {
        for (p, r) in predicted.into_iter().zip(reference) {
            match (p, r) {
                (true, true) => self.true_positive += 1,
                (true, false) => self.false_positive += 1,
                (false, true) => self.false_negative += 1,
                (false, false) => self.true_negative += 1,
            }
        }
    }

    /// Intersection over union; 1 when both masks are empty (nothing to find, nothing found).
    pub fn iou(&self) -> f64 {
        let union = self.true_positive + self.false_positive + self.false_negative;
        ratio_or_one(self.true_positive, union)
    }

    pub fn precision(&self) -> f64 {
        ratio_or_one(self.true_positive, self.true_positive + self.false_positive)
    }

    pub fn recall(&self) -> f64 {
        ratio_or_one(self.true_positive, self.true_positive + self.false_negative)
    }

    pub fn f1(&self) -> f64 {
        let denominator = 2 * self.true_positive + self.false_positive + self.false_negative;
        ratio_or_one(2 * self.true_positive, denominator)
    }
}

/// A ratio of pixel counts, 1 when there is nothing to count (no error on an empty reference).
pub(crate) fn ratio_or_one(numerator: u64, denominator: u64) -> f64 {
    if denominator == 0 {
        1.0
    } else {
        numerator as f64 / denominator as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_give_textbook_scores() {
        let mut m = MaskAgreement::default();
        // tp 2, fp 1, fn 1, tn 1
        m.accumulate(
            [true, true, true, false, false],
            [true, true, false, true, false],
        );
        assert_eq!(
            (
                m.true_positive,
                m.false_positive,
                m.false_negative,
                m.true_negative
            ),
            (2, 1, 1, 1)
        );
        assert!((m.iou() - 0.5).abs() < 1e-12);
        assert!((m.precision() - 2.0 / 3.0).abs() < 1e-12);
        assert!((m.recall() - 2.0 / 3.0).abs() < 1e-12);
        assert!((m.f1() - 2.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn empty_masks_agree_perfectly() {
        let mut m = MaskAgreement::default();
        m.accumulate([false; 4], [false; 4]);
        assert_eq!(m.iou(), 1.0);
    }
}
