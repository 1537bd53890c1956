//! Selecting by pointing (damage::pick): a click picks the Gaussian drawing most of the pixel,
//! the eyedropper the Gaussians of its colour, the volume tools a sphere or box around the
//! surface point clicked; screen shapes front-most or straight through; a snapped view's mask
//! lifted to its Gaussians; framing the selection; the distance between two surface points.

use glam::{Vec2, Vec3};

use super::AppState;
use crate::app::commands::PointSelect;
use crate::damage::DamageClass;
use crate::damage::pick::{front_hits, mask_hits, pick, surface_point};
use crate::raster::RenderSettings;
use crate::scene::Camera;
use crate::splats::Splats;
use crate::splats::model::SH_C0;
use crate::splats::model::state::{DELETED, HIDDEN, SELECTED};
use crate::splats::selection::{self, SetOp, Shape};

impl AppState {
    fn pick_settings(&self, splats: &Splats) -> RenderSettings {
        RenderSettings::new(Vec3::from_array(self.settings.background), splats.sh_degree)
    }

    /// A screen or volume shape: front-most (by rendered contribution) when the settings say
    /// so and the shape is on the screen, else straight through. On a hardware GPU the test runs
    /// in the GPU selection pass (the same rules), on the CPU otherwise or if the GPU fails.
    pub(super) fn select_shape(&mut self, shape: &Shape, camera: &Camera, op: SetOp) {
        let front = self.settings.selection_front_most && shape.screen_bounds().is_some();
        let background = Vec3::from_array(self.settings.background);
        let on_gpu = self.gpu_hits(shape, camera, front);
        self.edit_model(|m| {
            let hit = match on_gpu {
                Some(hit) => hit,
                None if front => {
                    let settings = RenderSettings::new(background, m.sh_degree);
                    front_hits(m, camera, shape, &settings)
                }
                None => selection::hits(m, camera, shape),
            };
            selection::select(m, &hit, op)
        });
    }

    /// Runs the selection test in the GPU selection pass on `ctx`'s device, even a software one
    /// (tests; by default only a hardware GPU is used, on first need).
    pub fn select_on_gpu(
        &mut self,
        ctx: &crate::gpu::GpuContext,
    ) -> Result<(), crate::gpu::GpuError> {
        self.gpu_selector = Some(Some(crate::gpu::select::GpuSelector::new(ctx)?));
        Ok(())
    }

    /// Whether screen and volume shapes are tested in the GPU selection pass.
    pub fn selects_on_gpu(&self) -> bool {
        matches!(self.gpu_selector, Some(Some(_)))
    }

    /// The GPU selection pass's hits, when a hardware GPU is there (created on first use; a
    /// software driver is slower than the CPU test, so it is never used for this).
    fn gpu_hits(&mut self, shape: &Shape, camera: &Camera, front: bool) -> Option<Vec<bool>> {
        let splats = self.splats.clone()?;
        if self.gpu_selector.is_none() {
            let selector = match crate::gpu::GpuContext::new_hardware() {
                Ok(Some(ctx)) => crate::gpu::select::GpuSelector::new(&ctx).ok(),
                _ => None,
            };
            self.gpu_selector = Some(selector);
        }
        let settings = crate::gpu::GpuRenderSettings {
            background: Vec3::from_array(self.settings.background),
            sh_degree: splats.sh_degree,
            ..Default::default()
        };
        let key = self.drawn_generation;
        let selector = self.gpu_selector.as_mut()?.as_mut()?;
        match selector.hits(&splats, key, camera, shape, front.then_some(&settings)) {
            Ok(hit) => Some(hit),
            Err(e) => {
                self.log_line(format!("GPU selection failed ({e}); selecting on the CPU"));
                self.gpu_selector = Some(None);
                None
            }
        }
    }

    pub(super) fn select_at(&mut self, pixel: Vec2, camera: &Camera, how: PointSelect, op: SetOp) {
        let Some(splats) = self.splats.clone() else {
            self.log_line("nothing to select yet: no model");
            return;
        };
        let settings = self.pick_settings(&splats);
        let radius = self.settings.volume_radius;
        let hit: Vec<bool> = match how {
            PointSelect::Gaussian | PointSelect::Colour => {
                let Some(g) = pick(&splats, camera, pixel, &settings) else {
                    self.log_line("no Gaussian draws there");
                    return;
                };
                if how == PointSelect::Gaussian {
                    (0..splats.len()).map(|i| i == g).collect()
                } else {
                    let target = base_colour(&splats, g);
                    let tolerance = self.settings.colour_match;
                    (0..splats.len())
                        .map(|i| {
                            splats.meta.state[i] & (HIDDEN | DELETED) == 0
                                && base_colour(&splats, i).distance(target) <= tolerance
                        })
                        .collect()
                }
            }
            PointSelect::Sphere | PointSelect::Box => {
                let Some(centre) = surface_point(&splats, camera, pixel, &settings) else {
                    self.log_line("no surface there to centre the volume on");
                    return;
                };
                let shape = match how {
                    PointSelect::Sphere => Shape::Sphere { centre, radius },
                    _ => Shape::Box {
                        a: centre - Vec3::splat(radius),
                        b: centre + Vec3::splat(radius),
                    },
                };
                selection::hits(&splats, camera, &shape)
            }
        };
        self.edit_model(|m| selection::select(m, &hit, op));
    }

