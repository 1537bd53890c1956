//! Selecting a twin's damage Gaussians (the paper's §2.3): a filter (label probability, or base
//! colour near the class colour in overlay mode), a validation against the views' damage masks
//! (a per-view vote at each Gaussian's centre, or the blending-weight majority of FlashSplat's
//! closed-form lift), then the k nearest neighbours of each kept Gaussian so that the structure
//! around the damage is refined with it. Reads no files; the masks arrive loaded.

use std::time::Instant;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use serde::Serialize;

use crate::damage::overlay::base_colour_class;
use crate::damage::{DamageClass, Palette, TrainMode};
use crate::raster::RenderSettings;
use crate::raster::weight_lift::WeightLift;
use crate::scene::{Camera, Mask};
use crate::splats::Splats;
use crate::splats::model::sigmoid;

/// How candidates are checked against the views' masks.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Validation {
    /// Keep every candidate.
    None,
    /// Keep a candidate when its centre falls inside the class's mask in at least this fraction
    /// of the views in which it is visible.
    Vote,
    /// Keep a candidate when its blending weight over the class's mask pixels, summed over the
    /// views, exceeds its weight over the other pixels (FlashSplat's closed-form lift).
    Lift,
}

impl std::str::FromStr for Validation {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "none" => Ok(Validation::None),
            "vote" => Ok(Validation::Vote),
            "lift" => Ok(Validation::Lift),
            _ => Err(format!(
                "unknown validation {text:?}: use lift, vote or none"
            )),
        }
    }
}

/// What is selected and how.
#[derive(Clone, Debug, PartialEq)]
pub struct SelectConfig {
    pub classes: Vec<DamageClass>,
    /// Label mode filters on the label channels; overlay mode on the base colour.
    pub mode: TrainMode,
    pub palette: Palette,
    /// Label mode: a candidate's class probability is at least this.
    pub label_threshold: f32,
    /// Overlay mode: a candidate's base colour is within this distance (8-bit RGB units) of the
    /// class colour.
    pub colour_tolerance: f32,
    pub validation: Validation,
    /// Vote: the fraction of the views that see a candidate in which it must fall in the mask.
    pub vote_fraction: f32,
    /// Neighbours added per kept Gaussian.
    pub min_neighbours: usize,
    /// Also offer every Gaussian the filter does not pass to the lift, for whichever class's
    /// mask pixels hold the majority of its weight: a survey update selects new damage this way,
    /// where the twin's labels know nothing of it yet (needs `Validation::Lift`).
    pub lift_unlabelled: bool,
}

impl Default for SelectConfig {
    fn default() -> Self {
        SelectConfig {
            classes: DamageClass::ALL.to_vec(),
            mode: TrainMode::Label,
            palette: Palette::default(),
            label_threshold: 0.5,
            colour_tolerance: 60.0,
            validation: Validation::Lift,
            vote_fraction: 0.5,
            min_neighbours: 8,
            lift_unlabelled: false,
        }
    }
}

/// One view the candidates are checked in: its camera and, per class in `DamageClass::ALL`
/// order, its damage mask at that camera's size (None: no mask for that class).
pub struct MaskView {
    pub camera: Camera,
    pub masks: Vec<Option<Mask>>,
}

/// Seconds per stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct SelectTimes {
    pub filter: f64,
    pub validate: f64,
    pub neighbours: f64,
}

/// The result: Gaussian indices after each stage, ascending.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Selection {
    pub filtered: Vec<u32>,
    pub validated: Vec<u32>,
    /// `validated` and their neighbours: what is refined.
    pub selected: Vec<u32>,
    /// Per validated Gaussian (same order), the class it was kept for (the most probable one).
    pub validated_class: Vec<DamageClass>,
    pub seconds: SelectTimes,
}

impl Selection {
    /// Per Gaussian of a model of `n`: selected or not.
    pub fn mask(&self, n: usize) -> Vec<bool> {
        let mut mask = vec![false; n];
        for &g in &self.selected {
            mask[g as usize] = true;
        }
        mask
    }
}

