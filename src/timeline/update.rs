//! The targeted update (the paper's §2.4): a later survey's masks select the Gaussians of old
//! and new damage (and their neighbours), and a hull-restricted refinement with the new photos,
//! mapped into the twin's light, trains only them. New damage takes the survey's tag, so it
//! renders in the new-damage colour while old damage keeps its class colour; the earlier
//! survey's model is read, never written.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::damage::evaluate::{DamageReadout, predicted_masks};
use crate::damage::refine::{Quality, RefineConfig, RefineReport, refine_from};
use crate::metrics::{PhaseClock, PhaseTimes};
use crate::raster::weight_lift::WeightLift;
use crate::raster::{RenderSettings, render};
use crate::scene::project::ColourTransform;
use crate::scene::{Dataset, Mask};
use crate::splats::Splats;
use crate::splats::model::{NO_SURVEY, logit, sigmoid};
use crate::timeline::appearance::{fit_appearance, unchanged_pixels};
use crate::timeline::near_floaters::near_floaters;
use crate::timeline::seed::{SeedConfig, SeedReport, seed_new_damage};
use crate::timeline::twin::{HISTORY_FILE, TimelineError, Twin};
use crate::timeline::update_rates::{
    UPDATE_LABEL_RATE, UPDATE_LABEL_WEIGHT, update_iterations, update_learning_rates,
};
// The update's steps are part of its schedule (`update_rates`); named here too, where the CLI
// and the viewer look for them.
pub use crate::timeline::update_rates::{UPDATE_ITERATIONS, UPDATE_STEPS_PER_VIEW};
use crate::train::focus::{ViewLights, trained_or_created};
use crate::train::history::{EvalSample, History};
use crate::train::job::{Job, JobContext, JobError, JobOptions};
use crate::train::views::split_views;

/// How an update runs.
#[derive(Clone, Debug, PartialEq)]
pub struct UpdateConfig {
    pub refine: RefineConfig,
    /// Fit and compensate each photo's light (off: train on the photos as they are).
    pub appearance: bool,
    /// Seed Gaussians for new damage before training (`timeline::seed`; None: off).
    pub seeds: Option<SeedConfig>,
    /// Clear the earlier twin's near floaters of the new survey's training cameras before
    /// training (`clear_near_floaters`; off: they stay, frozen, in front of those cameras).
    pub clear_near_floaters: bool,
    /// Train `update_iterations(training views)` steps instead of `refine.iterations` (the
    /// default when no step count is asked for: the survey's views are known only once it is
    /// opened).
    pub iterations_by_views: bool,
}

/// The neighbours of damage move at a tenth of the from-scratch geometry rates in an update
/// (`RefineConfig::neighbour_geometry_rate`): at full rates they grow into streaks that fit the
/// new photos' shadows and cost survey 1's views 0.7 dB on the demo, while the damage and the
/// seeds need full rates to take their new shape (docs/TIMELINE.md).
pub const NEIGHBOUR_GEOMETRY_RATE: f32 = 0.1;

/// How far the update may grow a Gaussian. With no bound, 175 of the demo's 8,441 trained
/// Gaussians grew more than 5× into opaque streaks that cost survey 1's views 2.2 dB; bounded at
/// 2×, the earlier views keep 1.6 dB of that with the same crack IoU and length
/// (docs/TIMELINE.md, "Update, measured").
pub const UPDATE_MAX_SCALE_GROWTH: f32 = 2.0;

// The gentle rates are a training preset (compaction's fine-tune uses them too).
pub use crate::train::spec::gentle_learning_rates;

impl UpdateConfig {
    /// The update as the project sets it up: its class colours, background and held-out views,
    /// with `strategy` at `scale` for `iterations` steps (None: `update_iterations` of the
    /// survey's training views) (the CLI's and the viewer's defaults).
    pub fn for_project(
        twin: &Twin,
        strategy: crate::damage::refine::Strategy,
        scale: crate::scene::ImageScale,
        iterations: Option<u32>,
        appearance: bool,
    ) -> UpdateConfig {
        let palette = crate::damage::Palette {
            colours: crate::damage::DamageClass::ALL.map(|c| twin.project.colour(c)),
        };
        let every = twin.project.settings.held_out_every.max(1) as usize;
        UpdateConfig {
            refine: RefineConfig {
                select: crate::damage::select::SelectConfig {
                    palette,
                    ..Default::default()
                },
                strategy,
                scale,
                iterations: iterations.unwrap_or(UPDATE_ITERATIONS),
                holdout: crate::train::views::Holdout::Auto { every },
                background: glam::Vec3::from_array(twin.project.settings.background),
                max_scale_growth: Some(UPDATE_MAX_SCALE_GROWTH),
                neighbour_geometry_rate: Some(NEIGHBOUR_GEOMETRY_RATE),
                lr: update_learning_rates(),
                label_lr: Some(UPDATE_LABEL_RATE),
                label_weight: UPDATE_LABEL_WEIGHT,
                ..RefineConfig::default()
            },
            appearance,
            seeds: Some(SeedConfig::default()),
            clear_near_floaters: true,
            iterations_by_views: iterations.is_none(),
        }
    }

