//! Several mapper draws on one database, and the choice among them.
//!
//! COLMAP 4's incremental mapper decides by its own RANSAC draws: on one lund database, seeds
//! gave 2 photos, none, or 18 photos, and the 18-photo models from one database were all wrong
//! (7–14° off) with a normal reprojection error (docs/POSE.md). Counting registered photos does
//! not tell a good model from a wrong one; the photos' GPS does, without the answer: the RMS
//! residual of the similarity from a model's camera centres to the EXIF GPS positions was
//! 4.4–5.0 m for every good lund model and 10–21 m for every wrong one.
//!
//! When even the kept draw's residual is large against the GPS baseline (`gps_plausible`),
//! every draw may be wrong: `pose` then runs more seeds, and warns when none is plausible.

use serde::Serialize;

use crate::scene::sfm::georef::Georeference;

/// What one mapper draw gave: its largest component, and how well its centres fit the GPS.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MapperDraw {
    /// `--Mapper.random_seed`; `None` when the engine was not given one (COLMAP 3.8's CLI).
    pub seed: Option<u64>,
    /// Photos in the draw's largest component (0 when the mapper found no initial pair).
    pub registered: usize,
    /// RMS residual of the similarity centres → GPS (metres), over the photos that agree.
    pub gps_rms_m: Option<f64>,
    /// Registered photos whose GPS fix the fit kept (`Georeference::used`).
    pub gps_agreeing: usize,
    /// RMS distance of the draw's GPS fixes to their mean (metres): the baseline the residual
    /// is judged against (`GPS_PLAUSIBLE_FRACTION`).
    pub gps_baseline_m: Option<f64>,
    /// Mean reprojection error of the largest component's points, pixels.
    pub reprojection_error_px: f64,
}

impl MapperDraw {
    pub fn new(
        seed: Option<u64>,
        registered: usize,
        georeference: Option<&Georeference>,
        reprojection_error_px: f64,
    ) -> MapperDraw {
        MapperDraw {
            seed,
            registered,
            gps_rms_m: georeference.map(|g| g.rms_m),
            gps_agreeing: georeference.map_or(0, |g| g.used.len()),
            gps_baseline_m: georeference.map(|g| g.baseline_m),
            reprojection_error_px,
        }
    }

    /// Whether the draw's GPS residual is small against the GPS baseline
    /// (`GPS_PLAUSIBLE_FRACTION`); `None` without a GPS fit.
    pub fn gps_plausible(&self) -> Option<bool> {
        let (rms, baseline) = (self.gps_rms_m?, self.gps_baseline_m?);
        Some(rms <= GPS_PLAUSIBLE_FRACTION * baseline)
    }
}

/// A draw's GPS residual is plausible for a right model when it is at most this fraction of the
/// GPS baseline (the fixes' RMS distance to their mean). Absolute, where `GPS_AGREEMENT_FACTOR`
/// is relative to the other draws: it says whether the best draw is any good at all. Why a
/// fraction of the baseline: a right model's residual is the GPS noise whatever the baseline,
/// a wrong model's grows with it (its shape differs from the path's). On lund (phone GPS, one
/// street: the only data set measured, so the value rests on it alone) every right model was at
/// 9–15 % (4.4–5.2 m over 31–58 m) and every wrong one at 29–96 %; 0.2 lies between, about
/// 1.4 × from each side. Where the GPS noise itself is a fifth of the baseline (a short stretch
/// of phone fixes), no model can be vouched for by it, and the warning that follows is due.
pub const GPS_PLAUSIBLE_FRACTION: f64 = 0.2;

/// A draw agrees with the GPS when its residual is at most this many times the reference
/// residual (below). Relative, not metres: a phone's GPS is good to a few metres, a drone's RTK
/// to centimetres, and the residual of a good model is that noise whatever it is. On lund the
/// wrong models' residuals were at least 2.0 × the good ones' (10.0 m against 5.04 m at most),
/// the good ones within 1.14 × of each other (4.44–5.04 m).
pub const GPS_AGREEMENT_FACTOR: f64 = 1.5;

