//! Initial Gaussians: from a coloured point cloud (SfM / `points.ply`, scale from the 3 nearest
//! neighbours as 3DGS does) or from random points in a box (NeRF-synthetic scenes have none).
//! Pure data: callers load the point cloud; nothing here reads files or trains.

use glam::{Quat, Vec3};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use std::num::NonZeroUsize;

use super::model::{MAX_SH_DEGREE, SH_C0, SplatMeta, Splats, logit};

/// 3DGS clamps the mean squared neighbour distance at 1e-7 (`torch.clamp_min(dist2, 1e-7)`)
/// so coincident points get a tiny, finite scale instead of `log(0) = -inf`.
pub const MIN_NEIGHBOUR_DIST2: f32 = 1e-7;

/// Options for building the initial model.
#[derive(Clone, Debug, PartialEq)]
pub struct InitOptions {
    /// Storage SH degree (coefficients above DC start at zero; training ramps the active degree).
    pub sh_degree: u32,
    /// Damage label channels (0 for appearance-only models).
    pub label_channels: usize,
    /// Initial opacity (3DGS: 0.1), stored as its logit.
    pub opacity: f32,
    /// Initial label logit: -4 (sigmoid ≈ 0.018) says "probably undamaged", so an untrained
    /// model renders almost no damage, yet the sigmoid's slope (≈ 0.018) still lets masks pull.
    pub raw_label: f32,
    /// Survey in which these Gaussians appear.
    pub survey: u16,
    /// Id of the first Gaussian; the rest count up (use `SplatMeta::next_id` to extend a model).
    pub first_id: u64,
}

impl Default for InitOptions {
    fn default() -> Self {
        InitOptions {
            sh_degree: 3,
            label_channels: 0,
            opacity: 0.1,
            raw_label: -4.0,
            survey: 0,
            first_id: 0,
        }
    }
}

/// Most Gaussians a model may start from. 3DGS's largest published scenes end training with about
/// 6 million; at SH degree 3 each Gaussian holds 59 floats, so 10 million are 2.4 GB of
/// parameters before gradients and Adam state triple it.
pub const MAX_INIT_POINTS: usize = 10_000_000;

/// Largest absolute coordinate of an initial point (the limit the scene readers skip points at,
/// `scene::limits::MAX_POINT_COORDINATE`).
const MAX_COORDINATE: f32 = crate::scene::limits::MAX_POINT_COORDINATE as f32;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum InitError {
    #[error("the point cloud is empty: nothing to initialise Gaussians from")]
    Empty,
    #[error("point {index} of the point cloud is not finite ({position:?})")]
    NonFinite { index: usize, position: [f32; 3] },
    #[error(
        "point {index} of the point cloud is beyond ±{MAX_COORDINATE:e} ({position:?}): no \
         Gaussian can be trained there"
    )]
    OutOfRange { index: usize, position: [f32; 3] },
    #[error("the point cloud has {positions} positions but {colours} colours")]
    ColourCount { positions: usize, colours: usize },
    #[error("SH degree {degree} is out of range: the 3DGS layout has degrees 0 to {MAX_SH_DEGREE}")]
    ShDegree { degree: u32 },
    #[error(
        "more than {MAX_INIT_POINTS} initial points asked for: the most a model may start from \
         (3DGS's largest scenes end with about 6 million Gaussians)"
    )]
    TooManyPoints { count: usize },
}

/// Refuses what no allocation should be attempted for: an SH degree above 3 (degree 100 asked
/// for 12 GB of coefficients, 2^32 − 1 wrapped their count) and more than `MAX_INIT_POINTS`.
fn check_request(points: usize, opts: &InitOptions) -> Result<(), InitError> {
    if opts.sh_degree > MAX_SH_DEGREE {
        return Err(InitError::ShDegree {
            degree: opts.sh_degree,
        });
    }
    if points > MAX_INIT_POINTS {
        return Err(InitError::TooManyPoints { count: points });
    }
    Ok(())
}

