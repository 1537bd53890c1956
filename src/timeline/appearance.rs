//! Appearance between surveys: a later survey is lit differently (sun, sky, exposure, white
//! balance), and an update must not repaint the twin with the new light. Per image a gain and an
//! offset per colour channel, `photo_c ≈ g_c · twin_c + o_c` (exposure and white balance, as
//! exposure compensation in 3DGS variants models them), is fitted in closed form (least
//! squares, pulled towards the identity) over the pixels where nothing changed, and the update
//! trains on the photos mapped back into the twin's look (`ColourTransform::undo`), so the
//! Gaussians keep their colours.
//!
//! Per channel, not a full 3×3 matrix: on a facade the three channels move together, so the
//! cross terms of a full matrix are nearly undetermined. On the demo building's survey 2 a full
//! fit came out as `[[1.36, -1.15, 0.59], …]` where the light was gains of about 0.87, 0.82 and
//! 0.72. After an update through it survey 1's held-out views lost 2.5 dB outside the damage,
//! against 1.9 dB with the per-channel fit: most of that loss has another cause
//! (docs/TIMELINE.md).

use std::collections::BTreeMap;

use crate::damage::evaluate::{DamageReadout, predicted_masks};
use crate::damage::refine::RefineConfig;
use crate::raster::{RenderOutput, RenderSettings, render};
use crate::scene::project::ColourTransform;
use crate::scene::{Dataset, Mask};
use crate::splats::Splats;
use crate::timeline::near_floaters::leaving_out_near_floaters;
use crate::train::focus::ViewLights;
use crate::train::job::JobError;
// The fit itself sits beneath `damage`, whose evaluation uses it too.
pub use crate::train::light_fit::fit_transform;

/// The pixels a fit may use: outside `masks` (damage, old or new), each grown by `margin`
/// pixels so blurred edges stay out too.
pub fn unchanged_pixels(masks: &[&Mask], width: u32, height: u32, margin: u32) -> Vec<bool> {
    let mut keep = vec![true; (width * height) as usize];
    let m = margin as i64;
    for mask in masks {
        for y in 0..height as i64 {
            for x in 0..width as i64 {
                if mask.data[(y * width as i64 + x) as usize] == 0 {
                    continue;
                }
                for yy in (y - m).max(0)..=(y + m).min(height as i64 - 1) {
                    let row = (yy * width as i64) as usize;
                    for xx in (x - m).max(0)..=(x + m).min(width as i64 - 1) {
                        keep[row + xx as usize] = false;
                    }
                }
            }
        }
    }
    keep
}

/// What `fit_appearance` fitted, and the renders it made that the seeds reuse.
pub struct LightFit {
    /// Per view, the light of its photo relative to the twin's render.
    pub lights: ViewLights,
    /// The same fitted over every view at once.
    pub pooled: ColourTransform,
    /// Per view asked to keep, the twin's render (without its near floaters) the fit used.
    pub renders: BTreeMap<usize, RenderOutput>,
}

/// Per view, the light of its photo relative to the render of `twin` (the twin as the update
/// trains it: its near floaters over damage cleared), fitted outside the damage, old and new,
/// grown by 4 px; and the same fitted over every view at once. The renders of the views `keep`
/// are kept for the seeds, which lift the new damage onto the same twin at the same views.
pub fn fit_appearance(
    twin: &Splats,
    dataset: &Dataset,
    config: &RefineConfig,
    readout: &DamageReadout,
    keep: &[usize],
) -> Result<LightFit, JobError> {
    let settings = RenderSettings::new(config.background, twin.sh_degree);
    let mut lights = ViewLights::new();
    let mut renders = BTreeMap::new();
    let (mut all_render, mut all_photo) = (Vec::new(), Vec::new());
    for index in 0..dataset.views.len() {
        let loaded = dataset.load_view(index, config.scale)?;
        let seen = leaving_out_near_floaters(twin, &loaded.camera, &settings);
        let out = render(twin, &loaded.camera, &seen);
        let old = predicted_masks(&out, readout);
        let observed: Vec<&Mask> = loaded.masks.values().collect();
        let masks: Vec<&Mask> = old.iter().chain(observed).collect();
        let (w, h) = (loaded.image.width, loaded.image.height);
        let keep_px = unchanged_pixels(&masks, w, h, 4);
        lights.insert(
            index,
            fit_transform(&out.color, &loaded.image.data, &|p| keep_px[p]),
        );
        // Every 7th kept pixel of every view for the survey's pooled transform.
        for (p, k) in keep_px.iter().enumerate() {
            if *k && p % 7 == 0 {
                all_render.extend_from_slice(&out.color[p * 3..p * 3 + 3]);
                all_photo.extend_from_slice(&loaded.image.data[p * 3..p * 3 + 3]);
            }
        }
        if keep.contains(&index) {
            renders.insert(index, out);
        }
    }
    Ok(LightFit {
        lights,
        pooled: fit_transform(&all_render, &all_photo, &|_| true),
        renders,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::project::ColourTransform;
    use crate::train::light_fit::tests::textured;

    #[test]
    fn changed_pixels_do_not_bend_the_fit() {
        let twin = textured(80, 60, 2);
        let mut photo = twin.clone();
        // New damage: a bright block the twin does not have, masked out of the fit.
        let mut damage = Mask::empty(80, 60);
        for y in 20..40 {
            for x in 20..50 {
                let p = (y * 80 + x) as usize;
                photo.data[p * 3..p * 3 + 3].copy_from_slice(&[1.0, 0.0, 0.0]);
                damage.data[p] = 1;
            }
        }
        let keep = unchanged_pixels(&[&damage], 80, 60, 2);
        let fitted = fit_transform(&twin.data, &photo.data, &|p| keep[p]);
        let identity = ColourTransform::IDENTITY;
        for c in 0..3 {
            for k in 0..3 {
                assert!((fitted.matrix[c][k] - identity.matrix[c][k]).abs() < 0.01);
            }
        }
    }
}
