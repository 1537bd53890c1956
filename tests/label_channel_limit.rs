//! One label-channel limit (`splats::MAX_LABEL_CHANNELS`), enforced where a PLY is read: a model
//! with more `label_*` properties is refused with one line naming the file by the reader, by
//! `render` and `eval`, and by the viewer's open, and nothing panics (it once asserted in the
//! rasterizer: `damage-twin render` exited 101).

use std::path::{Path, PathBuf};
use std::process::Command;

use damage_twin::splats::MAX_LABEL_CHANNELS;

/// A one-Gaussian PLY with `labels` label channels (`label_crack`, `label_spalling`,
/// `label_rebar`, then `label_3`, …), written by hand so that the writer's own check cannot stop
/// it.
fn model_with_labels(dir: &Path, labels: usize) -> PathBuf {
    let mut header = String::from("ply\nformat ascii 1.0\nelement vertex 1\n");
    let mut names = vec!["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity"]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
    names.extend(["scale_0", "scale_1", "scale_2"].map(String::from));
    names.extend(["rot_0", "rot_1", "rot_2", "rot_3"].map(String::from));
    names.extend((0..labels).map(damage_twin::splats::ply::label_property));
    for name in &names {
        header.push_str(&format!("property float {name}\n"));
    }
    header.push_str("end_header\n");
    let mut values = vec!["0"; names.len()];
    values[11] = "1"; // rot_0 = w = 1
    header.push_str(&values.join(" "));
    header.push('\n');
    let path = dir.join(format!("labels-{labels}.ply"));
    std::fs::write(&path, header).expect("write the model");
    path
}

/// A tiny synthetic dataset to render and evaluate against.
fn dataset(dir: &Path) -> PathBuf {
    let params = damage_twin::synth::SynthParams {
        width: 64,
        height: 36,
        views: 9,
        surveys: 1,
        sparse_points: 200,
        ..damage_twin::synth::SynthParams::demo(dir.join("synth"))
    };
    damage_twin::synth::generate(&params, &|_, _| {}).expect("synth");
    dir.join("synth/survey-1")
}

fn assert_refused(output: std::process::Output, model: &Path) {
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(errors.len(), 1, "{stderr}");
    let name = model.file_name().unwrap().to_string_lossy();
    assert!(
        errors[0].contains(name.as_ref()) && errors[0].contains("label"),
        "{stderr}"
    );
}

#[test]
fn too_many_label_channels_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let ok = model_with_labels(dir.path(), MAX_LABEL_CHANNELS);
    let splats = damage_twin::splats::ply::read_splats(&ok).expect("at the limit reads");
    assert_eq!(splats.label_channels, MAX_LABEL_CHANNELS);

    let bad = model_with_labels(dir.path(), 17);
    let err = damage_twin::splats::ply::read_splats(&bad)
        .expect_err("17 label channels are refused")
        .to_string();
    assert!(
        err.contains("labels-17.ply") && err.contains("label"),
        "{err}"
    );

    let data = dataset(dir.path());
    let exe = env!("CARGO_BIN_EXE_damage-twin");
    let render = Command::new(exe)
        .arg("render")
        .arg(&bad)
        .arg(&data)
        .args(["--view", "view-000", "--out"])
        .arg(dir.path().join("out.png"))
        .output()
        .expect("run render");
    assert_refused(render, &bad);
    let eval = Command::new(exe)
        .arg("eval")
        .arg(&bad)
        .arg(&data)
        .output()
        .expect("run eval");
    assert_refused(eval, &bad);
}

#[cfg(feature = "app")]
#[test]
fn the_viewer_refuses_too_many_label_channels_with_a_log_line() {
    use damage_twin::app::commands::Command as AppCommand;
    use damage_twin::app::settings::Settings;
    use damage_twin::app::state::AppState;

    let dir = tempfile::tempdir().expect("temp dir");
    let bad = model_with_labels(dir.path(), 17);
    let mut state = AppState::new(Settings::default());
    state.apply(AppCommand::Open(bad));
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    while !state.log.iter().any(|l| l.starts_with("error")) {
        assert!(std::time::Instant::now() < deadline, "{:?}", state.log);
        state.poll();
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let line = state.log.iter().find(|l| l.starts_with("error")).unwrap();
    assert!(line.contains("labels-17.ply"), "{line}");
    assert!(state.splats.is_none());
}
