//! An oracle for studies: hulls drawn from a synthetic survey's truth masks instead of from the
//! selected Gaussians. With them every damage pixel of every view lies inside a hull, so a
//! refinement trained on them shows what full hull coverage buys (an upper bound for the drawn
//! hulls, never a way to refine real photos: they have no truth).

use crate::damage::reference::{ReferenceSource, load_reference_views};
use crate::scene::{Dataset, ImageScale, Mask, MaskFolder, MaskSource};
use crate::train::focus::ViewHulls;
use crate::train::focus::hulls::Hull;
use crate::train::job::JobError;

/// Replaces each view's hulls by one hull: the union of its truth masks, every class, dilated
/// by a disc of `dilate_px` (the drawn hulls' margin). Refused when the dataset has no truth.
pub fn replace_with_truth_hulls(
    dataset: &Dataset,
    views: &mut [ViewHulls],
    scale: ImageScale,
    dilate_px: f32,
) -> Result<(), JobError> {
    let truth = MaskFolder::truth(&dataset.root);
    if !truth.is_available() {
        return Err(JobError::Invalid(format!(
            "{}: no truth masks to draw oracle hulls from",
            dataset.root.display()
        )));
    }
    let indices: Vec<usize> = views.iter().map(|v| v.index).collect();
    let loaded = load_reference_views(dataset, &ReferenceSource::Truth(truth), &indices, scale)?;
    for (view, reference) in views.iter_mut().zip(loaded) {
        let mut union = Mask::empty(view.width, view.height);
        for mask in reference.reference.iter().flatten() {
            for (u, &m) in union.data.iter_mut().zip(&mask.data) {
                *u |= u8::from(m != 0);
            }
        }
        let mask = dilated(&union, dilate_px);
        view.pixels = mask.count();
        view.hulls = if view.pixels == 0 {
            Vec::new()
        } else {
            vec![Hull {
                polygon: Vec::new(),
                x0: 0,
                y0: 0,
                mask,
                region: 0,
            }]
        };
        view.hull_count = view.hulls.len();
    }
    Ok(())
}

/// `mask` grown by a disc of `radius` pixels.
fn dilated(mask: &Mask, radius: f32) -> Mask {
    let (w, h) = (mask.width as i64, mask.height as i64);
    let r = radius.max(0.0).floor() as i64;
    let r2 = radius * radius;
    let mut out = Mask::empty(mask.width, mask.height);
    for y in 0..h {
        for x in 0..w {
            if mask.data[(y * w + x) as usize] == 0 {
                continue;
            }
            for dy in -r..=r {
                for dx in -r..=r {
                    let (nx, ny) = (x + dx, y + dy);
                    if (dx * dx + dy * dy) as f32 <= r2
                        && (0..w).contains(&nx)
                        && (0..h).contains(&ny)
                    {
                        out.data[(ny * w + nx) as usize] = 1;
                    }
                }
            }
        }
    }
    out
}
