//! Seeds for new damage. The update fine-tunes the twin's Gaussians without densifying, and a
//! coarse twin has none as thin as a new crack or bar: relabelling the wall Gaussians under a
//! 2 cm crack paints a band far wider than it. So before the update trains, every pixel where a
//! new survey's mask shows a seeded class and the twin's render does not (cleaned as the
//! detection cleans its new damage: no slivers along old damage, no specks) is lifted to the
//! twin's surface, kept when most of the new training views that see that surface point show the
//! same class (one view's segmentation error is outvoted, as in training), and the kept points,
//! merged on a grid of about a pixel's footprint, become small Gaussians of that class with the
//! photo's colour in the twin's light. The update then trains them with the rest of the selection.

use std::collections::{BTreeMap, HashMap};

use glam::{Quat, Vec3};

use crate::damage::DamageClass;
use crate::damage::evaluate::{DamageReadout, predicted_masks};
use crate::raster::{RenderOutput, RenderSettings, render};
use crate::scene::{Dataset, ImageScale, Mask, SceneError};
use crate::splats::Splats;
use crate::splats::model::{SH_C0, logit};
use crate::timeline::changes::{and_not, dilate, drop_slivers, drop_small};
use crate::timeline::earlier::{EarlierSurvey, surface_depth, unproject};
use crate::timeline::near_floaters::leaving_out_near_floaters;
use crate::train::focus::ViewLights;

/// How seeds are made.
#[derive(Clone, Debug, PartialEq)]
pub struct SeedConfig {
    /// Per class in `DamageClass::ALL` order, whether it is seeded. Spalls are not by default:
    /// relabelling and reshaping the wall Gaussians learns them (+0.26 IoU on the demo), and
    /// seeding them too (+0.05 more) left their measured regions in fragments: 171 spalling
    /// regions in the report for 17 true spalls (docs/TIMELINE.md).
    pub classes: [bool; 3],
    /// Per class, seeds merge on a grid of this many pixel footprints (at the candidates'
    /// median depth): 1.5 for thin cracks and bars, 3 for spalls, whose patches need no more.
    pub grid_px: [f32; 3],
    /// A candidate needs at least this many training views to see its surface point.
    pub min_views: usize,
    /// Mask pixels within this distance of a projected point count as at it.
    pub radius_px: u32,
    /// As the detection cleans its new damage: candidate blobs lying wholly within this many
    /// pixels of the class's rendered damage (slivers of misregistration) and blobs under
    /// `min_area_px` pixels (specks) are not seeded.
    pub band_px: u32,
    pub min_area_px: usize,
}

impl Default for SeedConfig {
    fn default() -> Self {
        SeedConfig {
            classes: [true, false, true],
            grid_px: [1.5, 3.0, 1.5],
            min_views: 2,
            radius_px: 1,
            band_px: 2,
            min_area_px: 16,
        }
    }
}

/// What seeding found and added.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SeedReport {
    /// Per class name: pixels the masks show and the twin does not, over the training views.
    pub candidates: BTreeMap<String, usize>,
    /// Of those, lifted points that most views seeing them agree on.
    pub agreed: BTreeMap<String, usize>,
    /// Gaussians added per class.
    pub seeds: BTreeMap<String, usize>,
}

/// What seeding keeps of one training view beside its camera, depth and masks (which the vote
/// holds, in the same order).
struct SeedView {
    /// The photo in the twin's light.
    photo: Vec<f32>,
    /// Per class: the mask shows it and the twin's render does not.
    candidates: Vec<Mask>,
}

