//! Pixel scoring of the real-photo study: a mask against the truth per view, and what a twin
//! renders where its input masks were wrong (the share of a segmenter's errors it corrects).

use crate::metrics::MaskAgreement;
use crate::scene::Mask;
use crate::studies::real::rows::{Correction, ViewErrors};

/// `predicted` against `truth` (same size) as one view's row.
pub fn view_errors(view: &str, predicted: &Mask, truth: &Mask) -> ViewErrors {
    let agreement = agreement(predicted, truth);
    ViewErrors {
        view: view.to_string(),
        truth_pixels: agreement.true_positive + agreement.false_negative,
        marked_pixels: agreement.true_positive + agreement.false_positive,
        iou: agreement.iou(),
        precision: agreement.precision(),
        recall: agreement.recall(),
    }
}

/// Pixel counts of `predicted` against `truth`; sizes must match (a shorter mask counts only
/// the pixels both have).
pub fn agreement(predicted: &Mask, truth: &Mask) -> MaskAgreement {
    let mut out = MaskAgreement::default();
    for (&p, &t) in predicted.data.iter().zip(&truth.data) {
        match (p != 0, t != 0) {
            (true, true) => out.true_positive += 1,
            (true, false) => out.false_positive += 1,
            (false, true) => out.false_negative += 1,
            (false, false) => out.true_negative += 1,
        }
    }
    out
}

/// Adds one view's counts to `pooled`.
pub fn add_agreement(pooled: &mut MaskAgreement, view: &MaskAgreement) {
    pooled.true_positive += view.true_positive;
    pooled.false_positive += view.false_positive;
    pooled.false_negative += view.false_negative;
    pooled.true_negative += view.true_negative;
}

/// Adds one view to `counts`: where `input` (what the twin trained on) disagrees with `truth`,
/// whether `twin` (its render) has the truth; where it agrees, whether the twin broke it.
pub fn add_corrections(counts: &mut Correction, truth: &Mask, input: &Mask, twin: &Mask) {
    for ((&t, &i), &r) in truth.data.iter().zip(&input.data).zip(&twin.data) {
        let damage = t != 0;
        let twin_right = (r != 0) == damage;
        if (i != 0) == damage {
            counts.right += 1;
            counts.introduced += u64::from(!twin_right);
        } else if damage {
            counts.missed += 1;
            counts.missed_corrected += u64::from(twin_right);
        } else {
            counts.added += 1;
            counts.added_corrected += u64::from(twin_right);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(bits: &[u8]) -> Mask {
        let mut m = Mask::empty(bits.len() as u32, 1);
        m.data.copy_from_slice(bits);
        m
    }

    #[test]
    fn a_view_is_scored_against_its_truth() {
        let truth = mask(&[1, 1, 1, 0, 0, 0]);
        let predicted = mask(&[0, 1, 1, 1, 1, 0]);
        let row = view_errors("v", &predicted, &truth);
        assert_eq!((row.truth_pixels, row.marked_pixels), (3, 4));
        assert!((row.iou - 2.0 / 5.0).abs() < 1e-12);
        assert!((row.precision - 0.5).abs() < 1e-12);
        assert!((row.recall - 2.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn corrections_count_missed_added_and_introduced_pixels() {
        // truth:  D D D . . . . .
        // input:  D . . D D . . .   (two missed, two added, four right)
        // twin:   D D . . D D . .   (one missed fixed, one added fixed, one right broken)
        let truth = mask(&[1, 1, 1, 0, 0, 0, 0, 0]);
        let input = mask(&[1, 0, 0, 1, 1, 0, 0, 0]);
        let twin = mask(&[1, 1, 0, 0, 1, 1, 0, 0]);
        let mut counts = Correction::default();
        add_corrections(&mut counts, &truth, &input, &twin);
        assert_eq!(
            counts,
            Correction {
                missed: 2,
                missed_corrected: 1,
                added: 2,
                added_corrected: 1,
                right: 4,
                introduced: 1,
            }
        );
        assert!((counts.corrected_share() - 0.5).abs() < 1e-12);
        assert!((counts.introduced_share() - 0.25).abs() < 1e-12);
    }
}
