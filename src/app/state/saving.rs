//! Saving from the viewer: a dataset or model as a new twin project, or the open project with
//! its surveys (the shown survey's model, every survey edited here, the shown survey's name),
//! all through `timeline::Twin`, whose writes are atomic.

use std::path::Path;
use std::sync::Arc;

use super::AppState;
use crate::splats::Splats;
use crate::timeline::Twin;
use crate::timeline::record::record_training;

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
        let mut twin = Twin::open_or_create(dir)?;
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
            record_training(
                &mut twin,
                &survey,
                outcome,
                training.mode,
                training.scale,
                None,
            )?;
            twin.save()?;
        }
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
            for survey in &source.project.surveys {
                twin.copy_survey_records(source, &survey.name)?;
            }
            twin
        };
        twin.project.classes = crate::damage::DamageClass::ALL
            .iter()
            .zip(self.settings.damage.colours)
            .map(|(&class, colour)| ClassStyle { class, colour })
            .collect();
        twin.project.settings.background = self.settings.background;
        let names: Vec<String> = twin
            .project
            .surveys
            .iter()
            .map(|s| s.name.clone())
            .collect();
        twin.project.settings.shown_survey = names.get(timeline.current).cloned();
        let mut written = Vec::new();
        for (index, name) in names.iter().enumerate() {
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
        twin.save()?;
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
