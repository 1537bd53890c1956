//! Several mapper draws on one database, and the choice among them.
//!
//! COLMAP 4's incremental mapper decides by its own RANSAC draws: on one lund database, seeds
//! gave 2 photos, none, or 18 photos, and the 18-photo models from one database were all wrong
//! (7–14° off) with a normal reprojection error (docs/POSE.md). Counting registered photos does
//! not tell a good model from a wrong one; the photos' GPS does, without the answer: the RMS
//! residual of the similarity from a model's camera centres to the EXIF GPS positions was
//! 4.4–5.0 m for every good lund model and 10–21 m for every wrong one.

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
            reprojection_error_px,
        }
    }
}

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
            candidates
                .into_iter()
                .filter(|&i| {
                    draws[i]
                        .gps_rms_m
                        .is_some_and(|rms| rms <= GPS_AGREEMENT_FACTOR * reference)
                })
                .collect()
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
}
