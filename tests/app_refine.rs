//! Refining a hand selection from the viewer (issue 22): the job runs on the selected Gaussians
//! only (the rest frozen), its result becomes the model, undo brings the previous model back
//! bit for bit and redo the refined one.
#![cfg(feature = "app")]

mod twin_support;

use std::sync::Arc;
use std::time::{Duration, Instant};

use damage_twin::app::commands::Command;
use damage_twin::app::settings::Settings;
use damage_twin::app::state::{AppState, WorkerResult};
use damage_twin::damage::DamageClass;
use damage_twin::damage::refine::Strategy;
use damage_twin::splats::model::state::{REFINED, SELECTED};
use damage_twin::splats::selection::SetOp;

#[test]
fn a_hand_selection_refines_and_undo_restores_the_model() {
    let dir = tempfile::tempdir().unwrap();
    let (dataset, coarse) = twin_support::coarse_twin(dir.path(), 1);
    let mut state = AppState::new(Settings::default());
    state
        .results_sender()
        .send(WorkerResult::Opened {
            source: dataset.root.clone(),
            dataset: Some(dataset.clone()),
            splats: Some(Arc::new(coarse.clone())),
            project_dir: None,
        })
        .unwrap();
    state.poll();
    state.apply(Command::SelectDamage {
        class: DamageClass::Crack,
        threshold: 0.5,
        survey: None,
        op: SetOp::Set,
    });
    let model = state.splats.clone().unwrap();
    let selected: Vec<usize> = (0..model.len())
        .filter(|&g| model.meta.state[g] & SELECTED != 0)
        .collect();
    assert!(!selected.is_empty(), "the coarse twin has crack Gaussians");
    state.apply(Command::RefineSelection {
        strategy: Strategy::Finetune,
        iterations: 30,
    });
    assert!(state.refine.is_some(), "{:?}", state.log);
    let start = Instant::now();
    while state.refine.is_some() {
        state.poll();
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "{:?}",
            state.log
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let refined = state.splats.clone().unwrap();
    assert!(
        state.log.iter().any(|l| l.starts_with("refined in")),
        "{:?}",
        state.log
    );
    assert_eq!(refined.len(), model.len(), "finetune keeps the count");
    // Only the selection moved, and it is marked refined.
    for g in 0..model.len() {
        let is_selected = model.meta.state[g] & SELECTED != 0;
        if is_selected {
            assert_ne!(refined.meta.state[g] & REFINED, 0);
        } else {
            assert_eq!(refined.means[g], model.means[g], "Gaussian {g} was frozen");
        }
    }
    assert!(
        selected.iter().any(|&g| refined.means[g] != model.means[g]),
        "the selection trained"
    );
    state.apply(Command::Undo);
    assert_eq!(
        **state.splats.as_ref().unwrap(),
        *model,
        "undo restores the model"
    );
    state.apply(Command::Redo);
    assert_eq!(**state.splats.as_ref().unwrap(), *refined);
}
