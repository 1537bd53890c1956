//! What the viewport looks through: the free camera or a snapped survey view (its photo or
//! change map read on a worker). The viewport draws with these and sends the commands that
//! change them; nothing here draws.

use crate::app::camera_controller::CameraController;
use crate::app::state::{AppState, Photo, Snap};
use crate::app::workers;
use crate::scene::Camera;

/// The camera the viewport renders with at `width × height` pixels: the snapped survey camera
/// (scaled to fit, aspect kept by the viewport) or the free camera.
pub fn view_camera(
    snap: Option<&Snap>,
    camera: &CameraController,
    width: u32,
    height: u32,
) -> Camera {
    match snap {
        Some(snap) => snap.camera.resized(width, height),
        None => camera.camera(width, height),
    }
}

impl AppState {
    /// The camera the viewport renders with at `width × height` pixels (see [`view_camera`]).
    pub fn view_camera(&self, width: u32, height: u32) -> Camera {
        view_camera(self.snap.as_ref(), &self.camera, width, height)
    }

    /// Leaves the snapped view; the free camera continues from its pose.
    pub(super) fn unsnap(&mut self) {
        if let Some(snap) = self.snap.take() {
            self.camera.snap_to(&snap.camera);
        }
    }

    /// Frames the whole scene again with the settings' navigation mode and field of view.
    pub(super) fn reset_view(&mut self) {
        self.snap = None;
        if let Some(scene) = &self.scene {
            self.camera = scene.frame.controller();
        }
        self.camera.mode = self.settings.nav_mode;
        self.camera.fov_y = self.settings.fov_deg.to_radians();
    }

    pub(super) fn snap_to(&mut self, index: usize) {
        let Some(dataset) = self.scene.as_ref().and_then(|s| s.dataset.clone()) else {
            return;
        };
        let Some(view) = dataset.views.get(index) else {
            self.log_line(format!("no survey view {index}"));
            return;
        };
        let change_map = self
            .timeline
            .as_ref()
            .filter(|t| t.show_change_maps)
            .and_then(|t| t.change_map(&view.name));
        self.snap = Some(Snap {
            view: index,
            camera: view.camera,
            photo: Photo::Loading,
            change_map: change_map.is_some(),
        });
        match change_map {
            Some(path) => workers::load_picture(path, index, self.results_sender()),
            None => workers::load_photo(dataset, index, &self.settings, self.results_sender()),
        }
    }
}