    /// The steps this update trains on a survey with `train_views` training views.
    pub fn iterations_for(&self, train_views: usize) -> u32 {
        if self.iterations_by_views {
            update_iterations(train_views)
        } else {
            self.refine.iterations
        }
    }
}

/// What an update did and measured (the survey's `metrics.json`).
#[derive(Clone, Debug, Serialize)]
pub struct UpdateReport {
    pub survey: String,
    pub previous: String,
    /// The survey's light relative to the twin's: the transform fitted over all its views.
    pub appearance: Option<ColourTransform>,
    /// Gaussians first seen as damage in this survey, and damage Gaussians from before.
    pub new_damage_gaussians: usize,
    pub old_damage_gaussians: usize,
    /// The previous survey's held-out views, outside the damage, before and after the update:
    /// the unchanged parts keep their look when these agree.
    pub previous_look_psnr_before: Option<f64>,
    pub previous_look_psnr_after: Option<f64>,
    /// The new-damage seeds the update added before training (None when seeding was off).
    pub seeds: Option<SeedReport>,
    /// Gaussians of the earlier twin cleared as near floaters of the new survey's training
    /// cameras (`clear_near_floaters`).
    pub near_floaters_cleared: usize,
    pub seconds: f64,
    /// Wall seconds per phase of the update (the refinement's own phases are in `refine`).
    pub phase_seconds: UpdatePhaseSeconds,
    /// CPU seconds (user + system, every thread) per phase; None where the process's CPU time
    /// cannot be read.
    pub phase_cpu_seconds: Option<UpdatePhaseSeconds>,
    pub refine: RefineReport,
}

/// Seconds per phase of an update. `previous_look` and, inside `refine`, the refinement's
/// held-out scoring before and after (`RefineReport`'s `evaluate` phase) measure the update; the
/// others make it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct UpdatePhaseSeconds {
    /// Reading the earlier twin and opening the survey.
    pub load: f64,
    /// Clearing the earlier twin's near floaters over damage.
    pub near_floaters: f64,
    /// Fitting each photo's light (with the renders of the twin the seeds reuse).
    pub appearance: f64,
    pub seeds: f64,
    /// The refinement, all its phases (`RefineReport::seconds` splits it).
    pub refine: f64,
    /// The earlier survey's held-out look before and after (`previous_look_psnr_*`).
    pub previous_look: f64,
    pub total: f64,
}

/// The updated model and its report.
#[derive(Clone, Debug)]
pub struct UpdateOutcome {
    pub splats: Splats,
    pub report: UpdateReport,
    /// Cancelled before the end: `splats` is the model as far as it got, and nothing should be
    /// recorded.
    pub cancelled: bool,
}

/// Writes an update's result into the project (`commit_update`), with the training `history`
/// that made it. Returns the model's path.
pub fn record_update(
    twin: &mut Twin,
    outcome: &UpdateOutcome,
    history: Option<&History>,
) -> Result<std::path::PathBuf, TimelineError> {
    let report = &outcome.report;
    commit_update(
        twin,
        &report.survey,
        &outcome.splats,
        report,
        report.appearance,
        history,
    )
}

/// The end of an update, as one commit (`Twin::commit`): survey `name`'s model, its
/// `metrics.json` (`report`), its training `history` and its light (no other survey's files or
/// records) written into the project as it is now, re-read under its lock, so whatever another
/// command recorded while the update trained stays. All or nothing: the three files replace the
/// previous update's together or not at all (a previous `history.json` does not stay beside a
/// model committed without one). Returns the model's path.
pub fn commit_update(
    twin: &mut Twin,
    name: &str,
    splats: &Splats,
    report: &impl Serialize,
    appearance: Option<ColourTransform>,
    history: Option<&History>,
) -> Result<std::path::PathBuf, TimelineError> {
    twin.commit(|twin| {
        let index = twin.survey_index(name)?;
        let path = twin.save_model(name, splats)?;
        twin.save_metrics(name, report)?;
        match history {
            Some(history) => twin.save_history(name, history).map(drop)?,
            None => twin.replaces(name, HISTORY_FILE)?,
        }
        twin.project.surveys[index].appearance = appearance;
        Ok(path)
    })
}

