//! Orchestrates a synth run: builds the world once (building, BVH, baked AO, both surveys'
//! damage), then per survey renders every view in parallel and writes photos, masks, truth,
//! the COLMAP model and the manifest. No shading or damage logic of its own.

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::Vec3;
use rayon::prelude::*;

use super::bridge::{self, BridgeLayout};
use super::bridge_damage;
use super::building::{Building, BuildingSpec};
use super::corrupt;
use super::damage::{self, DamagePoint, DamageState};
use super::drone;
use super::geometry::{Component, Geometry};
use super::joint::{self, JointFrame, Similarity, new_view_name};
use super::lighting::{AoMaps, Lighting};
use super::noise::{hash3, seed32};
use super::params::{Structure, Survey2Frame, SurveyOutput, SynthError, SynthOutput, SynthParams};
use super::quantities;
use super::render::{SceneContext, ViewRender, render_view};
use super::write;
use crate::scene::Camera;
use crate::scene::DamageClass;
use crate::scene::colmap::{ColmapCamera, ColmapImage, ColmapModel, ColmapPoint, write_text};

/// The scene shared by both surveys.
pub struct World {
    /// The structure: the building, or the bridge described in the building's terms.
    pub building: Building,
    pub geometry: Geometry,
    pub ao: AoMaps,
    /// Survey 1's and survey 2's damage.
    pub damage: [DamageState; 2],
    /// A bridge's spans whose damage survey 2 changed (empty for the building).
    pub changed_spans: Vec<u32>,
}

impl World {
    pub fn new(params: &SynthParams) -> World {
        let (building, damage, changed_spans) = match params.structure {
            Structure::Building => {
                let building = Building::new(BuildingSpec {
                    floors: params.floors,
                    bays_x: params.bays_x,
                    bays_y: params.bays_y,
                    bay_width: 4.0,
                    bay_depth: 4.5,
                    storey: 3.2,
                    seed: seed32(params.seed, 1),
                });
                let (d1, d2) = damage::generate(&building, params.seed);
                (building, [d1, d2], Vec::new())
            }
            Structure::Bridge { spans } => {
                let building = bridge::bridge(spans, seed32(params.seed, 1));
                let d = bridge_damage::generate(&building, spans, params.seed);
                (building, [d.survey1, d.survey2], d.changed_spans)
            }
        };
        let geometry = Geometry::new(building.prims.clone());
        let ao = AoMaps::bake(&geometry, &building);
        World {
            building,
            geometry,
            ao,
            damage,
            changed_spans,
        }
    }

    /// The cameras of survey `survey` (1-based), as written to its COLMAP model.
    pub fn cameras(&self, params: &SynthParams, survey: u32) -> Vec<Camera> {
        let k = drone::intrinsics(params.width, params.height, params.hfov_degrees);
        let n = if survey <= 1 {
            params.views
        } else {
            params.views_survey2
        };
        match params.structure {
            Structure::Building => drone::survey_path(&self.building, survey, n, k, params.seed),
            Structure::Bridge { spans } => drone::bridge_path(spans, survey, n, k, params.seed),
        }
    }

    /// Surface points of survey `survey`'s damage every `spacing` metres; with `only_new`, only
    /// damage that appeared after survey 1.
    pub fn damage_points(&self, survey: u32, spacing: f32, only_new: bool) -> Vec<DamagePoint> {
        let state = &self.damage[(survey.clamp(1, 2) - 1) as usize];
        let previous = (only_new && survey >= 2).then_some(&self.damage[0]);
        damage::damage_points(&self.building, &self.geometry, state, previous, spacing)
    }
}

/// Image file name of view `index`.
pub fn view_name(index: usize) -> String {
    format!("view-{index:03}.png")
}