impl SplatMeta {
    /// The next unused stable id: one past the largest id (0 for an empty model).
    pub fn next_id(&self) -> u64 {
        self.ids.iter().max().map_or(0, |&m| m + 1)
    }
}

/// Mean squared distance of each point to its (up to) 3 nearest other points, clamped below
/// at `MIN_NEIGHBOUR_DIST2` (3DGS `distCUDA2`). Exact k-d tree search, rayon over points.
pub fn mean_neighbour_dist2(points: &[Vec3]) -> Vec<f32> {
    let n = points.len();
    if n < 2 {
        return vec![MIN_NEIGHBOUR_DIST2; n];
    }
    let coords: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
    let tree: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(&coords);
    let want = 3.min(n - 1);
    // One extra: the query point finds itself at distance 0.
    let qty = NonZeroUsize::new(want + 1).unwrap_or(NonZeroUsize::MIN);
    coords
        .par_iter()
        .enumerate()
        .map(|(i, q)| {
            let found = tree.nearest_n::<SquaredEuclidean>(q, qty);
            let mut sum = 0.0f32;
            let mut taken = 0;
            let mut skipped_self = false;
            for nb in &found {
                if !skipped_self && nb.item as usize == i {
                    skipped_self = true;
                    continue;
                }
                if taken < want {
                    sum += nb.distance;
                    taken += 1;
                }
            }
            let d2 = if taken > 0 { sum / taken as f32 } else { 0.0 };
            d2.max(MIN_NEIGHBOUR_DIST2)
        })
        .collect()
}

/// Gaussians at the points: isotropic scale `sqrt(mean squared 3-NN distance)` (3DGS), identity
/// rotation, opacity `opts.opacity`, SH DC from the colour (`(rgb - 0.5) / SH_C0`), higher SH zero,
/// label logits `opts.raw_label`, ids counting up from `opts.first_id`.
/// Plain slices, so that any point source (SfM, a PLY, random) can seed a model. Refused before
/// anything is allocated: an SH degree above 3, more than `MAX_INIT_POINTS` points, a position
/// not finite or beyond ±1e7.
pub fn from_points(
    positions: &[Vec3],
    colours: &[[u8; 3]],
    opts: &InitOptions,
) -> Result<Splats, InitError> {
    check_request(positions.len(), opts)?;
    if positions.is_empty() {
        return Err(InitError::Empty);
    }
    if colours.len() != positions.len() {
        return Err(InitError::ColourCount {
            positions: positions.len(),
            colours: colours.len(),
        });
    }
    if let Some((index, p)) = positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
        return Err(InitError::NonFinite {
            index,
            position: p.to_array(),
        });
    }
    // `!(|v| <= max)` also catches NaN, already refused above.
    if let Some((index, p)) = positions
        .iter()
        .enumerate()
        .find(|(_, p)| !(p.abs().max_element() <= MAX_COORDINATE))
    {
        return Err(InitError::OutOfRange {
            index,
            position: p.to_array(),
        });
    }
    let n = positions.len();
    let dist2 = mean_neighbour_dist2(positions);
    let mut splats = Splats::empty(opts.sh_degree, opts.label_channels);
    let k3 = splats.sh_coeffs() * 3;
    splats.means = positions.to_vec();
    splats.log_scales = dist2.iter().map(|&d2| Vec3::splat(0.5 * d2.ln())).collect();
    splats.rotations = vec![Quat::IDENTITY; n];
    splats.raw_opacities = vec![logit(opts.opacity); n];
    splats.sh = vec![0.0; n * k3];
    for (g, rgb) in colours.iter().enumerate() {
        for (dc, &v) in splats.sh[g * k3..g * k3 + 3].iter_mut().zip(rgb) {
            *dc = (v as f32 / 255.0 - 0.5) / SH_C0;
        }
    }
    splats.raw_labels = vec![opts.raw_label; n * opts.label_channels];
    splats.meta = SplatMeta {
        ids: (opts.first_id..opts.first_id + n as u64).collect(),
        survey: vec![opts.survey; n],
        damage_survey: vec![crate::splats::model::NO_SURVEY; n],
        state: vec![0; n],
        frozen: vec![false; n],
    };
    Ok(splats)
}