impl UpdateReport {
    /// Adds the held-out PSNR before (at 0 s) and after (at `seconds`, the wall time the update's
    /// progress was recorded against) to the update's progress `history`.
    pub fn record_scores(&self, history: &mut History, seconds: f64) {
        if let Some(psnr) = self.refine.before.psnr {
            let before = EvalSample {
                wall_s: 0.0,
                step: 0,
                psnr,
            };
            history.evals.insert(0, before);
        }
        history.record_final(self.refine.after.psnr, seconds);
    }
}

/// Tags damage Gaussians with no survey yet as first seen in `survey` (label probability above
/// one half in any class). Returns how many it tagged.
pub fn tag_damage(splats: &mut Splats, survey: u16) -> usize {
    let channels = splats.label_channels;
    let mut tagged = 0;
    for g in 0..splats.len() {
        if splats.meta.damage_survey[g] != NO_SURVEY || channels == 0 {
            continue;
        }
        if splats.labels_of(g).iter().any(|&l| sigmoid(l) > 0.5) {
            splats.meta.damage_survey[g] = survey;
            tagged += 1;
        }
    }
    tagged
}

/// Starts the update of `survey` from the survey before it.
pub fn update_job(
    twin: Twin,
    survey: String,
    config: UpdateConfig,
    options: JobOptions,
) -> Job<UpdateOutcome> {
    Job::spawn("update", options, move |ctx| {
        update(ctx, &twin, &survey, &config)
    })
}

/// The update of `survey` written into the project when it finishes (`record_update`, with the
/// job's progress as the model's training history); the project as saved comes back with the
/// outcome. A cancelled or failed update writes nothing.
pub fn update_project_job(
    mut twin: Twin,
    survey: String,
    config: UpdateConfig,
    options: JobOptions,
) -> Job<(Twin, UpdateOutcome)> {
    Job::spawn("update", options, move |ctx| {
        ctx.keep_history();
        let outcome = update(ctx, &twin, &survey, &config)?;
        if !outcome.cancelled {
            let (mut history, seconds) = ctx.take_history();
            outcome.report.record_scores(&mut history, seconds);
            record_update(&mut twin, &outcome, Some(&history)).map_err(timeline_error)?;
        }
        Ok((twin, outcome))
    })
}

fn timeline_error(e: TimelineError) -> JobError {
    JobError::other(e)
}

