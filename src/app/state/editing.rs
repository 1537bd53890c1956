//! The viewer's edits of the model on screen: selection, visibility and hand-set damage classes
//! as undoable `Edit`s, and selecting a measured damage region.

use std::sync::Arc;

use super::AppState;
use crate::splats::Splats;
use crate::splats::model::state::SELECTED;
use crate::splats::selection::{self, Edit, SetOp};

impl AppState {
    /// Applies a selection or visibility edit to the model on screen, undoably; a measurement of
    /// the model stays current (no geometry changed).
    pub(super) fn edit_model(&mut self, edit: impl FnOnce(&mut Splats) -> Edit) {
        if self.refine.is_some() {
            self.log_line("a refinement is running: wait for it or cancel it");
            return;
        }
        let Some(splats) = &self.splats else {
            self.log_line("nothing to select yet: no model");
            return;
        };
        let start = std::time::Instant::now();
        let mut model = Splats::clone(splats);
        let change = edit(&mut model);
        if change.is_empty() {
            return;
        }
        let selection_only = matches!(&change, Edit::Bits { bit, .. } if *bit == SELECTED);
        self.edits.push(change);
        let selected = selection::selected_count(&model);
        let drawn = self.drawn_generation;
        self.show_model_keeping_measurement(model);
        if selection_only {
            // Selection bits do not change what is drawn (the GPU selection pass keeps its copy).
            self.drawn_generation = drawn;
        }
        // How long an edit takes on this model (the workbench aims at 100 ms for 100k).
        self.log_line(format!(
            "{selected} selected ({:.0} ms)",
            start.elapsed().as_secs_f64() * 1000.0
        ));
    }

    fn show_model_keeping_measurement(&mut self, model: Splats) {
        let current = self
            .regions
            .as_ref()
            .is_some_and(|r| r.generation == self.splats_generation);
        self.show_edited(Arc::new(model));
        if current && let Some(r) = &mut self.regions {
            r.generation = self.splats_generation;
        }
    }

    pub(super) fn undo_redo(&mut self, redo: bool) {
        if self.refine.is_some() {
            self.log_line("a refinement is running: wait for it or cancel it");
            return;
        }
        let Some(splats) = &self.splats else { return };
        let mut model = Splats::clone(splats);
        let done = if redo {
            self.edits.redo(&mut model)
        } else {
            self.edits.undo(&mut model)
        };
        if done {
            self.show_model_keeping_measurement(model);
        } else {
            self.log_line(if redo {
                "nothing to redo"
            } else {
                "nothing to undo"
            });
        }
    }

    /// Selects region `index`'s damage Gaussians (only those) and frames it.
    pub(super) fn focus_region(&mut self, index: usize) {
        let (Some(regions), Some(splats)) = (&self.regions, &self.splats) else {
            return;
        };
        let Some(region) = regions.measurement.regions.get(index) else {
            return;
        };
        if regions.generation != self.splats_generation {
            // Training or opening replaced the model: the indices name other Gaussians now.
            self.log_line("the model changed since it was measured: measure again");
            return;
        }
        let (centroid, extent) = (region.centroid, region.length.unwrap_or(region.area.sqrt()));
        // From the photographed side, a little above (the plane's normal faces the cameras).
        let facing = regions
            .measurement
            .planes
            .get(region.plane)
            .map(|p| glam::DVec3::from_array(p.normal).as_vec3() + self.camera.up * 0.3);
        let count = region.members.len();
        let mut hit = vec![false; splats.len()];
        for &g in &region.members {
            hit[g as usize] = true;
        }
        self.edit_model(|m| selection::select(m, &hit, SetOp::Set));
        self.snap = None;
        let target = glam::DVec3::from_array(centroid).as_vec3();
        self.camera
            .frame_target(target, (extent as f32).max(0.3), facing);
        self.log_line(format!("selected region {} ({count} Gaussians)", index + 1));
    }
}