    /// The snapped view's mask of `class`, lifted to the Gaussians that draw it.
    pub(super) fn select_from_mask(&mut self, class: DamageClass, op: SetOp) {
        let (Some(snap), Some(dataset), Some(splats)) = (
            self.snap.as_ref(),
            self.scene.as_ref().and_then(|s| s.dataset.clone()),
            self.splats.clone(),
        ) else {
            self.log_line("snap to a survey view first: its mask is lifted to the Gaussians");
            return;
        };
        let Some(masks) = dataset.masks.clone() else {
            self.log_line("this dataset has no damage masks");
            return;
        };
        // At most ~960 pixels wide: the vote needs the mask's shape, not every pixel.
        let width = snap.camera.intrinsics.width;
        let scale = crate::scene::ImageScale::Width(width.min(960));
        let loaded = dataset
            .load_view_masks(snap.view, masks.as_ref(), scale)
            .or_else(|_| {
                let full = crate::scene::ImageScale::Factor(1);
                dataset.load_view_masks(snap.view, masks.as_ref(), full)
            });
        let (camera, masks) = match loaded {
            Ok(loaded) => loaded,
            Err(e) => {
                self.log_line(format!("error: {e}"));
                return;
            }
        };
        let Some(mask) = masks.get(&class) else {
            self.log_line(format!("this view has no {} mask", class.id()));
            return;
        };
        let settings = self.pick_settings(&splats);
        let hit = mask_hits(&splats, &camera, mask, &settings);
        self.edit_model(|m| selection::select(m, &hit, op));
    }

    /// Adds a surface point to the distance measurement and says the distance.
    pub(super) fn measure_at(&mut self, pixel: Vec2, camera: &Camera) {
        let Some(splats) = self.splats.clone() else {
            return;
        };
        let settings = self.pick_settings(&splats);
        let Some(point) = surface_point(&splats, camera, pixel, &settings) else {
            self.log_line("no surface there to measure from");
            return;
        };
        if self.distance.len() >= 2 {
            self.distance.clear();
        }
        self.distance.push(point);
        if let Some(text) = self.distance_text() {
            self.log_line(format!("distance {text}"));
        }
    }

    /// The measured distance, in metres when the project knows its scale.
    pub fn distance_text(&self) -> Option<String> {
        let [a, b] = self.distance.as_slice() else {
            return None;
        };
        let units = a.distance(*b);
        let metres = self
            .timeline
            .as_ref()
            .and_then(|t| t.twin.project.settings.metres_per_unit);
        Some(match metres {
            Some(m) => format!("{:.3} m", f64::from(units) * m),
            None => format!("{units:.3} model units (no scale set)"),
        })
    }

    /// Frames the selected Gaussians (the whole scene when none is selected).
    pub(super) fn frame_selection(&mut self) {
        let Some(splats) = &self.splats else {
            return;
        };
        let selected: Vec<Vec3> = (0..splats.len())
            .filter(|&g| splats.meta.state[g] & SELECTED != 0)
            .map(|g| splats.means[g])
            .collect();
        if selected.is_empty() {
            self.apply(crate::app::commands::Command::ResetView);
            return;
        }
        let centre = selected.iter().copied().sum::<Vec3>() / selected.len() as f32;
        // The 90th percentile distance: a few stray Gaussians do not zoom the view out.
        let mut distances: Vec<f32> = selected.iter().map(|p| p.distance(centre)).collect();
        distances.sort_by(f32::total_cmp);
        let radius = distances[(distances.len() * 9 / 10).min(distances.len() - 1)];
        self.snap = None;
        self.camera.frame_target(centre, radius.max(0.05), None);
    }
}

/// Gaussian `g`'s base colour (the view-independent SH term), RGB in [0, 1].
fn base_colour(splats: &Splats, g: usize) -> Vec3 {
    let k = splats.sh_coeffs() * 3;
    let dc = &splats.sh[g * k..g * k + 3];
    Vec3::new(dc[0], dc[1], dc[2]) * SH_C0 + Vec3::splat(0.5)
}
