//! The survey timeline end to end on a tiny two-survey building: a coarse twin of survey 1, survey 2
//! placed in its frame, change detection and the targeted update. Checks what the library
//! promises, not quality (the demo-scale figures are in docs/TIMELINE.md): the change maps are
//! consistent with the masks they come from, the update writes survey 2's model only, survey 1's
//! model file is byte-identical afterwards, and new damage carries survey 2's tag.

mod twin_support;

use damage_twin::damage::Palette;
use damage_twin::damage::evaluate::DamageReadout;
use damage_twin::damage::refine::{RefineConfig, Strategy};
use damage_twin::scene::Camera;
use damage_twin::scene::ImageScale;
use damage_twin::splats::Splats;
use damage_twin::splats::model::{NO_SURVEY, logit, sigmoid};
use damage_twin::timeline::Twin;
use damage_twin::timeline::appearance::fit_appearance;
use damage_twin::timeline::changes::{DetectConfig, OLD_DAMAGE_THRESHOLD, detect};
use damage_twin::timeline::seed::{SeedConfig, seed_new_damage};
use damage_twin::timeline::survey::AlignMode;
use damage_twin::timeline::update::{UpdateConfig, clear_near_floaters, update_job};
use damage_twin::train::job::JobOptions;
use damage_twin::train::views::split_views;