/// Generates the demo dataset(s) into `params.out`; `progress(done, total)` is called after
/// every view (from worker threads).
pub fn generate(
    params: &SynthParams,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<SynthOutput, SynthError> {
    params.validate()?;
    let world = World::new(params);
    let total = params.views
        + if params.surveys >= 2 {
            params.views_survey2
        } else {
            0
        };
    let done = AtomicUsize::new(0);
    progress(0, total);
    let tick = || progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
    let mut surveys = Vec::new();
    let mut survey1_model = None;
    for survey in 1..=params.surveys {
        let (output, model) = write_survey(params, &world, survey, &tick, survey1_model.as_ref())?;
        surveys.push(output);
        survey1_model.get_or_insert(model);
    }
    Ok(SynthOutput { surveys })
}

struct ViewResult {
    points: Vec<(Vec3, [u8; 3], [f64; 2])>,
    has_class: [bool; 3],
}

/// Writes survey `survey`; returns what it wrote and its COLMAP model in the world frame (the
/// joint survey 2 is built from survey 1's).
fn write_survey(
    params: &SynthParams,
    world: &World,
    survey: u32,
    tick: &(dyn Fn() + Sync),
    survey1_model: Option<&ColmapModel>,
) -> Result<(SurveyOutput, ColmapModel), SynthError> {
    let dir = params.out.join(format!("survey-{survey}"));
    let second = survey >= 2;
    let joint = second && params.survey2_frame == Survey2Frame::Joint;
    let name = |i: usize| {
        if joint {
            new_view_name(i)
        } else {
            view_name(i)
        }
    };
    let mut dirs = vec![
        dir.join("images"),
        dir.join("truth/components"),
        dir.join("truth/depth"),
    ];
    for class in DamageClass::ALL {
        dirs.push(dir.join("masks").join(class.id()));
        dirs.push(dir.join("truth/masks").join(class.id()));
        if second {
            dirs.push(dir.join("truth/new-damage").join(class.id()));
        }
    }
    for d in &dirs {
        write::create_dir(d)?;
    }
    let cameras = world.cameras(params, survey);
    let lighting = Lighting::for_survey(survey);
    let ctx = SceneContext {
        building: &world.building,
        geometry: &world.geometry,
        ao: &world.ao,
        lighting: &lighting,
        damage: &world.damage[if second { 1 } else { 0 }],
        previous: second.then_some(&world.damage[0]),
        flat: params.component_colours,
        seed: seed32(params.seed, 2),
    };
    let noisy = corrupt::noisy_views(
        cameras.len(),
        params.mask_noise,
        params.seed ^ survey as u64,
    );
    let per_view = params.sparse_points / cameras.len().max(1);
    let results = cameras
        .par_iter()
        .enumerate()
        .map(|(i, cam)| {
            let r = render_view(&ctx, cam);
            let res = write_view(
                &dir,
                i,
                &name(i),
                cam,
                &r,
                noisy[i],
                second,
                per_view,
                params.seed,
                survey,
            )?;
            tick();
            Ok(res)
        })
        .collect::<Result<Vec<ViewResult>, SynthError>>()?;

    let k = cameras.first().map(|c| c.intrinsics);
    let mut model = ColmapModel {
        cameras: k.iter().map(|k| ColmapCamera::pinhole(1, k)).collect(),
        images: Vec::new(),
        points: Vec::new(),
    };
    let mut rng = fastrand::Rng::with_seed(params.seed ^ (0x5F00 + survey as u64));
    for (i, (cam, res)) in cameras.iter().zip(&results).enumerate() {
        let mut image = ColmapImage::from_camera(i as u32 + 1, 1, name(i), cam);
        for (j, (p, rgb, px)) in res.points.iter().enumerate() {
            let id = model.points.len() as u64 + 1;
            image.points2d.push((*px, id as i64));
            model.points.push(ColmapPoint {
                id,
                xyz: [p.x as f64, p.y as f64, p.z as f64],
                rgb: *rgb,
                error: 0.3 + 0.5 * rng.f64(),
                track: vec![(i as u32 + 1, j as u32)],
            });
        }
        model.images.push(image);
    }
    let mut old_images = Vec::new();
    let mut old_corrupted = Vec::new();
    if joint {
        let old = survey1_model.ok_or_else(|| {
            SynthError::InvalidParams("the joint survey 2 needs survey 1's model".to_string())
        })?;
        old_images = old.images.iter().map(|im| im.name.clone()).collect();
        let classes: Vec<&str> = DamageClass::ALL.iter().map(|c| c.id()).collect();
        joint::copy_old_views(&params.out.join("survey-1"), &dir, &old_images, &classes)?;
        let sim = Similarity::random(params.seed);
        write_text(
            &dir.join("sparse/0"),
            &joint::joint_model(old, &model, &sim, params.seed),
        )?;
        let new_images = (0..cameras.len()).map(name).collect();
        JointFrame::new(&sim, params.seed, old_images.clone(), new_images)
            .write(&dir.join("truth/joint_frame.json"))?;
        // Survey 1's written masks are copied, corrupted ones included.
        let noisy1 = corrupt::noisy_views(old_images.len(), params.mask_noise, params.seed ^ 1);
        old_corrupted = (0..old_images.len())
            .filter(|&i| noisy1[i])
            .map(view_name)
            .collect();
    } else {
        write_text(&dir.join("sparse/0"), &model)?;
    }

    let state = ctx.damage;
    let measured = quantities::measure(
        &world.building,
        &world.geometry,
        state,
        ctx.previous,
        survey,
    );
    quantities::write(&dir.join("truth/quantities.json"), &measured)?;
    let manifest = write::Manifest {
        generator: format!("damage-twin synth {}", env!("CARGO_PKG_VERSION")),
        survey,
        params: params.clone(),
        lighting: lighting.clone(),
        images: (0..cameras.len()).map(name).collect(),
        old_images,
        components: Component::ALL.iter().map(|c| (c.id(), c.name().to_string())).collect(),
        depth: write::DEPTH_ENCODING.to_string(),
        masks: "masks/<class>/<stem>.png and truth/masks/<class>/<stem>.png: 0/255 grey PNG of the \
            centre sample of each pixel (crack mask also where the crack's centre line passes within \
            half a pixel); classes are exclusive (rebar, then spalling, then crack). truth/components: \
            8-bit ids listed in `components`. truth/new-damage (survey 2): damage absent in survey 1."
            .to_string(),
        mask_corrupted_images: old_corrupted
            .into_iter()
            .chain((0..cameras.len()).filter(|&i| noisy[i]).map(name))
            .collect(),
        damage: write::DamageSummary {
            cracks: state.cracks.iter().map(|c| c.len()).sum(),
            spalls: state.spalls.len(),
            spalls_with_rebar: state.spalls.iter().filter(|s| s.rebar.is_some()).count(),
        },
        world: match params.structure {
            Structure::Building => "z up, metres; ground plane z = 0; building frame from (0, 0) to \
                (bays_x * 4, bays_y * 4.5); cameras in COLMAP convention (world-to-camera, x right, \
                y down, z forward)"
                .to_string(),
            Structure::Bridge { .. } => bridge::WORLD.to_string(),
        },
        frame: if joint {
            write::JOINT_FRAME.to_string()
        } else {
            "sparse/0 is in the world frame (metres), as truth/ is".to_string()
        },
        quantities: quantities::SCHEMA.to_string(),
    };
    write::manifest(&dir.join("truth/manifest.ron"), &manifest)?;
    if let Structure::Bridge { spans } = params.structure {
        let layout = BridgeLayout::new(spans, &world.changed_spans);
        write::json(&dir.join("truth/bridge.json"), &layout)?;
    }

    let mut views_with_class = [0; 3];
    for r in &results {
        for (count, &has) in views_with_class.iter_mut().zip(&r.has_class) {
            *count += has as usize;
        }
    }
    let output = SurveyOutput {
        dir,
        views: cameras.len(),
        points: model.points.len()
            + survey1_model
                .filter(|_| joint)
                .map_or(0, |m| m.points.len()),
        views_with_class,
        corrupted_views: noisy.iter().filter(|&&b| b).count(),
        quantities: measured.totals,
    };
    Ok((output, model))
}

#[allow(clippy::too_many_arguments)]
fn write_view(
    dir: &Path,
    index: usize,
    name: &str,
    camera: &Camera,
    r: &ViewRender,
    noisy: bool,
    second: bool,
    points: usize,
    seed: u64,
    survey: u32,
) -> Result<ViewResult, SynthError> {
    let (w, h) = (r.width, r.height);
    let mut rng = fastrand::Rng::with_seed(seed ^ hash3(0x51, survey, index as u32, 7) as u64);
    let mut noise_rng =
        fastrand::Rng::with_seed(seed ^ hash3(0x52, survey, index as u32, 9) as u64);
    write::rgb_png(&dir.join("images").join(name), w, h, r.rgb.clone())?;
    let building: Vec<bool> = r
        .components
        .iter()
        .map(|&c| c != Component::Sky.id())
        .collect();
    let mut has_class = [false; 3];
    for class in DamageClass::ALL {
        let bit = 1u8 << class.channel();
        let clean: Vec<u8> = r.classes.iter().map(|&c| (c & bit != 0) as u8).collect();
        has_class[class.channel()] = clean.contains(&1);
        write::mask_png(
            &dir.join("truth/masks").join(class.id()).join(name),
            w,
            h,
            &clean,
        )?;
        let written = if noisy {
            let mut m = clean;
            corrupt::corrupt_class_mask(
                class,
                &mut m,
                w as usize,
                h as usize,
                &building,
                &mut noise_rng,
            );
            m
        } else {
            clean
        };
        write::mask_png(
            &dir.join("masks").join(class.id()).join(name),
            w,
            h,
            &written,
        )?;
        if second {
            let new: Vec<u8> = r
                .new_classes
                .iter()
                .map(|&c| (c & bit != 0) as u8)
                .collect();
            write::mask_png(
                &dir.join("truth/new-damage").join(class.id()).join(name),
                w,
                h,
                &new,
            )?;
        }
    }
    write::grey_png(
        &dir.join("truth/components").join(name),
        w,
        h,
        r.components.clone(),
    )?;
    let depth_mm = r.depth.iter().map(|&z| write::depth_to_mm(z)).collect();
    write::depth_png(&dir.join("truth/depth").join(name), w, h, depth_mm)?;

    // SfM-like sparse points: random surface pixels, unprojected, with ~1 cm positional noise.
    let k = camera.intrinsics;
    let r_t = camera.rotation_matrix().transpose();
    let eye = camera.position();
    let mut out = Vec::with_capacity(points);
    let n = (w * h) as usize;
    for _ in 0..points * 4 {
        if out.len() >= points {
            break;
        }
        let i = rng.usize(0..n);
        let z = r.depth[i];
        if !(z > 0.0 && z < 60.0) {
            continue;
        }
        let (x, y) = ((i % w as usize) as f32 + 0.5, (i / w as usize) as f32 + 0.5);
        let p = eye + r_t * Vec3::new((x - k.cx) / k.fx * z, (y - k.cy) / k.fy * z, z);
        let noise = Vec3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)) * 0.01;
        let rgb = [r.rgb[i * 3], r.rgb[i * 3 + 1], r.rgb[i * 3 + 2]];
        out.push((p + noise, rgb, [x as f64, y as f64]));
    }
    Ok(ViewResult {
        points: out,
        has_class,
    })
}

fn gauss(rng: &mut fastrand::Rng) -> f32 {
    let u1 = rng.f32().max(1e-7);
    let u2 = rng.f32();
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}
