//! `stamp`: opens the capture, finds its planes, places the damage of both surveys, and draws
//! and writes every photo of every survey. The same parameters and inputs give the same bytes.

use serde::Serialize;

use crate::scene::load::{load_image, stored_geometry};
use crate::scene::open::OpenOptions;
use crate::scene::{DamageClass, Dataset};

use super::decal::{Decal, SpallShape};
use super::output::{SurveyWriter, write_manifest};
use super::params::{StampError, StampParams, rng};
use super::place::{Kind, Photo, Placer, orient_and_count};
use super::planes::{Plane, PlaneSearch, fit_planes};
use super::quantities::measure;
use super::render::{Lens, stamp_view};
use super::scale::{Scale, capture_scale};
use super::sources::list_pairs;

/// What was stamped, for the CLI to print.
#[derive(Clone, Debug, Serialize)]
pub struct StampSummary {
    pub views: usize,
    pub scale: Scale,
    /// Planes found, and the ones enough photos see.
    pub planes: usize,
    pub usable_planes: usize,
    /// Decals per survey (survey 2 includes survey 1's).
    pub decals: Vec<usize>,
    /// Damage pixels per survey over all views, per class.
    pub damage_pixels: Vec<Vec<(DamageClass, usize)>>,
    /// Decals asked for but not placed (no spot found).
    pub not_placed: usize,
}

/// Sparse points needed to look for planes at all.
const MIN_POINTS: usize = 30;
/// Occupancy cell of a plane, metres.
const PLANE_CELL_M: f64 = 0.5;

