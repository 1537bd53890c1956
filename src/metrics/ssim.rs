//! Structural similarity for evaluation, in f64 and written for clarity: 3DGS's formulation
//! (11×11 Gaussian window, σ = 1.5, per RGB channel, zero padding, mean of the SSIM map).
//! The training loss has its own fast f32 version (`train::ssim`), tested against this one.

const WINDOW: usize = 11;
const RADIUS: isize = 5;
const SIGMA: f64 = 1.5;
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

fn window() -> [f64; WINDOW] {
    let mut g = [0.0; WINDOW];
    for (i, v) in g.iter_mut().enumerate() {
        let d = i as f64 - RADIUS as f64;
        *v = (-(d * d) / (2.0 * SIGMA * SIGMA)).exp();
    }
    let sum: f64 = g.iter().sum();
    g.map(|v| v / sum)
}

/// Separable 'same' blur of one plane with zeros outside the image.
fn blur(plane: &[f64], width: usize, height: usize, g: &[f64; WINDOW]) -> Vec<f64> {
    let mut tmp = vec![0.0; plane.len()];
    for y in 0..height {
        for x in 0..width {
            let mut s = 0.0;
            for (k, &gk) in g.iter().enumerate() {
                let xx = x as isize + k as isize - RADIUS;
                if xx >= 0 && (xx as usize) < width {
                    s += gk * plane[y * width + xx as usize];
                }
            }
            tmp[y * width + x] = s;
        }
    }
    let mut out = vec![0.0; plane.len()];
    for y in 0..height {
        for x in 0..width {
            let mut s = 0.0;
            for (k, &gk) in g.iter().enumerate() {
                let yy = y as isize + k as isize - RADIUS;
                if yy >= 0 && (yy as usize) < height {
                    s += gk * tmp[yy as usize * width + x];
                }
            }
            out[y * width + x] = s;
        }
    }
    out
}

/// The SSIM map of one channel plane pair.
pub fn ssim_map(a: &[f64], b: &[f64], width: usize, height: usize) -> Vec<f64> {
    let g = window();
    let prod = |f: &dyn Fn(f64, f64) -> f64| -> Vec<f64> {
        a.iter().zip(b).map(|(&x, &y)| f(x, y)).collect()
    };
    let mu_a = blur(a, width, height, &g);
    let mu_b = blur(b, width, height, &g);
    let e_aa = blur(&prod(&|x, _| x * x), width, height, &g);
    let e_bb = blur(&prod(&|_, y| y * y), width, height, &g);
    let e_ab = blur(&prod(&|x, y| x * y), width, height, &g);
    (0..a.len())
        .map(|i| {
            let (ma, mb) = (mu_a[i], mu_b[i]);
            let var_a = e_aa[i] - ma * ma;
            let var_b = e_bb[i] - mb * mb;
            let cov = e_ab[i] - ma * mb;
            ((2.0 * ma * mb + C1) * (2.0 * cov + C2))
                / ((ma * ma + mb * mb + C1) * (var_a + var_b + C2))
        })
        .collect()
}

/// Mean SSIM of two interleaved RGB images in [0, 1] (`data[(y·w + x)·3 + c]`). The rendered
/// image is clamped to [0, 1] first, as 3DGS's evaluation does (and as `psnr` does here).
pub fn ssim(rendered: &[f32], target: &[f32], width: u32, height: u32) -> f64 {
    let n = width as usize * height as usize;
    if n == 0 {
        return f64::NAN;
    }
    ssim_over(rendered, target, width, height, None) / (3 * n) as f64
}

/// `ssim` averaged over the pixels where `used` is non-zero (the SSIM map is computed on the
/// whole image; ignored pixels only leave the average). NaN when no pixel is used.
pub fn ssim_masked(rendered: &[f32], target: &[f32], width: u32, height: u32, used: &[u8]) -> f64 {
    assert_eq!(
        used.len(),
        width as usize * height as usize,
        "ssim: mask size"
    );
    let n = used.iter().filter(|&&u| u != 0).count();
    if n == 0 {
        return f64::NAN;
    }
    ssim_over(rendered, target, width, height, Some(used)) / (3 * n) as f64
}

/// The SSIM map summed over the channels and over the used pixels (all without `used`).
fn ssim_over(
    rendered: &[f32],
    target: &[f32],
    width: u32,
    height: u32,
    used: Option<&[u8]>,
) -> f64 {
    let (w, h) = (width as usize, height as usize);
    assert_eq!(rendered.len(), w * h * 3, "ssim: rendered image size");
    assert_eq!(target.len(), w * h * 3, "ssim: target image size");
    let mut total = 0.0;
    for c in 0..3 {
        let a: Vec<f64> = (0..w * h)
            .map(|p| rendered[p * 3 + c].clamp(0.0, 1.0) as f64)
            .collect();
        let b: Vec<f64> = (0..w * h).map(|p| target[p * 3 + c] as f64).collect();
        let map = ssim_map(&a, &b, w, h);
        total += match used {
            Some(used) => map
                .iter()
                .zip(used)
                .filter(|&(_, &u)| u != 0)
                .map(|(v, _)| v)
                .sum::<f64>(),
            None => map.iter().sum::<f64>(),
        };
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize, seed: u64) -> Vec<f32> {
        let mut rng = fastrand::Rng::with_seed(seed);
        (0..n).map(|_| rng.f32()).collect()
    }

    #[test]
    fn identical_images_have_ssim_one() {
        let a = noise(20 * 13 * 3, 1);
        assert!((ssim(&a, &a, 20, 13) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn ssim_is_symmetric_and_drops_with_noise() {
        let a = noise(24 * 24 * 3, 2);
        let n = noise(24 * 24 * 3, 3);
        let slightly: Vec<f32> = a.iter().zip(&n).map(|(x, e)| x * 0.9 + e * 0.1).collect();
        let very: Vec<f32> = a.iter().zip(&n).map(|(x, e)| x * 0.3 + e * 0.7).collect();
        let s1 = ssim(&slightly, &a, 24, 24);
        let s2 = ssim(&very, &a, 24, 24);
        assert!((s1 - ssim(&a, &slightly, 24, 24)).abs() < 1e-12);
        assert!(s1 < 1.0 && s2 < s1, "{s1} {s2}");
    }

    #[test]
    fn constant_images_match_the_closed_form() {
        // Away from the zero padding, a constant image has mu = v and zero variance, so
        // SSIM = (2ab + C1)/(a² + b² + C1); with padding the border differs, so test the centre.
        let (w, h) = (31usize, 31usize);
        let a = vec![0.3f64; w * h];
        let b = vec![0.6f64; w * h];
        let map = ssim_map(&a, &b, w, h);
        let want = (2.0 * 0.3 * 0.6 + C1) / (0.09 + 0.36 + C1);
        assert!((map[15 * w + 15] - want).abs() < 1e-9);
    }
}