/// `n` points uniform in `[-half_extent, half_extent]³` with uniform random colours (3DGS's
/// NeRF-synthetic initialisation uses 100 000 points in `[-1.3, 1.3]³`). Positions and colours,
/// to feed to `from_points`.
///
/// An `n` above `MAX_INIT_POINTS` is not generated: the cloud then holds `MAX_INIT_POINTS + 1`
/// points, which `from_points` refuses with `InitError::TooManyPoints`. That keeps the work
/// bounded (`--init-points 18446744073709551615` overflowed the capacity) while this function
/// stays infallible; [`try_random_points`] refuses at once.
pub fn random_points(n: usize, half_extent: f32, seed: u64) -> (Vec<Vec3>, Vec<[u8; 3]>) {
    let n = n.min(MAX_INIT_POINTS + 1);
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut positions = Vec::with_capacity(n);
    let mut colours = Vec::with_capacity(n);
    for _ in 0..n {
        let p = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * (2.0 * half_extent) - half_extent;
        positions.push(p);
        colours.push([rng.u8(..), rng.u8(..), rng.u8(..)]);
    }
    (positions, colours)
}

/// [`random_points`] that refuses more than `MAX_INIT_POINTS` points before generating any.
pub fn try_random_points(
    n: usize,
    half_extent: f32,
    seed: u64,
) -> Result<(Vec<Vec3>, Vec<[u8; 3]>), InitError> {
    if n > MAX_INIT_POINTS {
        return Err(InitError::TooManyPoints { count: n });
    }
    Ok(random_points(n, half_extent, seed))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::splats::model::sigmoid;

    fn cloud(points: &[[f32; 3]]) -> (Vec<Vec3>, Vec<[u8; 3]>) {
        (
            points.iter().map(|&p| Vec3::from(p)).collect(),
            vec![[255, 0, 128]; points.len()],
        )
    }

    #[test]
    fn scale_is_rms_distance_to_three_nearest_neighbours() {
        // A point at the origin with neighbours at 1, 2, 3 along axes and a far one at 100.
        let c = cloud(&[
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 2.0, 0.0],
            [0.0, 0.0, 3.0],
            [100.0, 0.0, 0.0],
        ]);
        let s = from_points(&c.0, &c.1, &InitOptions::default()).unwrap();
        let want = ((1.0f32 + 4.0 + 9.0) / 3.0).sqrt().ln();
        assert!((s.log_scales[0] - Vec3::splat(want)).abs().max_element() < 1e-5);
        s.check_lengths().unwrap();
    }

    #[test]
    fn coincident_points_get_a_finite_clamped_scale() {
        let c = cloud(&[[1.0, 1.0, 1.0]; 50]);
        let s = from_points(&c.0, &c.1, &InitOptions::default()).unwrap();
        let want = 0.5 * MIN_NEIGHBOUR_DIST2.ln();
        assert!(
            s.log_scales
                .iter()
                .all(|l| (l.x - want).abs() < 1e-5 && l.is_finite())
        );
    }

    #[test]
    fn colour_opacity_labels_ids_follow_the_options() {
        let c = cloud(&[[0.0; 3], [1.0, 0.0, 0.0]]);
        let opts = InitOptions {
            sh_degree: 1,
            label_channels: 3,
            first_id: 10,
            survey: 2,
            ..InitOptions::default()
        };
        let s = from_points(&c.0, &c.1, &opts).unwrap();
        assert!((sigmoid(s.raw_opacities[1]) - 0.1).abs() < 1e-6);
        let sh = s.sh_of(1);
        assert!((sh[0] * SH_C0 + 0.5 - 1.0).abs() < 1e-6);
        assert!((sh[1] * SH_C0 + 0.5).abs() < 1e-6);
        assert!((sh[2] * SH_C0 + 0.5 - 128.0 / 255.0).abs() < 1e-6);
        assert!(sh[3..].iter().all(|&v| v == 0.0));
        assert_eq!(s.labels_of(0), &[-4.0; 3]);
        assert_eq!(s.meta.ids, vec![10, 11]);
        assert_eq!(s.meta.next_id(), 12);
        assert_eq!(s.meta.survey, vec![2, 2]);
        assert_eq!(s.rotations[0], Quat::IDENTITY);
    }

    #[test]
    fn bad_point_clouds_are_refused() {
        assert_eq!(
            from_points(&[], &[], &InitOptions::default()),
            Err(InitError::Empty)
        );
        let c = cloud(&[[0.0; 3], [f32::NAN, 0.0, 0.0]]);
        assert!(matches!(
            from_points(&c.0, &c.1, &InitOptions::default()),
            Err(InitError::NonFinite { index: 1, .. })
        ));
    }

    #[test]
    fn sh_degrees_above_three_are_refused_before_allocating() {
        let c = cloud(&[[0.0; 3], [1.0, 0.0, 0.0]]);
        for degree in [4, 100, u32::MAX] {
            let opts = InitOptions {
                sh_degree: degree,
                ..InitOptions::default()
            };
            let err = from_points(&c.0, &c.1, &opts).unwrap_err();
            assert_eq!(err, InitError::ShDegree { degree });
            assert!(err.to_string().contains(&degree.to_string()), "{err}");
        }
        let opts = InitOptions {
            sh_degree: 3,
            ..InitOptions::default()
        };
        assert_eq!(from_points(&c.0, &c.1, &opts).unwrap().sh_coeffs(), 16);
    }

    #[test]
    fn absurd_point_counts_and_coordinates_are_refused() {
        assert_eq!(
            try_random_points(usize::MAX, 1.0, 0),
            Err(InitError::TooManyPoints { count: usize::MAX })
        );
        assert_eq!(try_random_points(3, 1.0, 0).map(|c| c.0.len()), Ok(3));
        // The infallible form stops at one point past the limit, which `from_points` refuses.
        let capped = random_points(usize::MAX, 1.0, 0);
        assert_eq!(capped.0.len(), MAX_INIT_POINTS + 1);
        assert!(matches!(
            from_points(&capped.0, &capped.1, &InitOptions::default()),
            Err(InitError::TooManyPoints { .. })
        ));
        let far = cloud(&[[0.0; 3], [0.0, 1e20, 0.0]]);
        assert!(matches!(
            from_points(&far.0, &far.1, &InitOptions::default()),
            Err(InitError::OutOfRange { index: 1, .. })
        ));
    }

    #[test]
    fn random_points_fill_the_box_deterministically() {
        let a = random_points(1000, 1.3, 7);
        assert_eq!(a, random_points(1000, 1.3, 7));
        assert!(a.0.iter().all(|p| p.abs().max_element() <= 1.3));
        let s = from_points(&a.0, &a.1, &InitOptions::default()).unwrap();
        // 1000 points in a 2.6³ box: typical spacing ≈ 2.6 / 10, so scales are O(0.1).
        let mean = s.log_scales.iter().map(|l| l.x.exp()).sum::<f32>() / 1000.0;
        assert!(mean > 0.05 && mean < 0.4, "{mean}");
    }

    #[test]
    fn single_point_gets_the_minimum_scale() {
        let c = cloud(&[[0.0; 3]]);
        let s = from_points(&c.0, &c.1, &InitOptions::default()).unwrap();
        assert!(s.log_scales[0].is_finite());
    }
}
