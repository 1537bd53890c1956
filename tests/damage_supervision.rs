//! Damage supervision end to end on a small synthetic survey: label and overlay runs learn the
//! damage (scored against the clean truth masks on held-out views), and the mask-noise study
//! reports the corrupted inputs and the twin against the clean masks.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::OnceLock;

use damage_twin::damage::evaluate::{DamageReadout, evaluate_damage};
use damage_twin::damage::reference::{load_reference_views, reference_source};
use damage_twin::damage::setup::{RunConfig, prepare_run};
use damage_twin::damage::{DamageClass, Palette, TrainMode};
use damage_twin::metrics::MaskAgreement;
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{Dataset, ImageScale};
use damage_twin::splats::Splats;
use damage_twin::studies::mask_noise::{NoiseModel, StudyConfig, StudyStage, run_study};
use damage_twin::synth::params::SynthParams;
use damage_twin::train::job::JobOptions;
use damage_twin::train::run::train;

/// One survey of the demo building at 240×135 with 24 views, generated once per test binary.
fn survey() -> &'static Dataset {
    static DATA: OnceLock<(tempfile::TempDir, Dataset)> = OnceLock::new();
    &DATA
        .get_or_init(|| {
            let dir = tempfile::tempdir().expect("temp dir");
            let params = SynthParams {
                width: 240,
                height: 135,
                views: 24,
                surveys: 1,
                sparse_points: 6000,
                ..SynthParams::demo(dir.path())
            };
            damage_twin::synth::generate::generate(&params, &|_, _| {}).expect("synth");
            let root: PathBuf = dir.path().join("survey-1");
            let dataset = Dataset::open(&root, &OpenOptions::default()).expect("opens");
            (dir, dataset)
        })
        .1
}

fn config(mode: TrainMode, iterations: u32) -> RunConfig {
    RunConfig {
        mode,
        scale: ImageScale::Factor(1),
        iterations,
        seed: 3,
        ..RunConfig::default()
    }
}

type Iou = BTreeMap<String, f64>;

/// Trains `config` on the survey and scores damage against the clean truth masks: (model, IoU on
/// held-out views before training, after training, IoU on the training views after training).
fn train_and_score(config: &RunConfig) -> (Splats, Iou, Iou, Iou) {
    let dataset = survey();
    let run = prepare_run(dataset, config).expect("run prepares");
    assert_eq!(run.mode, config.mode);
    let heldout_indices = run.heldout_indices.clone();
    let train_indices = run.train_indices.clone();
    let outcome = train(run.setup, JobOptions::default())
        .wait()
        .expect("training finishes");
    let splats = (*outcome.splats).clone();
    let source = reference_source(dataset).expect("synth writes truth/");
    assert!(source.masks().describe().ends_with("truth/masks"));
    let heldout =
        load_reference_views(dataset, &source, &heldout_indices, config.scale).expect("truth");
    let readout = DamageReadout {
        mode: config.mode,
        ..DamageReadout::for_model(&splats, Palette::default())
    };
    let before = evaluate_damage(
        &prepare_run(dataset, config).expect("again").setup.splats,
        &heldout,
        &readout,
        config.background,
    )
    .per_class(MaskAgreement::iou);
    let after = evaluate_damage(&splats, &heldout, &readout, config.background)
        .per_class(MaskAgreement::iou);
    let train =
        load_reference_views(dataset, &source, &train_indices, config.scale).expect("truth");
    let fit =
        evaluate_damage(&splats, &train, &readout, config.background).per_class(MaskAgreement::iou);
    (splats, before, after, fit)
}

