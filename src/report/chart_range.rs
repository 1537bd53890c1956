//! The axes of a chart drawn from values a file held, which may be anything: NaN, ±inf or
//! numbers near `f64::MAX` in a hand-edited or corrupted `metrics.json` or `history.json`.
//! plotters steps along an axis to place its key points; an axis whose ends overflow to infinity,
//! or whose width is below the spacing of `f64`s at its ends, made it step for ever (the report
//! hung). Values a chart cannot place are left out of the axes and the drawing, and every axis
//! is wide enough for its magnitude.

/// Largest magnitude drawn. No measured value of a report comes near it: seconds (1e12 s is
/// 31 700 years), losses, PSNR, IoU, Gaussian counts (at most 1e7).
pub const MAX_PLOTTED: f64 = 1e12;

/// The smallest axis width relative to the magnitude of its ends: a million `f64` steps at
/// least, so key points a tenth of the width apart are distinct numbers.
const MIN_RELATIVE_WIDTH: f64 = 1e-6;

/// Whether a chart can place `value` (NaN is not).
pub fn plottable(value: f64) -> bool {
    value.abs() <= MAX_PLOTTED
}

/// Both coordinates of a point are plottable.
pub fn plottable_point(&(x, y): &(f64, f64)) -> bool {
    plottable(x) && plottable(y)
}

/// The axis over the plottable `values`, padded on each side by `pad(lo, hi)` (at least
/// `MIN_RELATIVE_WIDTH` of the larger end's magnitude); None when no value is plottable.
pub fn padded_range(
    values: impl Iterator<Item = f64>,
    pad: impl Fn(f64, f64) -> f64,
) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|&v| plottable(v))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !(lo <= hi) {
        return None;
    }
    let pad = pad(lo, hi).max(lo.abs().max(hi.abs()) * MIN_RELATIVE_WIDTH);
    Some((lo - pad, hi + pad))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_a_chart_cannot_place_are_left_out() {
        let values = [1.0, f64::MAX, f64::NAN, f64::INFINITY, -f64::MAX, 3.0];
        let (lo, hi) = padded_range(values.into_iter(), |_, _| 0.5).unwrap();
        assert_eq!((lo, hi), (0.5, 3.5));
        assert!(padded_range([f64::MAX, f64::NAN].into_iter(), |_, _| 1.0).is_none());
    }

    #[test]
    fn an_axis_is_never_narrower_than_its_magnitude_resolves() {
        let (lo, hi) = padded_range([1e12, 1e12].into_iter(), |_, _| 1e-3).unwrap();
        assert!(hi - lo >= 2e6 - 1.0, "{lo} {hi}");
        // Ordinary values keep the chart's own padding.
        assert_eq!(
            padded_range([20.0, 30.0].into_iter(), |lo, hi| (hi - lo) * 0.1),
            Some((19.0, 31.0))
        );
    }
}