/// The draw to keep (its index), `None` when no draw registered two photos.
///
/// With GPS: among the draws whose residual is within `GPS_AGREEMENT_FACTOR` of the reference,
/// the one registering the most photos (ties: the lower residual). The reference is the smallest
/// residual among draws whose GPS fit used at least half as many photos as the largest such
/// fit: a 3-photo model fits any three fixes closely, and must not set the bar for the others.
/// When some of those draws are plausible (`MapperDraw::gps_plausible`), only they compete.
/// Without GPS (no draw has a fit): the most photos, ties by the lower reprojection error —
/// weaker, since a wrong model registered every lund photo at a normal reprojection error.
pub fn choose_draw(draws: &[MapperDraw]) -> Option<usize> {
    let candidates: Vec<usize> = (0..draws.len())
        .filter(|&i| draws[i].registered >= 2)
        .collect();
    let most_agreeing = candidates
        .iter()
        .filter(|&&i| draws[i].gps_rms_m.is_some())
        .map(|&i| draws[i].gps_agreeing)
        .max();
    let agreeing: Vec<usize> = match most_agreeing {
        Some(most) => {
            let reference = candidates
                .iter()
                .filter(|&&i| draws[i].gps_agreeing * 2 >= most)
                .filter_map(|&i| draws[i].gps_rms_m)
                .fold(f64::INFINITY, f64::min);
            let agreeing: Vec<usize> = candidates
                .into_iter()
                .filter(|&i| {
                    draws[i]
                        .gps_rms_m
                        .is_some_and(|rms| rms <= GPS_AGREEMENT_FACTOR * reference)
                })
                .collect();
            let plausible: Vec<usize> = agreeing
                .iter()
                .copied()
                .filter(|&i| draws[i].gps_plausible() == Some(true))
                .collect();
            if plausible.is_empty() {
                agreeing
            } else {
                plausible
            }
        }
        None => candidates,
    };
    // Most photos first; then the smaller residual (with GPS) or reprojection error (without).
    let tie_break = |d: &MapperDraw| d.gps_rms_m.unwrap_or(d.reprojection_error_px);
    agreeing.into_iter().min_by(|&a, &b| {
        let (a, b) = (&draws[a], &draws[b]);
        b.registered
            .cmp(&a.registered)
            .then(tie_break(a).total_cmp(&tie_break(b)))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn draw(registered: usize, gps: Option<(f64, usize)>, reprojection: f64) -> MapperDraw {
        MapperDraw {
            seed: Some(registered as u64),
            registered,
            gps_rms_m: gps.map(|g| g.0),
            gps_agreeing: gps.map_or(0, |g| g.1),
            // 40 m: every residual up to 8 m is plausible.
            gps_baseline_m: gps.map(|_| 40.0),
            reprojection_error_px: reprojection,
        }
    }

    #[test]
    fn a_wrong_model_registering_more_photos_loses_to_a_good_one_by_its_gps_residual() {
        // Lund 01–18's draws: two photos, none, a wrong 18-photo model (10–17 m), a good one.
        let draws = [
            draw(2, None, 0.5),
            draw(0, None, 0.0),
            draw(18, Some((12.0, 18)), 0.7),
            draw(17, Some((4.6, 17)), 0.7),
        ];
        assert_eq!(choose_draw(&draws), Some(3));
    }

    #[test]
    fn among_agreeing_draws_the_most_photos_win_then_the_smaller_residual() {
        let draws = [
            draw(27, Some((4.4, 27)), 0.6),
            draw(28, Some((5.0, 28)), 0.6),
            draw(28, Some((4.9, 28)), 0.9),
        ];
        assert_eq!(choose_draw(&draws), Some(2));
    }

    #[test]
    fn a_small_model_fitting_its_few_fixes_closely_does_not_set_the_bar() {
        // Three photos fit any three GPS fixes to a metre; the 18-photo good model still agrees.
        let draws = [draw(3, Some((0.4, 3)), 0.5), draw(18, Some((4.6, 18)), 0.7)];
        assert_eq!(choose_draw(&draws), Some(1));
    }

    #[test]
    fn without_gps_the_most_photos_win_then_the_lower_reprojection_error() {
        let draws = [
            draw(10, None, 0.5),
            draw(12, None, 0.9),
            draw(12, None, 0.7),
        ];
        assert_eq!(choose_draw(&draws), Some(2));
        assert_eq!(choose_draw(&[draw(0, None, 0.0), draw(1, None, 0.0)]), None);
    }

    #[test]
    fn a_plausible_draw_wins_over_a_larger_one_agreeing_only_with_the_others() {
        // 8.1 m is within 1.5 × of 5.5 m but not within a fifth of the 40 m baseline.
        let draws = [
            draw(17, Some((5.5, 17)), 0.7),
            draw(18, Some((8.1, 18)), 0.7),
        ];
        assert_eq!(draws[0].gps_plausible(), Some(true));
        assert_eq!(draws[1].gps_plausible(), Some(false));
        assert_eq!(choose_draw(&draws), Some(0));
        // Lund 01–18's run with no good draw: both 18-photo models implausible, the least
        // wrong kept (the caller warns).
        let wrong = [
            draw(2, None, 0.5),
            draw(18, Some((16.5, 18)), 0.7),
            draw(18, Some((16.4, 18)), 0.7),
        ];
        assert_eq!(choose_draw(&wrong), Some(2));
        assert_eq!(wrong[2].gps_plausible(), Some(false));
        assert_eq!(wrong[0].gps_plausible(), None);
    }
}