#[test]
fn label_mode_learns_the_damage_on_held_out_views() {
    let (splats, before, after, fit) = train_and_score(&config(TrainMode::Label, 400));
    assert_eq!(splats.label_channels, DamageClass::ALL.len());
    eprintln!(
        "label mode IoU: held-out before {before:?}, after {after:?}; training views {fit:?}"
    );
    // Untrained labels (logit -4) render no damage at all.
    assert!(
        before["spalling"] < 0.01 && before["crack"] < 0.01,
        "{before:?}"
    );
    // A 24-view building at 240×135 after 400 steps is far from converged (the demo-building
    // figures are in docs/DAMAGE.md); this checks that masks reach the label channels and the
    // channels render where the damage is, also from views the twin never saw.
    assert!(fit["spalling"] > 0.25 && fit["crack"] > 0.05, "{fit:?}");
    assert!(after["spalling"] > 0.1, "{after:?}");

    // The CLI reads the same figures back from the saved model.
    let dir = tempfile::tempdir().expect("temp dir");
    let model = dir.path().join("model.ply");
    damage_twin::splats::ply::write_splats(&model, &splats).expect("model saves");
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_damage-twin"))
        .arg("eval")
        .arg(&model)
        .arg(&survey().root)
        .arg("--json")
        .output()
        .expect("eval runs");
    assert!(output.status.success(), "{output:?}");
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).expect("JSON");
    assert_eq!(report["damage_mode"], "label");
    for figure in ["iou", "precision", "recall", "f1"] {
        for class in ["crack", "spalling"] {
            let value = report[figure][class].as_f64();
            assert!(
                value.is_some_and(|v| (0.0..=1.0).contains(&v)),
                "{figure}.{class}: {report}"
            );
        }
    }
    let cli_iou = report["iou"]["spalling"].as_f64().unwrap_or(-1.0);
    assert!(
        (cli_iou - after["spalling"]).abs() < 1e-9,
        "{cli_iou} vs {after:?}"
    );
}

#[test]
fn overlay_mode_paints_the_targets_and_reads_the_colours_back() {
    let dataset = survey();
    let overlay = prepare_run(dataset, &config(TrainMode::Overlay, 1)).expect("prepares");
    let plain = prepare_run(dataset, &config(TrainMode::Rgb, 1)).expect("prepares");
    let labelled = prepare_run(dataset, &config(TrainMode::Label, 1)).expect("prepares");
    assert_eq!(overlay.setup.splats.label_channels, 0);
    // The colours are chosen against the photos and travel with the model.
    let chosen = overlay
        .setup
        .splats
        .overlay
        .expect("overlay colours with the model");
    let red = Palette::from_overlay(&chosen).unit_colour(DamageClass::Crack);
    let mut painted = 0;
    for ((o, p), l) in overlay
        .setup
        .views
        .iter()
        .zip(&plain.setup.views)
        .zip(&labelled.setup.views)
    {
        assert!(o.labels.is_empty() && p.labels.is_empty());
        let crack = &l.labels[DamageClass::Crack.channel()];
        let later = &l.labels[1..];
        for (i, &m) in crack.data.iter().enumerate() {
            let on_top = later.iter().any(|mask| mask.data[i] != 0);
            if m != 0 && !on_top {
                assert_eq!(
                    &o.image.data[i * 3..i * 3 + 3],
                    &red,
                    "{} pixel {i}",
                    o.name
                );
                painted += 1;
            } else if m == 0 && !on_top {
                assert_eq!(
                    &o.image.data[i * 3..i * 3 + 3],
                    &p.image.data[i * 3..i * 3 + 3]
                );
            }
        }
    }
    assert!(painted > 100, "only {painted} crack pixels painted");

    let (_, before, after, fit) = train_and_score(&config(TrainMode::Overlay, 400));
    eprintln!(
        "overlay mode IoU: held-out before {before:?}, after {after:?}; training views {fit:?}"
    );
    // Overlay colours are read back only where the render matches the class colour within the
    // tolerance: the twin must have started to reproduce painted pixels somewhere.
    assert!(
        after["spalling"] > before["spalling"],
        "{before:?} → {after:?}"
    );
    assert!(fit["spalling"] > 0.0, "{fit:?}");
}

