//! Overlay mode (the published method): damage masks painted into the photos in the class
//! colours become the photometric target. Afterwards damage is read back where a colour is close
//! to a class colour: each Gaussian's base colour (`labels_from_colours`, the default) or each
//! rendered pixel (`detect_overlay`, as the paper reads its renders).

use crate::damage::{DamageClass, Palette};
use crate::scene::{Mask, RgbImage};
use crate::splats::Splats;
use crate::splats::model::SH_C0;
use crate::train::spec::TrainView;

/// A Gaussian starts in a class colour when at least this fraction of the views its centre
/// projects into paint that class there. About half the views of a facade see it, the others
/// look through the building at another wall, so a majority would miss most damage; damage
/// covers a few percent of a photo, so chance agreement stays far below.
const SEED_VOTE_FRACTION: f32 = 0.25;

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

/// Starts the Gaussians that lie on painted damage in their class colour (SH DC; the other bands
/// are left). `views` still carry their masks (`DamageClass::ALL` order; painted in that order,
/// so the last class set at a pixel is its colour). Initial colours come from the unpainted
/// photos, and at the SH DC learning rate a wall-grey Gaussian needs most of a 3,000-step run
/// to become saturated green (docs/DAMAGE.md); seeded, the painted damage is there from the
/// start. Returns how many Gaussians were seeded.
pub fn seed_class_colours(splats: &mut Splats, views: &[TrainView], palette: &Palette) -> usize {
    let coeffs = splats.sh_coeffs() * 3;
    let mut seeded = 0;
    for g in 0..splats.len() {
        let mean = splats.means[g];
        let mut seen = 0u32;
        let mut votes = [0u32; 3];
        for view in views {
            let Some((x, y)) = view.camera.pixel_of(mean) else {
                continue;
            };
            seen += 1;
            let p = (y * view.image.width + x) as usize;
            let painted = DamageClass::ALL
                .iter()
                .zip(&view.labels)
                .rev()
                .find(|(_, mask)| mask.data.get(p).is_some_and(|&m| m != 0))
                .map(|(class, _)| class.channel());
            if let Some(k) = painted {
                votes[k] += 1;
            }
        }
        let (best, &count) = votes
            .iter()
            .enumerate()
            .max_by_key(|&(_, v)| *v)
            .unwrap_or((0, &0));
        if seen > 0 && count as f32 >= SEED_VOTE_FRACTION * seen as f32 {
            let colour = palette.unit_colour(DamageClass::ALL[best]);
            let sh = &mut splats.sh[g * coeffs..g * coeffs + 3];
            for (c, value) in sh.iter_mut().zip(colour) {
                *c = (value - 0.5) / SH_C0;
            }
            seeded += 1;
        }
    }
    seeded
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

/// The distance (8-bit RGB units) of Gaussian `g`'s base colour (the view-independent SH DC
/// term) to `colour`.
pub fn base_colour_distance(splats: &Splats, g: usize, colour: [u8; 3]) -> f32 {
    let sh = splats.sh_of(g);
    let mut d2 = 0.0;
    for c in 0..3 {
        let value = (SH_C0 * sh[c] + 0.5).clamp(0.0, 1.0) * 255.0;
        let diff = value - f32::from(colour[c]);
        d2 += diff * diff;
    }
    d2.sqrt()
}

/// The class of Gaussian `g` read from its base colour: of `classes`, the one whose colour is
/// nearest, when within `tolerance` (8-bit RGB units; the first on a tie), else none.
pub fn base_colour_class(
    splats: &Splats,
    g: usize,
    palette: &Palette,
    tolerance: f32,
    classes: &[DamageClass],
) -> Option<DamageClass> {
    classes
        .iter()
        .map(|&class| {
            (
                class,
                base_colour_distance(splats, g, palette.colour(class)),
            )
        })
        .filter(|&(_, d)| d <= tolerance)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(class, _)| class)
}

/// The overlay-mode class of each Gaussian read from its base colour (`base_colour_class` over
/// every class).
pub fn gaussian_classes(
    splats: &Splats,
    palette: &Palette,
    tolerance: f32,
) -> Vec<Option<DamageClass>> {
    (0..splats.len())
        .map(|g| base_colour_class(splats, g, palette, tolerance, &DamageClass::ALL))
        .collect()
}

/// Exposed rebar is seen where the cover concrete has spalled, and one colour per pixel cannot
/// say both: where overlay mode reads rebar it reads spalling too. (At 240×135 a fifth of the
/// demo building's spalled pixels are rebar pixels as well: docs/DAMAGE.md.) Masks in
/// `DamageClass::ALL` order.
pub fn nest_rebar_in_spalling(masks: &mut [Mask]) {
    let (s, r) = (
        DamageClass::Spalling.channel(),
        DamageClass::Rebar.channel(),
    );
    if masks.len() > s.max(r) && masks[s].data.len() == masks[r].data.len() {
        let rebar = masks[r].data.clone();
        for (spall, rebar) in masks[s].data.iter_mut().zip(rebar) {
            *spall |= rebar;
        }
    }
}

