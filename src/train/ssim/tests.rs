//! The banded SSIM against itself: every band height gives the same bits.

use super::*;

fn image(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = fastrand::Rng::with_seed(seed);
    (0..n).map(|_| rng.f32()).collect()
}

/// Bands recompute their margins; every band height, down to one row (margins larger than
/// the band) and up to the whole image, must give the same bits, with and without the
/// gradient and the pixel weights.
#[test]
fn every_band_height_gives_the_same_bits() {
    for (w, h) in [(37u32, 29u32), (9, 4), (3, 23)] {
        let n = (w * h) as usize;
        let (x, y, weights) = (image(n * 3, 1), image(n * 3, 2), image(n, 3));
        for pixel_weights in [None, Some(&weights[..])] {
            let mut want = None;
            for band_rows in [h as usize, 1, 2, 5, 11, 16] {
                let mut ws = SsimWorkspace::new();
                let mut grad = vec![f32::NAN; n * 3];
                let with_grad = ssim_in_bands(
                    &mut ws,
                    &x,
                    &y,
                    w,
                    h,
                    pixel_weights,
                    Some(&mut grad),
                    band_rows,
                );
                let value = ssim_in_bands(&mut ws, &x, &y, w, h, pixel_weights, None, band_rows);
                assert_eq!(
                    with_grad.to_bits(),
                    value.to_bits(),
                    "{w}x{h} / {band_rows}"
                );
                let bits: Vec<u32> = grad.iter().map(|g| g.to_bits()).collect();
                assert!(grad.iter().all(|g| g.is_finite()), "{w}x{h} / {band_rows}");
                match &want {
                    None => want = Some((value.to_bits(), bits)),
                    Some(want) => {
                        assert_eq!(want.0, value.to_bits(), "{w}x{h} / {band_rows}");
                        assert!(want.1 == bits, "{w}x{h} / {band_rows}: gradient bits");
                    }
                }
            }
        }
    }
}