/// Lifts the new damage of `dataset`'s views `train_idx` (at `scale`) onto the twin and appends
/// a seed Gaussian per grid cell to `model`. `lights` maps each view's photo into the twin's
/// light (views without one are taken as they are). `rendered` holds renders of `model`
/// (without its near floaters, at `scale`) that the caller already made, by view index: the
/// update's light fit renders the same twin at the same views, and rendering it again cost a
/// render per training view. Views missing from `rendered` are rendered here; the seeds are the
/// same either way.
#[allow(clippy::too_many_arguments)]
pub fn seed_new_damage(
    model: &mut Splats,
    dataset: &Dataset,
    train_idx: &[usize],
    scale: ImageScale,
    settings: &RenderSettings,
    readout: &DamageReadout,
    lights: &ViewLights,
    config: &SeedConfig,
    rendered: &BTreeMap<usize, RenderOutput>,
) -> Result<SeedReport, SceneError> {
    if model.label_channels < DamageClass::ALL.len() {
        return Ok(SeedReport::default());
    }
    let mut views = Vec::with_capacity(train_idx.len());
    let mut voters = Vec::with_capacity(train_idx.len());
    for &index in train_idx {
        let mut loaded = dataset.load_view(index, scale)?;
        if loaded.masks.is_empty() {
            continue;
        }
        if let Some(transform) = lights.get(&index) {
            transform.undo(&mut loaded.image);
        }
        let own;
        let out = match rendered.get(&index) {
            Some(out) => out,
            None => {
                let seen = leaving_out_near_floaters(model, &loaded.camera, settings);
                own = render(model, &loaded.camera, &seen);
                &own
            }
        };
        let drawn = predicted_masks(out, readout);
        let (w, h) = (loaded.image.width, loaded.image.height);
        let masks: Vec<Mask> = DamageClass::ALL
            .iter()
            .map(|c| loaded.masks.remove(c).unwrap_or_else(|| Mask::empty(w, h)))
            .collect();
        let candidates = masks
            .iter()
            .zip(&drawn)
            .map(|(observed, drawn)| {
                let new = drop_slivers(&and_not(observed, drawn), &dilate(drawn, config.band_px));
                drop_small(&new, config.min_area_px)
            })
            .collect();
        voters.push((loaded.camera, surface_depth(out), masks));
        views.push(SeedView {
            photo: loaded.image.data,
            candidates,
        });
    }
    let voters = EarlierSurvey::from_views(voters, config.radius_px);
    Ok(plant(model, &voters, &views, config))
}