/// A copy of an overlay-mode twin whose label channels say each Gaussian's class as read from
/// its base colour (`gaussian_classes`; a rebar Gaussian is spalling too, as in
/// `nest_rebar_in_spalling`): rendered, they give damage masks that blend by opacity like the
/// colours did, but that a view-dependent tint and a blended edge cannot push out of
/// tolerance. Logits of ±`CERTAIN_LOGIT` stand for "is" and "is not".
pub fn labels_from_colours(splats: &Splats, palette: &Palette, tolerance: f32) -> Splats {
    const CERTAIN_LOGIT: f32 = 20.0;
    let classes = gaussian_classes(splats, palette, tolerance);
    let channels = DamageClass::ALL.len();
    let mut out = splats.clone();
    out.label_channels = channels;
    out.raw_labels = classes
        .iter()
        .flat_map(|class| {
            DamageClass::ALL.map(|c| {
                let nested = c == DamageClass::Spalling && *class == Some(DamageClass::Rebar);
                if *class == Some(c) || nested {
                    CERTAIN_LOGIT
                } else {
                    -CERTAIN_LOGIT
                }
            })
        })
        .collect();
    out
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

    #[test]
    fn gaussians_read_their_class_from_the_base_colour_and_rebar_is_spalling_too() {
        use glam::{Quat, Vec3};
        let palette = Palette::default();
        let mut splats = Splats::empty(0, 0);
        // Base colour → SH DC: colour = SH_C0 · dc + 0.5.
        let dc = |rgb: [f32; 3]| rgb.map(|v| (v - 0.5) / SH_C0);
        let colours = [
            palette.unit_colour(DamageClass::Crack),
            palette.unit_colour(DamageClass::Rebar).map(|v| v * 0.9), // 25 off: within 40
            [0.5, 0.5, 0.5],
        ];
        for (g, rgb) in colours.iter().enumerate() {
            splats.push(
                Vec3::ZERO,
                Vec3::ZERO,
                Quat::IDENTITY,
                0.0,
                &dc(*rgb),
                &[],
                g as u64,
                0,
            );
        }
        let classes = gaussian_classes(&splats, &palette, OVERLAY_TOLERANCE);
        assert_eq!(
            classes,
            vec![Some(DamageClass::Crack), Some(DamageClass::Rebar), None]
        );
        let labelled = labels_from_colours(&splats, &palette, OVERLAY_TOLERANCE);
        assert_eq!(labelled.label_channels, 3);
        let on =
            |g: usize| -> Vec<bool> { labelled.labels_of(g).iter().map(|&l| l > 0.0).collect() };
        assert_eq!(on(0), vec![true, false, false]);
        assert_eq!(on(1), vec![false, true, true]); // spalling and rebar
        assert_eq!(on(2), vec![false, false, false]);
        // A tolerance that excludes the tinted rebar leaves it unclassified.
        assert_eq!(gaussian_classes(&splats, &palette, 10.0)[1], None);
    }

    #[test]
    fn gaussians_on_painted_damage_start_in_its_colour() {
        use crate::scene::{Camera, Intrinsics};
        use glam::{Quat, Vec3};
        let intrinsics = Intrinsics {
            width: 9,
            height: 9,
            fx: 9.0,
            fy: 9.0,
            cx: 4.5,
            cy: 4.5,
        };
        // Four views of the origin; the origin lands on pixel (4, 4) in each.
        let views: Vec<TrainView> = (0..4)
            .map(|i| {
                let angle = i as f32 * 0.3;
                let eye = Vec3::new(angle.sin(), 0.0, -angle.cos()) * 5.0;
                let camera = Camera::look_at(intrinsics, eye, Vec3::ZERO, Vec3::NEG_Y);
                let mut labels = vec![Mask::empty(9, 9), Mask::empty(9, 9), Mask::empty(9, 9)];
                if i == 0 {
                    labels[DamageClass::Spalling.channel()].data[4 * 9 + 4] = 1;
                }
                TrainView {
                    name: format!("v{i}"),
                    camera,
                    image: RgbImage {
                        width: 9,
                        height: 9,
                        data: vec![0.5; 243],
                    },
                    labels,
                    region: None,
                    light: None,
                }
            })
            .collect();
        assert_eq!(views[2].camera.pixel_of(Vec3::ZERO), Some((4, 4)));
        let palette = Palette::default();
        let mut splats = Splats::empty(1, 0);
        let grey = [0.0; 12];
        for (g, mean) in [Vec3::ZERO, Vec3::new(0.0, 0.3, 0.0)]
            .into_iter()
            .enumerate()
        {
            splats.push(
                mean,
                Vec3::ZERO,
                Quat::IDENTITY,
                0.0,
                &grey,
                &[],
                g as u64,
                0,
            );
        }
        // One view of four paints spalling at the origin: a quarter, enough.
        let seeded = seed_class_colours(&mut splats, &views, &palette);
        assert_eq!(seeded, 1);
        let expected = palette.unit_colour(DamageClass::Spalling);
        for (dc, want) in splats.sh_of(0)[..3].iter().zip(expected) {
            assert!((SH_C0 * dc + 0.5 - want).abs() < 1e-5);
        }
        // The higher band and the undamaged Gaussian are left alone.
        assert!(splats.sh_of(0)[3..].iter().all(|&v| v == 0.0));
        assert!(splats.sh_of(1).iter().all(|&v| v == 0.0));
    }
}