/// The update of survey `name` in the calling job.
pub fn update(
    ctx: &mut JobContext,
    twin: &Twin,
    name: &str,
    config: &UpdateConfig,
) -> Result<UpdateOutcome, JobError> {
    let started = PhaseClock::start();
    let mut times = PhaseTimes::<UpdatePhaseSeconds>::new();
    let t = PhaseClock::start();
    let index = twin.survey_index(name).map_err(timeline_error)?;
    let previous = index
        .checked_sub(1)
        .map(|i| twin.project.surveys[i].name.clone())
        .ok_or_else(|| {
            JobError::Invalid(format!(
                "`{name}` is the first survey: there is no twin to update (train it with `twin new`)"
            ))
        })?;
    let mut model = twin
        .load_model(&previous)
        .map_err(timeline_error)?
        .ok_or_else(|| {
            JobError::Invalid(format!(
                "survey `{previous}` has no model yet: update or train it first"
            ))
        })?;
    // Damage the previous twin knows is old: first seen there at the latest.
    tag_damage(&mut model, (index - 1) as u16);
    let mut dataset = twin.open_survey_dataset(name).map_err(timeline_error)?;
    // Every phase reads the survey's views (the floaters' masks, the light fit, the seeds, the
    // selection, the crops, the held-out scoring): each is decoded and resized once, and the
    // kept views go when the update ends (`Dataset::keep_loaded_views`).
    dataset.keep_loaded_views();
    let readout = DamageReadout {
        mode: config.refine.select.mode,
        ..DamageReadout::for_model(&model, config.refine.select.palette)
    };
    let mut refine_config = config.refine.clone();
    refine_config.select.lift_unlabelled = true;
    let (train_idx, _) =
        split_views(&dataset, &refine_config.holdout).map_err(JobError::Invalid)?;
    refine_config.iterations = config.iterations_for(train_idx.len());
    times.record(&t, |p| &mut p.load);

    // The twin as the update trains it: without its near floaters and with its new-damage
    // seeds, when those are on; the twin itself otherwise. The floaters are cleared first (they
    // need no light), so the light fit renders the twin the seeds render, once per view.
    let t = PhaseClock::start();
    let mut seeded = None;
    let mut cleared = Vec::new();
    if config.clear_near_floaters {
        let mut without = model.clone();
        cleared = clear_near_floaters(&mut without, &dataset, &train_idx, &refine_config)?;
        if !cleared.is_empty() {
            ctx.log(format!("cleared {} near floaters", cleared.len()));
            seeded = Some(without);
        }
    }
    times.record(&t, |p| &mut p.near_floaters);

    // Each photo's light relative to the twin's rides on its training view.
    let t = PhaseClock::start();
    let mut lights = ViewLights::new();
    let mut appearance = None;
    let mut rendered = BTreeMap::new();
    if config.appearance {
        ctx.log("fitting each photo's light against the twin");
        let trained = seeded.as_ref().unwrap_or(&model);
        // The seeds read the training views' renders only when they are on.
        let keep: &[usize] = if config.seeds.is_some() {
            &train_idx
        } else {
            &[]
        };
        let fit = fit_appearance(trained, &dataset, &refine_config, &readout, keep)?;
        lights = fit.lights;
        appearance = Some(fit.pooled);
        rendered = fit.renders;
    }
    times.record(&t, |p| &mut p.appearance);

    let t = PhaseClock::start();
    let seeds = match &config.seeds {
        Some(seed_config) => {
            let settings = RenderSettings::new(refine_config.background, model.sh_degree);
            let with_seeds = seeded.get_or_insert_with(|| model.clone());
            let report = seed_new_damage(
                with_seeds,
                &dataset,
                &train_idx,
                refine_config.scale,
                &settings,
                &readout,
                &lights,
                seed_config,
                &rendered,
            )?;
            ctx.log(format!("new-damage seeds: {:?}", report.seeds));
            Some(report)
        }
        None => None,
    };
    drop(rendered);
    times.record(&t, |p| &mut p.seeds);
    let t = PhaseClock::start();
    let seeded = seeded.as_ref().unwrap_or(&model);
    let outcome = refine_from(ctx, &dataset, &lights, &model, seeded, &refine_config)?;
    times.record(&t, |p| &mut p.refine);
    let mut splats = (*outcome.splats).clone();
    // History: what the update trained or created changed in this survey (the seeds count as
    // created); damage nobody saw before is this survey's.
    let survey = index as u16;
    let changed = trained_or_created(
        &splats,
        seeded,
        &outcome.selection.selected,
        model.meta.next_id(),
    );
    for (g, changed) in changed.into_iter().enumerate() {
        if changed {
            splats.meta.survey[g] = survey;
        }
    }
    for &g in &cleared {
        splats.meta.survey[g] = survey;
    }
    let new_damage = tag_damage(&mut splats, survey);
    let old_damage = splats
        .meta
        .damage_survey
        .iter()
        .filter(|&&s| s != NO_SURVEY && s < survey)
        .count();
    let t = PhaseClock::start();
    let (look_before, look_after) = if outcome.cancelled {
        (None, None)
    } else {
        previous_look(twin, &previous, &model, &splats, &readout)?
    };
    times.record(&t, |p| &mut p.previous_look);
    times.record(&started, |p| &mut p.total);
    Ok(UpdateOutcome {
        splats,
        report: UpdateReport {
            survey: name.to_string(),
            previous,
            appearance,
            new_damage_gaussians: new_damage,
            old_damage_gaussians: old_damage,
            previous_look_psnr_before: look_before,
            previous_look_psnr_after: look_after,
            seeds,
            near_floaters_cleared: cleared.len(),
            seconds: times.wall.total,
            phase_seconds: times.wall,
            phase_cpu_seconds: times.cpu,
            refine: outcome.report,
        },
        cancelled: outcome.cancelled,
    })
}

/// A cleared Gaussian's opacity: below the renderer's alpha threshold at its centre, so it
/// draws nothing (and, frozen, stays so).
const CLEARED_OPACITY: f32 = 1e-4;

/// A near floater is cleared when its blending weight over the damage pixels of the views it
/// floats in front of adds up to at least this many pixels (at the selection scale).
const FLOATER_DAMAGE_WEIGHT: f32 = 1.0;

