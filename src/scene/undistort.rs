//! Remaps an image taken through a radial-tangential lens (`Distortion`) to the view's pinhole
//! camera. The output keeps the input's size and fx, fy, cx, cy (no cropping, no new camera
//! matrix); pixels whose source falls outside the input repeat the nearest edge pixel.

use rayon::prelude::*;

use crate::scene::{Distortion, Intrinsics, Mask, RgbImage};

/// Where a pinhole pixel's ray lands in the distorted image, for an image of `width × height`
/// (any scale of the stored size: intrinsics are scaled to it).
struct Remap {
    /// Pinhole: (fx, fy, cx, cy) at the image size.
    pinhole: [f64; 4],
    /// Distorted image: (fx, fy, cx, cy) at the image size.
    lens: [f64; 4],
    k1: f64,
    k2: f64,
    p1: f64,
    p2: f64,
}

impl Remap {
    fn new(distortion: &Distortion, pinhole: &Intrinsics, width: u32, height: u32) -> Remap {
        let sx = width as f64 / pinhole.width.max(1) as f64;
        let sy = height as f64 / pinhole.height.max(1) as f64;
        let d = distortion;
        Remap {
            pinhole: [
                pinhole.fx as f64 * sx,
                pinhole.fy as f64 * sy,
                pinhole.cx as f64 * sx,
                pinhole.cy as f64 * sy,
            ],
            lens: [
                d.fx as f64 * sx,
                d.fy as f64 * sy,
                d.cx as f64 * sx,
                d.cy as f64 * sy,
            ],
            k1: d.k1 as f64,
            k2: d.k2 as f64,
            p1: d.p1 as f64,
            p2: d.p2 as f64,
        }
    }

    /// Source position in pixel-index space (pixel `i` has its centre at `i`) of the output pixel
    /// `(x, y)` (centre at `x + 0.5` in COLMAP's continuous convention).
    fn source(&self, x: u32, y: u32) -> (f64, f64) {
        let [fx, fy, cx, cy] = self.pinhole;
        let u = (x as f64 + 0.5 - cx) / fx;
        let v = (y as f64 + 0.5 - cy) / fy;
        let (ud, vd) = distort(u, v, self.k1, self.k2, self.p1, self.p2);
        let [fxd, fyd, cxd, cyd] = self.lens;
        (fxd * ud + cxd - 0.5, fyd * vd + cyd - 0.5)
    }
}

/// OpenCV's radial-tangential model on normalised coordinates (COLMAP's OPENCV, which
/// SIMPLE_RADIAL and RADIAL are special cases of).
pub fn distort(u: f64, v: f64, k1: f64, k2: f64, p1: f64, p2: f64) -> (f64, f64) {
    let r2 = u * u + v * v;
    let radial = 1.0 + k1 * r2 + k2 * r2 * r2;
    (
        u * radial + 2.0 * p1 * u * v + p2 * (r2 + 2.0 * u * u),
        v * radial + p1 * (r2 + 2.0 * v * v) + 2.0 * p2 * u * v,
    )
}

/// Clamps a (possibly NaN or huge) coordinate to a valid index; `as` saturates and maps NaN to 0.
fn clamp_index(i: f64, len: u32) -> usize {
    (i as i64).clamp(0, len as i64 - 1) as usize
}

/// Bilinear remap of a distorted RGB image to its pinhole camera (see the module comment).
/// `image` may be at any scale of `pinhole`'s size; the output has `image`'s size.
pub fn undistort_rgb(image: &RgbImage, distortion: &Distortion, pinhole: &Intrinsics) -> RgbImage {
    let (w, h) = (image.width, image.height);
    if w == 0 || h == 0 || image.data.len() != w as usize * h as usize * 3 {
        return image.clone();
    }
    let remap = Remap::new(distortion, pinhole, w, h);
    let mut data = vec![0.0f32; image.data.len()];
    data.par_chunks_mut(w as usize * 3)
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..w {
                let (xs, ys) = remap.source(x, y as u32);
                let (x0f, y0f) = (xs.floor(), ys.floor());
                let (ax, ay) = ((xs - x0f) as f32, (ys - y0f) as f32);
                let (ax, ay) = (
                    if ax.is_finite() { ax } else { 0.0 },
                    if ay.is_finite() { ay } else { 0.0 },
                );
                let (x0, x1) = (clamp_index(x0f, w), clamp_index(x0f + 1.0, w));
                let (y0, y1) = (clamp_index(y0f, h), clamp_index(y0f + 1.0, h));
                let at =
                    |xi: usize, yi: usize, c: usize| image.data[(yi * w as usize + xi) * 3 + c];
                for c in 0..3 {
                    let top = at(x0, y0, c) * (1.0 - ax) + at(x1, y0, c) * ax;
                    let bottom = at(x0, y1, c) * (1.0 - ax) + at(x1, y1, c) * ax;
                    row[x as usize * 3 + c] = top * (1.0 - ay) + bottom * ay;
                }
            }
        });
    RgbImage {
        width: w,
        height: h,
        data,
    }
}