#[test]
fn detection_and_update_keep_the_history() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, mut coarse) = twin_support::coarse_twin(dir.path(), 2);
    // Survey 2 flies where survey 1 did not: an opaque floater right in front of one of its
    // training cameras, which no view of survey 1 constrained (as on the demo building).
    let survey_two = damage_twin::scene::Dataset::open(
        &dir.path().join("synth/survey-2"),
        &damage_twin::scene::open::OpenOptions::default(),
    )
    .expect("opens survey 2");
    let floater_id = put_floater(&mut coarse, &survey_two.views[1].camera);

    let mut twin = Twin::create(&dir.path().join("project")).expect("creates the project");
    twin.add_survey("2024", "2024-06-01", &dir.path().join("synth/survey-1"))
        .expect("adds survey 1");
    let first_model = twin.save_model("2024", &coarse).expect("saves survey 1");
    twin.save().expect("saves the project");
    let placed = twin
        .add_placed_survey(
            "2025",
            "2025-06-01",
            &dir.path().join("synth/survey-2"),
            AlignMode::SameFrame,
        )
        .expect("places survey 2");
    assert!(placed.is_none(), "same-frame needs no registration");
    twin.save().expect("saves the project");
    let first_bytes = std::fs::read(&first_model).expect("reads survey 1's model");

    // Change detection: every map is consistent with the masks it was made from.
    let palette = Palette::default();
    let config = DetectConfig {
        scale: ImageScale::Factor(2),
        readout: DamageReadout::for_model(&coarse, palette),
        background: glam::Vec3::ZERO,
        band_px: 2,
        min_area_px: 6,
        vote: true,
        old_threshold: OLD_DAMAGE_THRESHOLD,
    };
    let dataset = twin.open_survey_dataset("2025").expect("opens survey 2");
    let mut progress = Vec::new();
    let detection = detect(&coarse, &dataset, &config, None, &mut |done, total| {
        progress.push((done, total))
    })
    .expect("detects");
    assert_eq!(detection.views.len(), dataset.views.len());
    assert_eq!(
        progress.last().map(|&(done, total)| done == total),
        Some(true)
    );
    let mut observed_pixels = 0;
    for view in &detection.views {
        for class in 0..view.observed.len() {
            let (old, seen) = (&view.old[class], &view.observed[class]);
            let (new, gone) = (&view.new[class], &view.gone[class]);
            assert_eq!((new.width, new.height), (seen.width, seen.height));
            for p in 0..seen.data.len() {
                let [is_old, is_seen] = [old.data[p] != 0, seen.data[p] != 0];
                let [is_new, is_gone] = [new.data[p] != 0, gone.data[p] != 0];
                assert!(!is_new || is_seen, "{}: new but not seen", view.name);
                assert!(!is_new || !is_old, "{}: new but old", view.name);
                assert!(!is_gone || is_old, "{}: gone but not old", view.name);
                assert!(!is_gone || !is_seen, "{}: gone but seen", view.name);
            }
            observed_pixels += seen.data.iter().filter(|&&d| d != 0).count();
        }
    }
    assert!(observed_pixels > 0, "survey 2 has damage to compare");
    let steps: Vec<&str> = detection.steps.iter().map(|s| s.step.as_str()).collect();
    assert_eq!(steps.first(), Some(&"raw"));
    assert!(
        detection
            .summary()
            .is_some_and(|s| !s.truth_pixels.is_empty()),
        "the synthetic survey's truth/new-damage is scored"
    );

    // The update: survey 2's model is written, survey 1's is not touched.
    let config = UpdateConfig {
        refine: RefineConfig {
            strategy: Strategy::Finetune,
            scale: ImageScale::Factor(1),
            select_scale: ImageScale::Factor(2),
            iterations: 40,
            ..RefineConfig::default()
        },
        appearance: true,
        seeds: Some(SeedConfig::default()),
        clear_near_floaters: true,
        iterations_by_views: false,
    };
    let outcome = update_job(
        twin.clone(),
        "2025".into(),
        config,
        JobOptions::headless(None),
    )
    .wait()
    .expect("updates");
    // The cost comparison is `bench --refine`'s: an update times no full-image steps.
    assert!(outcome.report.refine.step_costs.is_none());
    assert!(outcome.report.refine.ms_per_full_step.is_none());
    let second_model = twin
        .save_model("2025", &outcome.splats)
        .expect("saves survey 2");
    twin.save().expect("saves the project");
    assert_ne!(first_model, second_model);
    assert_eq!(
        std::fs::read(&first_model).expect("reads survey 1's model again"),
        first_bytes,
        "survey 1's model is byte-identical after the update"
    );

    // History: survey 2's model holds survey 1's Gaussians (fine-tune keeps them all) and the
    // new-damage seeds, with survey 1's damage tagged 0 and the damage first seen now tagged 1.
    let reopened = Twin::open(&dir.path().join("project")).expect("reopens");
    let updated = reopened
        .load_model("2025")
        .expect("loads")
        .expect("survey 2 has a model");
    let before = reopened
        .load_model("2024")
        .expect("loads")
        .expect("survey 1 has a model");
    let seeds: usize = outcome
        .report
        .seeds
        .as_ref()
        .expect("seeding is on")
        .seeds
        .values()
        .sum();
    assert!(seeds > 0, "survey 2's new damage is seeded");
    assert_eq!(updated.len(), before.len() + seeds);
    assert_eq!(
        updated.meta.ids[..before.len()],
        before.meta.ids[..],
        "survey 1's Gaussians come first, in order"
    );
    let first_seed = before.meta.next_id();
    assert!(
        updated.meta.ids[before.len()..]
            .iter()
            .all(|&id| id >= first_seed),
        "seeds take fresh ids"
    );
    assert!(
        updated.meta.survey[before.len()..].iter().all(|&s| s == 1),
        "seeds appeared in survey 2"
    );
    let tags = &updated.meta.damage_survey;
    let new_tagged = tags.iter().filter(|&&s| s == 1).count();
    let old_tagged = tags.iter().filter(|&&s| s == 0).count();
    assert_eq!(new_tagged, outcome.report.new_damage_gaussians);
    assert_eq!(old_tagged, outcome.report.old_damage_gaussians);
    assert!(old_tagged > 0, "survey 1's damage is tagged as old");
    assert!(
        tags.iter().all(|&s| s == NO_SURVEY || s <= 1),
        "no tag beyond the surveys there are"
    );
    let survey_one_tags = before
        .meta
        .damage_survey
        .iter()
        .filter(|&&s| s != NO_SURVEY)
        .count();
    assert!(
        survey_one_tags <= old_tagged,
        "tags of survey 1's model are kept"
    );
    assert!(outcome.report.appearance.is_some(), "the light was fitted");

    // The floater in front of survey 2's camera is cleared (it would otherwise stay, frozen, over
    // the damage behind it), and the clearing is survey 2's change.
    assert!(outcome.report.near_floaters_cleared >= 1);
    let floater = updated
        .meta
        .ids
        .iter()
        .position(|&id| id == floater_id)
        .expect("the floater keeps its place");
    assert!(
        sigmoid(updated.raw_opacities[floater]) < 0.01,
        "the near floater is cleared: opacity {}",
        sigmoid(updated.raw_opacities[floater])
    );
    assert_eq!(updated.meta.survey[floater], 1);
}