pub fn stamp(
    params: &StampParams,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<StampSummary, StampError> {
    params.check()?;
    let dataset = Dataset::open(&params.capture, &OpenOptions::default())?;
    let points = match &dataset.points {
        Some(points) if points.len() >= MIN_POINTS => points,
        other => {
            return Err(StampError::refused(
                &params.capture,
                format!(
                    "{} sparse points: stamp fits its surfaces to the capture's points \
                     (COLMAP points3D, transforms.json's ply_file_path) and needs at least \
                     {MIN_POINTS}",
                    other.as_ref().map_or(0, |p| p.len())
                ),
            ));
        }
    };
    let pairs = list_pairs(&params.crack_sources)?;
    let scale = capture_scale(&dataset, params.metres_per_unit)?;
    let mpu = scale.metres_per_unit;

    let mut photos = Vec::with_capacity(dataset.views.len());
    for view in &dataset.views {
        let stored = crate::scene::files::image_size(&view.image_path)?;
        let (camera, distortion) = stored_geometry(view, stored)?;
        photos.push(Photo {
            lens: Lens { camera, distortion },
            path: view.image_path.clone(),
        });
    }
    let up = photos
        .iter()
        .map(|p| p.lens.camera.rotation.as_dquat().inverse() * glam::DVec3::NEG_Y)
        .sum::<glam::DVec3>()
        .normalize_or(glam::DVec3::Z);
    let search = PlaneSearch {
        tolerance: params.plane_tolerance_m / mpu,
        cell: PLANE_CELL_M / mpu,
        min_inliers: MIN_POINTS.max(points.len() / 50),
        max_planes: 8,
        iterations: 400,
    };
    let mut planes = fit_planes(&points.positions, up, &search, params.seed);
    let seen = orient_and_count(&mut planes, &photos);
    let usable: Vec<usize> = (0..planes.len())
        .filter(|&i| seen[i] >= params.min_views)
        .collect();
    if usable.is_empty() {
        return Err(StampError::refused(
            &params.capture,
            format!(
                "no surface to stamp: {} plane(s) with at least {} of the {} sparse points within \
                 {} m, none seen by {} photos (--min-views)",
                planes.len(),
                search.min_inliers,
                points.len(),
                params.plane_tolerance_m,
                params.min_views
            ),
        ));
    }

    let (decals, not_placed) = place_all(params, &photos, &planes, usable.clone(), &pairs, mpu)?;
    let mut summary = StampSummary {
        views: photos.len(),
        scale: scale.clone(),
        planes: planes.len(),
        usable_planes: usable.len(),
        decals: Vec::new(),
        damage_pixels: Vec::new(),
        not_placed,
    };
    let lights = survey_lights(params.seed, params.surveys);
    let total = photos.len() * params.surveys as usize;
    for survey in 1..=params.surveys {
        let writer = SurveyWriter::create(&params.out, survey, &params.classes)?;
        let mut pixels = vec![0usize; DamageClass::ALL.len()];
        for (k, (photo, view)) in photos.iter().zip(&dataset.views).enumerate() {
            let image = load_image(&photo.path)?;
            let stamped = stamp_view(
                &image,
                &photo.lens,
                &decals,
                &planes,
                survey,
                lights[survey as usize - 1],
            );
            for (class, mask) in &stamped.masks {
                pixels[class.channel()] += mask.data.iter().filter(|&&v| v != 0).count();
            }
            writer.write_view(&view.name, &stamped)?;
            progress((survey as usize - 1) * photos.len() + k + 1, total);
        }
        writer.write_model(&dataset, &photos)?;
        let quantities = measure(&decals, survey, mpu);
        writer.write_json("truth/quantities.json", &quantities)?;
        write_manifest(
            &writer, params, &summary, &planes, &usable, &decals, &lights, survey,
        )?;
        summary
            .decals
            .push(decals.iter().filter(|d| d.first_survey <= survey).count());
        summary.damage_pixels.push(
            DamageClass::ALL
                .iter()
                .map(|&c| (c, pixels[c.channel()]))
                .collect(),
        );
    }
    Ok(summary)
}

/// Survey 1's photos as taken; survey 2's under another exposure and white balance.
fn survey_lights(seed: u64, surveys: u32) -> Vec<[f32; 3]> {
    let mut random = rng(seed, 0x4C49_4748);
    (1..=surveys)
        .map(|survey| {
            if survey == 1 {
                return [1.0; 3];
            }
            let exposure = 0.75 + 0.5 * random.f32();
            let warm = 0.92 + 0.16 * random.f32();
            [exposure * warm, exposure, exposure / warm]
        })
        .collect()
}

/// Places survey 1's cracks and spalls, then survey 2's new ones; ids in order of placement.
fn place_all(
    params: &StampParams,
    photos: &[Photo],
    planes: &[Plane],
    usable: Vec<usize>,
    pairs: &[super::sources::SourcePair],
    mpu: f64,
) -> Result<(Vec<Decal>, usize), StampError> {
    let mut placer = Placer::new(
        photos,
        planes,
        usable,
        pairs,
        mpu,
        rng(params.seed, 0x504C_4143),
    );
    let mut shapes = rng(params.seed, 0x5348_4150);
    let crack = Kind::Crack {
        length_m: params.crack_length_m,
        min_width_m: params.crack_width_m,
        survey1_share: params.crack_survey1_share,
    };
    let mut plan: Vec<(bool, u32)> = Vec::new();
    let stamps_cracks = params.stamps(DamageClass::Crack);
    let stamps_spalls = params.stamps(DamageClass::Spalling);
    for (cracks, spalls, survey) in [
        (params.cracks, params.spalls, 1),
        (params.new_cracks, params.new_spalls, 2),
    ] {
        if survey > params.surveys {
            continue;
        }
        plan.extend(std::iter::repeat_n(
            (true, survey),
            if stamps_cracks { cracks } else { 0 },
        ));
        plan.extend(std::iter::repeat_n(
            (false, survey),
            if stamps_spalls { spalls } else { 0 },
        ));
    }
    let mut not_placed = 0;
    for (id, (is_crack, survey)) in plan.into_iter().enumerate() {
        let kind = if is_crack {
            crack.clone()
        } else {
            let radius = params.spall_diameter_m * 0.5 * (0.7 + 0.3 * shapes.f64());
            Kind::Spall {
                shape: SpallShape::seeded(
                    radius,
                    params.spall_growth,
                    params.stamps(DamageClass::Rebar),
                    &mut shapes,
                ),
            }
        };
        if !placer.place(id as u32, &kind, survey)? {
            not_placed += 1;
        }
    }
    Ok((placer.placed, not_placed))
}