/// The candidate class of Gaussian `g`, if any: the most probable (label mode) or the nearest
/// colour (overlay mode) among the configured classes that passes the filter.
fn candidate_class(splats: &Splats, g: usize, config: &SelectConfig) -> Option<DamageClass> {
    if config.mode == TrainMode::Overlay {
        let (palette, tolerance) = (&config.palette, config.colour_tolerance);
        return base_colour_class(splats, g, palette, tolerance, &config.classes);
    }
    let mut best: Option<(DamageClass, f32)> = None;
    for &class in &config.classes {
        let score = match config.mode {
            TrainMode::Label if splats.label_channels > class.channel() => {
                let p = sigmoid(splats.labels_of(g)[class.channel()]);
                (p >= config.label_threshold).then_some(p)
            }
            _ => None,
        };
        if let Some(score) = score
            && best.is_none_or(|(_, b)| score > b)
        {
            best = Some((class, score));
        }
    }
    best.map(|(class, _)| class)
}

/// Runs the three stages; `on_view(done, total)` after each validation view.
pub fn select(
    splats: &Splats,
    views: &[MaskView],
    config: &SelectConfig,
    background: glam::Vec3,
    on_view: &mut dyn FnMut(usize, usize),
) -> Selection {
    let mut selection = Selection::default();
    let t = Instant::now();
    let filtered: Vec<(u32, DamageClass)> = (0..splats.len())
        .filter_map(|g| candidate_class(splats, g, config).map(|c| (g as u32, c)))
        .collect();
    selection.filtered = filtered.iter().map(|&(g, _)| g).collect();
    let lift_all = config.lift_unlabelled && config.validation == Validation::Lift;
    let candidates: Vec<(u32, Option<DamageClass>)> = if lift_all {
        let mut class_of = vec![None; splats.len()];
        for &(g, c) in &filtered {
            class_of[g as usize] = Some(c);
        }
        class_of
            .into_iter()
            .enumerate()
            .map(|(g, c)| (g as u32, c))
            .collect()
    } else {
        filtered.iter().map(|&(g, c)| (g, Some(c))).collect()
    };
    selection.seconds.filter = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let kept: Vec<(u32, DamageClass)> = match config.validation {
        Validation::None => filtered,
        Validation::Vote | Validation::Lift => {
            validate(splats, views, &candidates, config, background, on_view)
        }
    };
    selection.validated = kept.iter().map(|&(g, _)| g).collect();
    selection.validated_class = kept.iter().map(|&(_, c)| c).collect();
    selection.seconds.validate = t.elapsed().as_secs_f64();

    let t = Instant::now();
    selection.selected = with_neighbours(splats, &selection.validated, config.min_neighbours);
    selection.seconds.neighbours = t.elapsed().as_secs_f64();
    selection
}

/// Keeps the candidates the views' masks confirm.
fn validate(
    splats: &Splats,
    views: &[MaskView],
    candidates: &[(u32, Option<DamageClass>)],
    config: &SelectConfig,
    background: glam::Vec3,
    on_view: &mut dyn FnMut(usize, usize),
) -> Vec<(u32, DamageClass)> {
    let classes = DamageClass::ALL.len();
    // Maps per view: one per class (its mask pixels), then every pixel.
    let channels = classes + 1;
    let settings = RenderSettings::new(background, splats.sh_degree);
    let mut lift = WeightLift::new(splats, channels, settings);
    // Per candidate: Σ weight per class and in total (lift); views seen and views inside (vote).
    let mut weight = vec![[0.0f64; 4]; candidates.len()];
    let all = classes;
    let mut seen = vec![0u32; candidates.len()];
    let mut inside = vec![0u32; candidates.len()];
    for (done, view) in views.iter().enumerate() {
        let k = &view.camera.intrinsics;
        let width = k.width as usize;
        let masks = &view.masks;
        let per_gaussian = lift.view(&view.camera, |p, c| {
            if c == classes {
                1.0
            } else {
                match &masks[c] {
                    Some(m) if m.data.get(p).is_some_and(|&v| v != 0) => 1.0,
                    _ => 0.0,
                }
            }
        });
        for (i, &(g, class)) in candidates.iter().enumerate() {
            let w = &per_gaussian[g as usize * channels..(g as usize + 1) * channels];
            for c in 0..classes {
                weight[i][c] += f64::from(w[c]);
            }
            weight[i][all] += f64::from(w[classes]);
            let Some(class) = class else {
                continue;
            };
            // Visible: it draws at least a tenth of a pixel's worth in this view.
            if w[classes] > 0.1 {
                seen[i] += 1;
                let centre = view.camera.project(splats.means[g as usize]);
                let hit = centre.is_some_and(|c| {
                    let (x, y) = (c.x.floor(), c.y.floor());
                    x >= 0.0
                        && y >= 0.0
                        && (x as u32) < k.width
                        && (y as u32) < k.height
                        && masks[class.channel()]
                            .as_ref()
                            .is_some_and(|m| m.data[y as usize * width + x as usize] != 0)
                });
                inside[i] += u32::from(hit);
            }
        }
        on_view(done + 1, views.len());
    }
    let wanted = |c: DamageClass| config.classes.contains(&c);
    candidates
        .iter()
        .enumerate()
        .filter_map(|(i, &(g, class))| {
            // An unlabelled candidate stands for the class holding most of its weight.
            let class = class.or_else(|| {
                DamageClass::ALL
                    .into_iter()
                    .filter(|&c| wanted(c))
                    .max_by(|a, b| weight[i][a.channel()].total_cmp(&weight[i][b.channel()]))
            })?;
            let keep = match config.validation {
                Validation::Lift => weight[i][class.channel()] > 0.5 * weight[i][all],
                Validation::Vote => {
                    seen[i] > 0 && inside[i] as f32 >= config.vote_fraction * seen[i] as f32
                }
                Validation::None => true,
            };
            keep.then_some((g, class))
        })
        .collect()
}