#[test]
fn the_mask_noise_study_scores_corrupted_inputs_and_the_twin_against_clean_masks() {
    let study = StudyConfig {
        // Out of order: the study runs rate 0 first, whose twin the other rates compare with.
        rates: vec![0.5, 0.0],
        modes: vec![TrainMode::Label],
        run: RunConfig {
            ..config(TrainMode::Label, 300)
        },
        noise: NoiseModel::Views,
        noise_seed: 5,
        threads: None,
        fine_iterations: 0,
        fine_label_geometry_until: None,
        fine_label_pos_weight: 2.0,
    };
    let mut finished = 0;
    let rows = run_study(survey(), &study, &mut |event| {
        if let damage_twin::studies::mask_noise::StudyEvent::RunFinished { .. } = event {
            finished += 1;
        }
    })
    .expect("study runs");
    assert_eq!(finished, 2);
    for class in [DamageClass::Crack, DamageClass::Spalling] {
        let row = |rate: f32| {
            rows.iter()
                .find(|r| r.class == class && r.rate == rate)
                .unwrap_or_else(|| panic!("no {class} row at {rate}: {rows:?}"))
        };
        let (clean, noisy) = (row(0.0), row(0.5));
        eprintln!("{clean:?}\n{noisy:?}");
        assert_eq!(clean.input_iou, 1.0);
        assert_eq!(clean.noisy_views, 0);
        assert_eq!(
            noisy.noisy_views, 11,
            "half of the 21 training views, rounded half away from zero"
        );
        assert!(noisy.input_iou < 0.95, "{noisy:?}");
        // What the clean-mask twin makes of the pixels the corruption got wrong.
        assert!(clean.clean_twin_corrected.is_nan(), "{clean:?}");
        assert!(
            (0.0..=1.0).contains(&noisy.clean_twin_corrected),
            "{noisy:?}"
        );
        for r in [clean, noisy] {
            for v in [r.twin_iou_train, r.twin_iou_heldout] {
                assert!((0.0..=1.0).contains(&v), "{r:?}");
            }
        }
        // The twin has learnt some of the damage despite the noisy views (the study's real
        // figures are in docs/DAMAGE.md).
        if class == DamageClass::Spalling {
            assert!(noisy.twin_iou_train > 0.05, "{noisy:?}");
        }
    }

    // The paper's model: every view corrupted by 0.4 × its own damage area per class; the
    // label-mode twin also refined at the photos' resolution on masks corrupted there.
    let area = StudyConfig {
        rates: vec![0.4],
        noise: NoiseModel::Area,
        run: config(TrainMode::Label, 800),
        fine_iterations: 20,
        ..study
    };
    let mut fine_errors = Vec::new();
    let rows = run_study(survey(), &area, &mut |event| {
        if let damage_twin::studies::mask_noise::StudyEvent::FineFailed { error, .. } = event {
            fine_errors.push(error);
        }
    })
    .expect("study runs");
    assert!(fine_errors.is_empty(), "{fine_errors:?}");
    let stages: Vec<StudyStage> = rows.iter().map(|r| r.stage).collect();
    assert!(
        stages.contains(&StudyStage::Coarse) && stages.contains(&StudyStage::Finetune),
        "{stages:?}"
    );
    for r in rows.iter().filter(|r| r.class != DamageClass::Rebar) {
        eprintln!("{r:?}");
        assert_eq!(r.noisy_views, 21, "every training view");
        // Added and removed regions of 0.4 × the damage: IoU about 1 / 1.4 or less.
        assert!((0.45..0.85).contains(&r.input_iou), "{r:?}");
        assert!(r.corrupted_pixels > 0, "{r:?}");
        assert!((0.0..=1.0).contains(&r.errors_corrected), "{r:?}");
        assert!((0.0..0.2).contains(&r.errors_introduced), "{r:?}");
    }
}

#[test]
fn the_stability_suite_perturbs_only_the_training_views_and_scores_the_held_out_ones() {
    use damage_twin::studies::stability::{Perturbation, perturb, stability_run};
    let dataset = survey();
    let base = config(TrainMode::Label, 60);
    let run = prepare_run(dataset, &base).expect("prepares");
    let training = run.setup.views.clone();

    let mut few = training.clone();
    perturb(&mut few, Perturbation::Views(5)).expect("five views");
    let names: Vec<&str> = few.iter().map(|v| v.name.as_str()).collect();
    let spread: Vec<&str> = [0, 4, 8, 12, 16]
        .iter()
        .map(|&i| training[i].name.as_str())
        .collect();
    assert_eq!((training.len(), names), (21, spread));
    let err = perturb(&mut few, Perturbation::Views(1000)).expect_err("too many");
    assert!(err.contains("1000 training views"), "{err}");

    let mut noisy = training.clone();
    let noise = Perturbation::PoseNoise {
        degrees: 2.0,
        seed: 1,
    };
    perturb(&mut noisy, noise).expect("noise");
    for (before, after) in training.iter().zip(&noisy) {
        let turned = before.camera.rotation.angle_between(after.camera.rotation);
        assert!(
            (turned.to_degrees() - 2.0).abs() < 0.01,
            "{}",
            turned.to_degrees()
        );
        assert!(before.camera.position().distance(after.camera.position()) > 0.0);
        assert_eq!(before.image, after.image);
    }

    // A row scores the held-out views, posed exactly, at the training size.
    let row = stability_run(dataset, &base, noise, "pose_noise", 2.0, None).expect("trains");
    assert_eq!((row.axis.as_str(), row.value), ("pose_noise", 2.0));
    assert_eq!((row.width, row.height), (240, 135));
    assert!(row.psnr.is_finite() && row.ssim.is_some());
    assert_eq!(
        row.iou.keys().collect::<Vec<_>>(),
        ["crack", "rebar", "spalling"]
    );
}
