//! Saving from the viewer: a dataset or model as a new twin project, or the open project with
//! its surveys (the shown survey's model, every survey edited here, the shown survey's name),
//! all through `timeline::Twin`, whose writes are atomic and go one writer at a time: a save
//! merges into the project as other commands left it, or is refused with the writer holding it.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use super::AppState;
use crate::splats::Splats;
use crate::timeline::Twin;
use crate::timeline::lock::{DEFAULT_LOCK_WAIT, Writer};
use crate::timeline::record::record_training;

/// How long a save from the window waits for another writer: the window does not redraw
/// meanwhile, and a command that writes a project holds it for well under a second.
const SAVE_LOCK_WAIT: Duration = Duration::from_secs(2);

/// The viewer as a project's writer: a save on the UI thread waits `SAVE_LOCK_WAIT`; an update's
/// or a detection's commit, in its worker, waits as long as the CLI's commands, so that minutes
/// of training are not lost to a writer that is about to finish.
pub(super) fn viewer_writer(in_worker: bool) -> Writer {
    let wait = if in_worker {
        DEFAULT_LOCK_WAIT
    } else {
        SAVE_LOCK_WAIT
    };
    Writer::new("the damage-twin viewer").waiting(wait)
}

impl AppState {
    pub(super) fn save_project(&mut self, dir: &Path) {
        if self.timeline.is_some() {
            let result = self.save_timeline(dir);
            let ok = result.is_ok();
            self.report(result, &format!("saved the twin to {}", dir.display()));
            if ok && let Some(scene) = &mut self.scene {
                scene.project_dir = Some(dir.to_path_buf());
            }
            return;
        }
        let Some(splats) = self.splats.clone() else {
            self.log_line("nothing to save yet: no model");
            return;
        };
        let dataset_root = self
            .scene
            .as_ref()
            .and_then(|s| s.dataset.as_ref())
            .map(|d| d.root.clone());
        let result = self.save_twin(dir, dataset_root.as_deref(), &splats);
        let ok = result.is_ok();
        self.report(result, &format!("saved the twin to {}", dir.display()));
        if ok && let Some(scene) = &mut self.scene {
            scene.project_dir = Some(dir.to_path_buf());
        }
    }

    /// The twin project in `dir` with the model on screen saved as its survey's model, the
    /// damage colours, background and training scale as its settings, and the last finished
    /// run's figures as that survey's metrics.
    fn save_twin(
        &self,
        dir: &Path,
        dataset_root: Option<&Path>,
        splats: &Splats,
    ) -> anyhow::Result<()> {
        use crate::scene::project::{ClassStyle, ProjectSettings};
        let mut twin = Twin::open_or_create(dir)?.with_writer(viewer_writer(false));
        twin.commit(|twin| {
            twin.project.classes = crate::damage::DamageClass::ALL
                .iter()
                .zip(self.settings.damage.colours)
                .map(|(&class, colour)| ClassStyle { class, colour })
                .collect();
            twin.project.settings = ProjectSettings {
                background: self.settings.background,
                scale: self.settings.training.scale,
                ..twin.project.settings.clone()
            };
            let survey = twin.save_survey_model(dataset_root, splats)?;
            if let Some(outcome) = self.training.as_ref().and_then(|t| t.outcome.as_ref()) {
                let training = &self.settings.training;
                record_training(twin, &survey, outcome, training.mode, training.scale, None)?;
            }
            Ok(())
        })?;
        Ok(())
    }

    /// Saves the open project into `dir` (its own folder, or another one for "save as"): the
    /// model on screen as the shown survey's, every other survey edited here as its own, the
    /// shown survey and the viewer's colours in `twin.ron`. Into another folder every survey's
    /// model, metrics, history and change maps are written there (a project's own files stay
    /// inside its folder), and datasets are referred to where they are.
    fn save_timeline(&mut self, dir: &std::path::Path) -> anyhow::Result<()> {
        use crate::scene::project::ClassStyle;
        let Some(timeline) = &self.timeline else {
            anyhow::bail!("no project is open");
        };
        let source = &timeline.twin;
        let same_folder = crate::timeline::twin::same_folder(source.dir(), dir);
        let mut twin = if same_folder {
            source.clone()
        } else {
            // Refuses a folder that holds another project: nothing there is overwritten.
            let mut twin = Twin::create(dir)?;
            let mut project = source.project.clone();
            let moved = |p: &std::path::Path| {
                if p.as_os_str().is_empty() {
                    p.to_path_buf()
                } else {
                    twin.relative(&source.resolve(p))
                }
            };
            for survey in &mut project.surveys {
                survey.dataset = moved(&survey.dataset);
                survey.metrics = None;
                survey.changes = None;
                survey.model = None;
            }
            twin.project = project;
            twin
        }
        .with_writer(viewer_writer(false));
        // Into the project as other commands left it: a survey added or a record written since
        // it was opened here stays; the surveys shown here are found by name.
        let written = twin.commit(|twin| {
            // Into another folder: each survey's records are copied there with its model.
            if !same_folder {
                for survey in &source.project.surveys {
                    twin.copy_survey_records(source, &survey.name)?;
                }
            }
            twin.project.classes = crate::damage::DamageClass::ALL
                .iter()
                .zip(self.settings.damage.colours)
                .map(|(&class, colour)| ClassStyle { class, colour })
                .collect();
            twin.project.settings.background = self.settings.background;
            let names: Vec<&str> = source
                .project
                .surveys
                .iter()
                .map(|s| s.name.as_str())
                .collect();
            twin.project.settings.shown_survey = names.get(timeline.current).map(|n| n.to_string());
            let mut written = Vec::new();
            for (index, name) in names.into_iter().enumerate() {
                let model = if index == timeline.current {
                    self.splats.clone()
                } else {
                    match timeline.loaded.get(&index) {
                        Some(slot) if slot.edited || !same_folder => slot.splats.clone(),
                        _ if !same_folder => source.load_model(name)?.map(Arc::new),
                        _ => None,
                    }
                };
                if let Some(model) = model {
                    twin.save_model(name, &model)?;
                    written.push(index);
                }
            }
            Ok(written)
        })?;
        let Some(timeline) = &mut self.timeline else {
            return Ok(());
        };
        for index in written {
            if let Some(slot) = timeline.loaded.get_mut(&index) {
                slot.edited = false;
            }
        }
        timeline.twin = twin;
        Ok(())
    }
}