/// Lifts the candidates of `views` (view `i` is `voters`' view `i`), keeps those most views
/// agree on, and appends one seed per grid cell to `model`.
fn plant(
    model: &mut Splats,
    voters: &EarlierSurvey,
    views: &[SeedView],
    config: &SeedConfig,
) -> SeedReport {
    let mut report = SeedReport::default();
    // Lift, vote, and pool per grid cell.
    struct Point {
        position: Vec3,
        colour: Vec3,
        footprint: f32,
    }
    let mut agreed: Vec<Vec<Point>> = (0..DamageClass::ALL.len()).map(|_| Vec::new()).collect();
    for (i, view) in views.iter().enumerate() {
        let (camera, depth) = voters.view(i);
        let fx = camera.intrinsics.fx;
        for (class, mask) in view.candidates.iter().enumerate() {
            if !config.classes[class] {
                continue;
            }
            let pixels: Vec<usize> = (0..mask.data.len())
                .filter(|&p| mask.data[p] != 0)
                .collect();
            *report
                .candidates
                .entry(DamageClass::ALL[class].id().to_string())
                .or_default() += pixels.len();
            for p in pixels {
                let z = depth[p];
                if !z.is_finite() {
                    continue;
                }
                let point = unproject(camera, p, z);
                let (seen, damaged) = voters.votes(point, class);
                if seen < config.min_views || 2 * damaged < seen {
                    continue;
                }
                let footprint = z / fx;
                // Half a footprint nearer the camera than the surface, so a seed sorts in front of
                // the wall Gaussians whose centres lie on it.
                let position = unproject(camera, p, z - 0.5 * footprint);
                let c = &view.photo[p * 3..p * 3 + 3];
                agreed[class].push(Point {
                    position,
                    colour: Vec3::new(c[0], c[1], c[2]),
                    footprint,
                });
            }
        }
    }

    let coeffs = model.sh_coeffs();
    let mut next_id = model.meta.next_id();
    for (class, points) in agreed.iter().enumerate() {
        if points.is_empty() {
            continue;
        }
        let name = DamageClass::ALL[class].id().to_string();
        report.agreed.insert(name.clone(), points.len());
        let mut footprints: Vec<f32> = points.iter().map(|p| p.footprint).collect();
        footprints.sort_by(f32::total_cmp);
        let cell = footprints[footprints.len() / 2] * config.grid_px[class];
        let mut cells: HashMap<[i64; 3], (Vec3, Vec3, u32)> = HashMap::new();
        for point in points {
            let key = (point.position / cell).floor().as_i64vec3().to_array();
            let entry = cells.entry(key).or_insert((Vec3::ZERO, Vec3::ZERO, 0));
            entry.0 += point.position;
            entry.1 += point.colour;
            entry.2 += 1;
        }
        // Sorted cells: the same masks give the same model.
        let mut cells: Vec<_> = cells.into_iter().collect();
        cells.sort_by_key(|(key, _)| *key);
        let log_scale = Vec3::splat((0.5 * cell).ln());
        let mut labels = vec![-3.0f32; model.label_channels];
        labels[class] = 3.0;
        let mut sh = vec![0.0f32; coeffs * 3];
        for (_, (position_sum, colour_sum, count)) in &cells {
            let colour = *colour_sum / *count as f32;
            for c in 0..3 {
                sh[c] = (colour[c] - 0.5) / SH_C0;
            }
            model.push(
                *position_sum / *count as f32,
                log_scale,
                Quat::IDENTITY,
                logit(0.8),
                &sh,
                &labels,
                next_id,
                crate::splats::model::NO_SURVEY,
            );
            next_id += 1;
        }
        report.seeds.insert(name, cells.len());
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Camera, Intrinsics};

    /// Plants seeds from views made by `view`.
    fn plant_views(model: &mut Splats, views: Vec<(SeedView, Voter)>) -> SeedReport {
        let config = SeedConfig::default();
        let (views, voters): (Vec<SeedView>, Vec<Voter>) = views.into_iter().unzip();
        plant(
            model,
            &EarlierSurvey::from_views(voters, config.radius_px),
            &views,
            &config,
        )
    }

    type Voter = (Camera, Vec<f32>, Vec<Mask>);

    /// A view of a wall at z = 5 from a camera at `x` looking along +z, with a crack mask along
    /// the world line x = 0 (`crack_line`) and optionally a blob no other view shows.
    fn view(x: f32, crack_line: bool, blob: bool) -> (SeedView, Voter) {
        let (w, h) = (40u32, 30u32);
        let k = Intrinsics {
            width: w,
            height: h,
            fx: 40.0,
            fy: 40.0,
            cx: 20.0,
            cy: 15.0,
        };
        // World to camera: p_cam = p_world - (x, 0, 0).
        let camera = Camera::new(k, Quat::IDENTITY, Vec3::new(-x, 0.0, 0.0));
        let mut crack = Mask::empty(w, h);
        for row in 5..25 {
            if crack_line {
                let px = camera
                    .pixel_of(Vec3::new(0.0, 0.0, 5.0))
                    .expect("in view")
                    .0;
                crack.data[(row * w + px) as usize] = 1;
            }
            if blob {
                for col in 30..33 {
                    crack.data[(row * w + col) as usize] = 1;
                }
            }
        }
        let empty = Mask::empty(w, h);
        let seed_view = SeedView {
            photo: vec![0.2; (w * h * 3) as usize],
            candidates: vec![crack.clone(), empty.clone(), empty.clone()],
        };
        let voter = (
            camera,
            vec![5.0; (w * h) as usize],
            vec![crack, empty.clone(), empty],
        );
        (seed_view, voter)
    }

    #[test]
    fn seeds_sit_on_the_damage_most_views_show() {
        let mut model = Splats::empty(0, 3);
        let views = vec![
            view(0.0, true, true),
            view(0.3, true, false),
            view(-0.3, true, false),
        ];
        let report = plant_views(&mut model, views);
        let seeds = report.seeds.get("crack").copied().unwrap_or(0);
        assert!(seeds > 0, "{report:?}");
        assert_eq!(model.len(), seeds);
        // The line is 20 rows of 1/8 unit each per view: the seeds cover it, not the blob
        // that only the first view shows.
        for g in 0..model.len() {
            let m = model.means[g];
            assert!(m.x.abs() < 0.2, "seed {g} at {m}: off the crack line");
            assert!((m.z - 5.0).abs() < 0.2, "seed {g} at {m}: off the wall");
            let labels = model.labels_of(g);
            assert!(labels[0] > 0.0 && labels[1] < 0.0 && labels[2] < 0.0);
            // Colour: the photo's.
            let base = model.sh_of(g)[0] * SH_C0 + 0.5;
            assert!((base - 0.2).abs() < 1e-5);
        }
        let span = model.means.iter().map(|m| m.y).fold(f32::MIN, f32::max)
            - model.means.iter().map(|m| m.y).fold(f32::MAX, f32::min);
        assert!(
            span > 1.5,
            "the seeds span the crack's 2.5 units, got {span}"
        );
        // Fresh ids after the model's own.
        assert_eq!(model.meta.ids, (0..seeds as u64).collect::<Vec<_>>());
    }

    #[test]
    fn damage_one_view_alone_shows_is_not_seeded() {
        let mut model = Splats::empty(0, 3);
        let views = vec![
            view(0.0, false, true),
            view(0.3, false, false),
            view(-0.3, false, false),
        ];
        let report = plant_views(&mut model, views);
        assert_eq!(model.len(), 0, "{report:?}");
        assert!(report.candidates["crack"] > 0);
    }
}