/// Clears (opacity to `CLEARED_OPACITY`) every Gaussian of `model` that is a near floater
/// (`near_floaters::near_floaters`) of one of `views`' cameras and covers that view's damage masks.
/// A later survey flies where the earlier one did not: on the demo building survey 2 flies
/// twice as high, and one opaque 4 m floater that survey 1 left there sat in front of survey
/// 2's cameras. Outside the selection it stays frozen, so the update can neither remove it nor
/// fit the cracks behind it, and the held-out views lose the old cracks it covers
/// (docs/TIMELINE.md). Detection, the light fit and the seeds already leave near floaters out;
/// only those over damage are cleared here, because clearing every near floater (1,674 on the
/// demo) cost survey 1's views 1.9 dB. Returns the indices cleared, ascending.
pub fn clear_near_floaters(
    model: &mut Splats,
    dataset: &Dataset,
    views: &[usize],
    config: &RefineConfig,
) -> Result<Vec<usize>, JobError> {
    let Some(masks) = dataset.masks.clone() else {
        return Ok(Vec::new());
    };
    let settings = RenderSettings::new(config.background, model.sh_degree);
    let mut lift = WeightLift::new(model, 1, settings);
    let mut over_damage = vec![0.0f32; model.len()];
    for &view in views {
        let near: Vec<u32> = near_floaters(model, &dataset.views[view].camera)
            .iter()
            .enumerate()
            .filter_map(|(g, &floats)| floats.then_some(g as u32))
            .collect();
        if near.is_empty() {
            continue;
        }
        let (camera, view_masks) =
            dataset.load_view_masks(view, masks.as_ref(), config.select_scale)?;
        let damage = |p: usize| view_masks.values().any(|m| m.data[p] != 0);
        // Only the near floaters' weights are read: rendering their tiles gives them bit for
        // bit (`WeightLift::view_of`).
        let weights = lift.view_of(&camera, &near, |p, _| f32::from(damage(p)));
        for &g in &near {
            over_damage[g as usize] += weights[g as usize];
        }
    }
    let cleared: Vec<usize> = (0..model.len())
        .filter(|&g| over_damage[g] >= FLOATER_DAMAGE_WEIGHT)
        .collect();
    for &g in &cleared {
        model.raw_opacities[g] = logit(CLEARED_OPACITY);
    }
    Ok(cleared)
}

/// PSNR of the previous survey's held-out views outside the damage (theirs and the renders'),
/// for the model before and after the update.
fn previous_look(
    twin: &Twin,
    previous: &str,
    before: &Splats,
    after: &Splats,
    readout: &DamageReadout,
) -> Result<(Option<f64>, Option<f64>), JobError> {
    let dataset = twin.open_survey_dataset(previous).map_err(timeline_error)?;
    let every = twin.project.settings.held_out_every.max(1) as usize;
    let (_, heldout) = split_views(&dataset, &crate::train::views::Holdout::Auto { every })
        .map_err(JobError::Invalid)?;
    let scale = crate::scene::ImageScale::Factor(2);
    let mut se = [0.0f64; 2];
    let mut n = 0usize;
    for &index in &heldout {
        let loaded = dataset.load_view(index, scale)?;
        let settings = RenderSettings::new(
            glam::Vec3::from_array(twin.project.settings.background),
            before.sh_degree,
        );
        let outs = [
            render(before, &loaded.camera, &settings),
            render(after, &loaded.camera, &settings),
        ];
        let mut masks: Vec<Mask> = loaded.masks.values().cloned().collect();
        for out in &outs {
            masks.extend(predicted_masks(out, readout));
        }
        let refs: Vec<&Mask> = masks.iter().collect();
        let keep = unchanged_pixels(&refs, loaded.image.width, loaded.image.height, 2);
        for (p, k) in keep.iter().enumerate() {
            if !k {
                continue;
            }
            for (i, out) in outs.iter().enumerate() {
                for c in 0..3 {
                    let d = f64::from(out.color[p * 3 + c] - loaded.image.data[p * 3 + c]);
                    se[i] += d * d;
                }
            }
            n += 3;
        }
    }
    let psnr = |s: f64| (n > 0).then(|| -10.0 * (s / n as f64).max(1e-12).log10());
    Ok((psnr(se[0]), psnr(se[1])))
}

/// Held-out quality of the update, for callers that print one line.
pub fn summary(report: &UpdateReport) -> (&Quality, &Quality) {
    (&report.refine.before, &report.refine.after)
}