/// The update renders the twin it trains (its near floaters cleared) once per view for the
/// light fit and the seeds: the seeds take the renders the fit kept, and are the same bit for
/// bit as when they render the twin themselves.
#[test]
fn the_light_fit_and_the_seeds_share_their_renders() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (_, mut coarse) = twin_support::coarse_twin(dir.path(), 2);
    let dataset = damage_twin::scene::Dataset::open(
        &dir.path().join("synth/survey-2"),
        &damage_twin::scene::open::OpenOptions::default(),
    )
    .expect("opens survey 2");
    put_floater(&mut coarse, &dataset.views[1].camera);
    let config = RefineConfig {
        scale: ImageScale::Factor(1),
        select_scale: ImageScale::Factor(2),
        ..RefineConfig::default()
    };
    let (train_idx, _) = split_views(&dataset, &config.holdout).expect("splits");
    let mut trained = coarse.clone();
    let cleared = clear_near_floaters(&mut trained, &dataset, &train_idx, &config).expect("clears");
    assert!(!cleared.is_empty(), "the floater is cleared");
    let readout = DamageReadout::for_model(&coarse, Palette::default());

    let plain = fit_appearance(&trained, &dataset, &config, &readout, &[]).expect("fits");
    assert!(plain.renders.is_empty());
    let shared = fit_appearance(&trained, &dataset, &config, &readout, &train_idx).expect("fits");
    assert_eq!(shared.lights, plain.lights);
    assert_eq!(shared.pooled, plain.pooled);
    assert_eq!(
        shared.renders.keys().copied().collect::<Vec<_>>(),
        train_idx
    );

    let settings = damage_twin::raster::RenderSettings::new(config.background, coarse.sh_degree);
    let seed_config = SeedConfig::default();
    // Seeded with the seeds' own renders (none given) and with the light fit's.
    let no_renders = std::collections::BTreeMap::new();
    let seeded_with = |rendered| {
        let mut seeded = trained.clone();
        let report = seed_new_damage(
            &mut seeded,
            &dataset,
            &train_idx,
            config.scale,
            &settings,
            &readout,
            &shared.lights,
            &seed_config,
            rendered,
        )
        .expect("seeds");
        (seeded, report)
    };
    let (seeded_plain, report_plain) = seeded_with(&no_renders);
    let (seeded, report) = seeded_with(&shared.renders);
    assert_eq!(report, report_plain);
    assert!(seeded.len() > trained.len(), "seeds were planted");
    assert!(seeded == seeded_plain, "the seeded models differ");
}

/// Appends an opaque, undamaged Gaussian a tenth of the median depth in front of `camera`, wide
/// enough to cover much of its view. Returns its id.
fn put_floater(model: &mut Splats, camera: &Camera) -> u64 {
    let mut depths: Vec<f32> = model
        .means
        .iter()
        .map(|&m| camera.world_to_camera(m).z)
        .filter(|&z| z > 0.0)
        .collect();
    depths.sort_by(f32::total_cmp);
    let depth = 0.1 * depths[depths.len() / 2];
    let mean = camera.position() + camera.rotation.inverse() * glam::Vec3::new(0.0, 0.0, depth);
    let id = model.meta.ids.iter().max().map_or(0, |&m| m + 1);
    let sh = vec![0.0; model.sh_coeffs() * 3];
    let labels = vec![logit(0.01); model.label_channels];
    model.push(
        mean,
        glam::Vec3::splat((0.3 * depth).ln()),
        glam::Quat::IDENTITY,
        logit(0.95),
        &sh,
        &labels,
        id,
        0,
    );
    id
}