/// `kept` and the `k` nearest Gaussians of each (the adaptive radius: each kept Gaussian's
/// distance to its k-th neighbour), ascending and unique.
pub fn with_neighbours(splats: &Splats, kept: &[u32], k: usize) -> Vec<u32> {
    let mut out: Vec<u32> = kept.to_vec();
    if k > 0 && !kept.is_empty() && splats.len() > 1 {
        let coords: Vec<[f32; 3]> = splats.means.iter().map(|p| p.to_array()).collect();
        let tree: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(&coords);
        let want = std::num::NonZeroUsize::new((k + 1).min(splats.len()))
            .unwrap_or(std::num::NonZeroUsize::MIN);
        for &g in kept {
            for nb in tree.nearest_n::<SquaredEuclidean>(&coords[g as usize], want) {
                out.push(nb.item as u32);
            }
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::render;
    use crate::scene::Intrinsics;
    use crate::splats::model::SH_C0;
    use glam::{Quat, Vec2, Vec3};

    /// A wall of Gaussians at z = 0 seen by cameras in front of it; the ones in the square
    /// |x|, |y| < 0.3 are damage. Labels: the truth, plus `false_labels` undamaged Gaussians
    /// labelled damage (a segmenter's error the masks do not share).
    fn wall(false_labels: usize) -> (Splats, Vec<bool>, Vec<MaskView>) {
        let mut splats = Splats::empty(0, 3);
        let mut truth = Vec::new();
        let n = 24;
        for iy in 0..n {
            for ix in 0..n {
                let p = Vec2::new(ix as f32, iy as f32) / (n - 1) as f32 * 2.0 - Vec2::ONE;
                let damage = p.x.abs() < 0.3 && p.y.abs() < 0.3;
                truth.push(damage);
                let id = splats.len() as u64;
                splats.push(
                    Vec3::new(p.x, p.y, 0.0),
                    Vec3::new(0.05, 0.05, 0.01).map(f32::ln),
                    Quat::IDENTITY,
                    3.0,
                    &[0.0; 3],
                    &[if damage { 4.0 } else { -4.0 }, -4.0, -4.0],
                    id,
                    0,
                );
            }
        }
        // The masks: the truth's rendered crack channel, at 0.5, from three cameras.
        let k = Intrinsics {
            width: 64,
            height: 64,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 32.0,
        };
        let views = [-0.3f32, 0.0, 0.3]
            .iter()
            .map(|&x| {
                let camera = Camera::new(k, Quat::IDENTITY, Vec3::new(-x, 0.0, 2.5));
                let out = render(&splats, &camera, &RenderSettings::new(Vec3::ZERO, 0));
                let crack = Mask {
                    width: 64,
                    height: 64,
                    data: out
                        .labels
                        .chunks_exact(3)
                        .map(|l| u8::from(l[0] > 0.5))
                        .collect(),
                };
                MaskView {
                    camera,
                    masks: vec![Some(crack), None, None],
                }
            })
            .collect();
        // The segmenter's errors: undamaged Gaussians labelled crack in the model.
        let mut rng = fastrand::Rng::with_seed(9);
        let mut added = 0;
        while added < false_labels {
            let g = rng.usize(..splats.len());
            let p = splats.means[g];
            if !truth[g] && p.x.abs() < 0.8 && p.y.abs() < 0.8 && splats.raw_labels[g * 3] < 0.0 {
                splats.raw_labels[g * 3] = 4.0;
                added += 1;
            }
        }
        (splats, truth, views)
    }

    fn precision_recall(picked: &[u32], truth: &[bool]) -> (f64, f64) {
        let tp = picked.iter().filter(|&&g| truth[g as usize]).count() as f64;
        let positives = truth.iter().filter(|&&t| t).count() as f64;
        (tp / picked.len().max(1) as f64, tp / positives)
    }

    #[test]
    fn validation_removes_labels_the_masks_do_not_confirm() {
        let (splats, truth, views) = wall(30);
        for validation in [Validation::Lift, Validation::Vote] {
            let config = SelectConfig {
                classes: vec![DamageClass::Crack],
                validation,
                min_neighbours: 0,
                ..SelectConfig::default()
            };
            let selection = select(&splats, &views, &config, Vec3::ZERO, &mut |_, _| {});
            let (p_filter, r_filter) = precision_recall(&selection.filtered, &truth);
            let (p, r) = precision_recall(&selection.validated, &truth);
            // The filter takes the 30 false labels: precision 36 / 66.
            assert!(p_filter < 0.6 && r_filter == 1.0, "{p_filter} {r_filter}");
            // Measured: both drop every false label (precision 1.0). The lift keeps every true
            // Gaussian; the vote loses the square's rim (recall 0.83), whose centres fall just
            // outside the thresholded mask in most views: a hard test at one pixel, where the
            // lift weighs the whole footprint.
            assert!(p >= 0.95, "{validation:?}: precision {p}");
            let min_recall = if validation == Validation::Lift {
                0.95
            } else {
                0.75
            };
            assert!(r >= min_recall, "{validation:?}: recall {r}");
        }
    }

    #[test]
    fn unlabelled_damage_is_lifted_from_the_masks_alone() {
        // A twin that knows nothing of the damage (every label low): the masks alone select it,
        // as a survey update selects new damage.
        let (mut splats, truth, views) = wall(0);
        splats.raw_labels.iter_mut().for_each(|l| *l = -4.0);
        let config = SelectConfig {
            lift_unlabelled: true,
            min_neighbours: 0,
            ..SelectConfig::default()
        };
        let selection = select(&splats, &views, &config, Vec3::ZERO, &mut |_, _| {});
        assert!(selection.filtered.is_empty());
        let (p, r) = precision_recall(&selection.validated, &truth);
        // Measured 1.0 / 1.0 (the rendered masks are the truth's).
        assert!(p >= 0.95 && r >= 0.95, "{p} {r}");
        assert!(
            selection
                .validated_class
                .iter()
                .all(|&c| c == DamageClass::Crack)
        );
    }

    #[test]
    fn neighbours_grow_the_selection_around_the_damage() {
        let (splats, _, _) = wall(0);
        let kept = [300u32];
        let grown = with_neighbours(&splats, &kept, 4);
        assert_eq!(grown.len(), 5, "{grown:?}");
        assert!(grown.contains(&300));
        let centre = splats.means[300];
        for &g in &grown {
            // The four grid neighbours at one spacing (2 / 23).
            assert!(splats.means[g as usize].distance(centre) < 0.09 + 1e-3);
        }
    }

    #[test]
    fn overlay_mode_filters_by_base_colour() {
        let mut splats = Splats::empty(0, 0);
        let red = (1.0 - 0.5) / SH_C0;
        let grey = (0.5 - 0.5) / SH_C0;
        for (id, dc) in [[red, -0.5 / SH_C0, -0.5 / SH_C0], [grey; 3]]
            .iter()
            .enumerate()
        {
            splats.push(
                Vec3::ZERO,
                Vec3::ZERO,
                Quat::IDENTITY,
                0.0,
                dc,
                &[],
                id as u64,
                0,
            );
        }
        let config = SelectConfig {
            mode: TrainMode::Overlay,
            validation: Validation::None,
            min_neighbours: 0,
            ..SelectConfig::default()
        };
        let selection = select(&splats, &[], &config, Vec3::ZERO, &mut |_, _| {});
        assert_eq!(selection.validated, vec![0]);
        assert_eq!(selection.validated_class, vec![DamageClass::Crack]);
    }
}