/// Nearest-neighbour remap of a distorted mask to its pinhole camera (labels stay 0/1).
/// `mask` may be at any scale of `pinhole`'s size; the output has `mask`'s size.
pub fn undistort_mask(mask: &Mask, distortion: &Distortion, pinhole: &Intrinsics) -> Mask {
    let (w, h) = (mask.width, mask.height);
    if w == 0 || h == 0 || mask.data.len() != w as usize * h as usize {
        return mask.clone();
    }
    let remap = Remap::new(distortion, pinhole, w, h);
    let mut data = vec![0u8; mask.data.len()];
    data.par_chunks_mut(w as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..w {
                let (xs, ys) = remap.source(x, y as u32);
                let xi = clamp_index(xs.round(), w);
                let yi = clamp_index(ys.round(), h);
                row[x as usize] = mask.data[yi * w as usize + xi];
            }
        });
    Mask {
        width: w,
        height: h,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: u32 = 160;
    const H: u32 = 120;

    fn pinhole() -> Intrinsics {
        Intrinsics {
            width: W,
            height: H,
            fx: 150.0,
            fy: 140.0,
            cx: 81.0,
            cy: 59.0,
        }
    }

    fn lens() -> Distortion {
        let k = pinhole();
        Distortion {
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            k1: -0.25,
            k2: 0.05,
            p1: 0.004,
            p2: -0.003,
        }
    }

    /// Test-only inverse of `distort` (fixed-point iteration, converges for mild lenses).
    fn undistort_point(ud: f64, vd: f64, d: &Distortion) -> (f64, f64) {
        let (mut u, mut v) = (ud, vd);
        for _ in 0..50 {
            let (du, dv) = distort(u, v, d.k1 as f64, d.k2 as f64, d.p1 as f64, d.p2 as f64);
            u += ud - du;
            v += vd - dv;
        }
        (u, v)
    }

    /// A smooth pattern defined on the pinhole's normalised image plane.
    fn pattern(u: f64, v: f64) -> [f32; 3] {
        [
            (0.5 + 0.4 * (6.0 * u).sin()) as f32,
            (0.5 + 0.4 * (5.0 * v).cos()) as f32,
            (0.5 + 0.4 * (4.0 * (u + v)).sin()) as f32,
        ]
    }

    /// Photographs the pattern through the lens: each distorted pixel looks up the pinhole point
    /// its ray comes from.
    fn distorted_photo(d: &Distortion) -> RgbImage {
        let mut img = RgbImage::filled(W, H, [0.0; 3]);
        for y in 0..H {
            for x in 0..W {
                let ud = (x as f64 + 0.5 - d.cx as f64) / d.fx as f64;
                let vd = (y as f64 + 0.5 - d.cy as f64) / d.fy as f64;
                let (u, v) = undistort_point(ud, vd, d);
                let i = ((y * W + x) * 3) as usize;
                img.data[i..i + 3].copy_from_slice(&pattern(u, v));
            }
        }
        img
    }

    #[test]
    fn undistorting_a_photographed_pattern_recovers_the_pinhole_pattern() {
        let d = lens();
        let out = undistort_rgb(&distorted_photo(&d), &d, &pinhole());
        let k = pinhole();
        let (mut max_err, mut sum_err, mut n) = (0.0f32, 0.0f32, 0);
        // Interior only: near the border the source falls outside the photo and is clamped.
        for y in 8..H - 8 {
            for x in 8..W - 8 {
                let u = (x as f64 + 0.5 - k.cx as f64) / k.fx as f64;
                let v = (y as f64 + 0.5 - k.cy as f64) / k.fy as f64;
                let want = pattern(u, v);
                let got = out.pixel(x, y);
                for c in 0..3 {
                    let e = (want[c] - got[c]).abs();
                    max_err = max_err.max(e);
                    sum_err += e;
                    n += 1;
                }
            }
        }
        // Bilinear interpolation of a pattern changing ~0.04 per pixel: 0.01 max, 0.002 mean;
        // the raw photo differs from the pinhole pattern by more than 0.1 (checked below).
        assert!(max_err < 0.01, "max error {max_err}");
        assert!(
            sum_err / (n as f32) < 0.002,
            "mean error {}",
            sum_err / n as f32
        );

        let raw = distorted_photo(&d);
        let mut raw_max = 0.0f32;
        for y in 8..H - 8 {
            for x in 8..W - 8 {
                let u = (x as f64 + 0.5 - k.cx as f64) / k.fx as f64;
                let v = (y as f64 + 0.5 - k.cy as f64) / k.fy as f64;
                raw_max = raw_max.max((pattern(u, v)[0] - raw.pixel(x, y)[0]).abs());
            }
        }
        assert!(
            raw_max > 0.1,
            "the test lens must visibly distort ({raw_max})"
        );
    }

    #[test]
    fn undistorting_a_mask_moves_a_block_to_its_pinhole_place_and_keeps_it_binary() {
        let d = lens();
        let k = pinhole();
        // A block [-0.35, -0.1] x [0.1, 0.3] on the pinhole plane, photographed through the lens.
        let inside = |u: f64, v: f64| (-0.35..=-0.1).contains(&u) && (0.1..=0.3).contains(&v);
        let mut photo = Mask::empty(W, H);
        for y in 0..H {
            for x in 0..W {
                let ud = (x as f64 + 0.5 - d.cx as f64) / d.fx as f64;
                let vd = (y as f64 + 0.5 - d.cy as f64) / d.fy as f64;
                let (u, v) = undistort_point(ud, vd, &d);
                photo.data[(y * W + x) as usize] = inside(u, v) as u8;
            }
        }
        let out = undistort_mask(&photo, &d, &k);
        assert!(out.data.iter().all(|&v| v <= 1));
        let mut wrong = 0;
        for y in 0..H {
            for x in 0..W {
                let u = (x as f64 + 0.5 - k.cx as f64) / k.fx as f64;
                let v = (y as f64 + 0.5 - k.cy as f64) / k.fy as f64;
                wrong += (out.get(x, y) != inside(u, v)) as usize;
            }
        }
        // Only block-edge pixels may differ by nearest-neighbour rounding (the edge is ~130 px).
        assert!(wrong < 60, "{wrong} pixels wrong");
        let moved = photo
            .data
            .iter()
            .zip(&out.data)
            .filter(|(a, b)| a != b)
            .count();
        assert!(moved > 60, "the lens must move the block ({moved} px)");
    }

    #[test]
    fn a_half_size_image_is_remapped_with_scaled_intrinsics() {
        let d = lens();
        let full = undistort_rgb(&distorted_photo(&d), &d, &pinhole());
        // Point-sample the photo at half size (pixel centres of the half image).
        let photo = distorted_photo(&d);
        let mut half = RgbImage::filled(W / 2, H / 2, [0.0; 3]);
        for y in 0..H / 2 {
            for x in 0..W / 2 {
                let a = photo.pixel(2 * x, 2 * y);
                let b = photo.pixel(2 * x + 1, 2 * y + 1);
                let i = ((y * (W / 2) + x) * 3) as usize;
                for c in 0..3 {
                    half.data[i + c] = 0.5 * (a[c] + b[c]);
                }
            }
        }
        let out = undistort_rgb(&half, &d, &pinhole());
        assert_eq!((out.width, out.height), (W / 2, H / 2));
        let mut max_err = 0.0f32;
        for y in 4..H / 2 - 4 {
            for x in 4..W / 2 - 4 {
                let a = full.pixel(2 * x, 2 * y);
                let b = full.pixel(2 * x + 1, 2 * y + 1);
                let got = out.pixel(x, y);
                for c in 0..3 {
                    max_err = max_err.max((0.5 * (a[c] + b[c]) - got[c]).abs());
                }
            }
        }
        // Two resamplings of a smooth pattern at half resolution.
        assert!(max_err < 0.05, "{max_err}");
    }
}
