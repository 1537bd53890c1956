//! Overlay mode (the published method): damage masks painted into the photos in the class
//! colours become the photometric target; afterwards a rendered pixel is read back as damage when
//! its colour is close to a class colour.

use crate::damage::{DamageClass, Palette};
use crate::scene::{Mask, RgbImage};

/// Default distance (8-bit RGB units) within which a rendered colour counts as a class colour:
/// the same tolerance the colour-coded mask reader uses.
pub const OVERLAY_TOLERANCE: f32 = crate::scene::masks::COLOUR_TOLERANCE;

/// Paints `masks` (one per class in `DamageClass::ALL` order; a missing or wrongly sized mask
/// paints nothing) into `image` in the palette's colours. Later classes win where masks overlap,
/// so exposed rebar stays visible inside its spall.
pub fn paint_overlay(image: &mut RgbImage, masks: &[Mask], palette: &Palette) {
    for (class, mask) in DamageClass::ALL.iter().zip(masks) {
        if mask.width != image.width || mask.height != image.height {
            continue;
        }
        let colour = palette.unit_colour(*class);
        for (rgb, &m) in image.data.chunks_exact_mut(3).zip(&mask.data) {
            if m != 0 {
                rgb.copy_from_slice(&colour);
            }
        }
    }
}

/// Reads per-class masks back from an overlay-mode render (`color`: RGB interleaved in [0, 1],
/// `width × height`): each pixel goes to the class whose colour is nearest, when that distance is
/// within `tolerance` (8-bit RGB units), else to no class.
pub fn detect_overlay(
    color: &[f32],
    width: u32,
    height: u32,
    palette: &Palette,
    tolerance: f32,
) -> Vec<Mask> {
    let mut masks: Vec<Mask> = DamageClass::ALL
        .iter()
        .map(|_| Mask::empty(width, height))
        .collect();
    let colours: Vec<[f32; 3]> = DamageClass::ALL
        .iter()
        .map(|&c| palette.colour(c).map(f32::from))
        .collect();
    let limit = tolerance * tolerance;
    for (p, rgb) in color.chunks_exact(3).enumerate().take(masks[0].data.len()) {
        let pixel = [rgb[0] * 255.0, rgb[1] * 255.0, rgb[2] * 255.0];
        let mut best = (f32::INFINITY, usize::MAX);
        for (k, c) in colours.iter().enumerate() {
            let d2 = (0..3).map(|i| (pixel[i] - c[i]).powi(2)).sum::<f32>();
            if d2 < best.0 {
                best = (d2, k);
            }
        }
        // NaN colours compare false and stay background.
        if best.0 <= limit {
            masks[best.1].data[p] = 1;
        }
    }
    masks
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn painted_pixels_are_detected_and_others_are_not() {
        let (w, h) = (4, 3);
        let mut image = RgbImage {
            width: w,
            height: h,
            data: vec![0.5; 36],
        };
        let mut crack = Mask::empty(w, h);
        crack.data[1] = 1;
        let mut spalling = Mask::empty(w, h);
        spalling.data[5] = 1;
        spalling.data[6] = 1;
        let mut rebar = Mask::empty(w, h);
        rebar.data[6] = 1; // inside the spall: painted last, wins
        let palette = Palette::default();
        paint_overlay(&mut image, &[crack, spalling, rebar], &palette);
        // A render that is slightly off the painted colour is still within tolerance.
        let rendered: Vec<f32> = image.data.iter().map(|v| v * 0.97).collect();
        let found = detect_overlay(&rendered, w, h, &palette, OVERLAY_TOLERANCE);
        let set = |m: &Mask| -> Vec<usize> { (0..12).filter(|&i| m.data[i] != 0).collect() };
        assert_eq!(set(&found[0]), vec![1]);
        assert_eq!(set(&found[1]), vec![5]);
        assert_eq!(set(&found[2]), vec![6]);
        // Grey, NaN and a colour far from every class are nothing.
        let far = [0.5, 0.5, 0.5, f32::NAN, 0.0, 0.0];
        let none = detect_overlay(&far, 2, 1, &palette, OVERLAY_TOLERANCE);
        assert!(none.iter().all(|m| m.data.iter().all(|&v| v == 0)));
    }
}
