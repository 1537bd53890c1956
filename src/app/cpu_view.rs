//! The viewport's renderer on a software GPU driver: the CPU reference rasterizer on a worker
//! thread. On lavapipe the WGSL forward pass is several times slower than the CPU reference
//! for the same frame (docs/APP.md), and because lavapipe executes a submission before the
//! next present, a slow splat render also stalls every UI frame behind it. Here the UI thread
//! only posts requests (the newest wins) and shows the last finished picture as a texture, so
//! the panels stay fluid whatever a render costs. A real GPU keeps the paint-callback path.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender};

use crate::damage::layer::DamageLayer;
use crate::raster::{Rasterizer, RenderOutput, RenderSettings};
use crate::scene::Camera;
use crate::splats::Splats;

/// While only the model changes (training under a resting camera), the picture refreshes at
/// most this often: each render takes CPU time from training, and a new picture every snapshot
/// (4 per second) took most of a core at rest on the 2-core machine.
const MODEL_REFRESH: Duration = Duration::from_secs(1);

/// What one picture shows; an identical request is not rendered again.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewRequest {
    pub generation: u64,
    pub camera: Camera,
    pub splat_scale: f32,
    pub damage: DamageLayer,
    pub background: [f32; 3],
}

/// A finished picture.
pub struct Picture {
    pub request: ViewRequest,
    pub image: egui::ColorImage,
    /// Wall time of the render, milliseconds (what the adaptive resolution reacts to).
    pub render_ms: f32,
}

/// The worker's input: the request and the model it refers to.
struct Job {
    request: ViewRequest,
    splats: Arc<Splats>,
}

/// Client side, owned by the viewport.
pub struct CpuView {
    jobs: Sender<Job>,
    pictures: Receiver<Picture>,
    /// The last request posted (rendering or done), and when.
    posted: Option<ViewRequest>,
    posted_at: Instant,
    texture: Option<egui::TextureHandle>,
    ctx: egui::Context,
}

impl CpuView {
    /// Starts the worker. `ctx` is asked to repaint when a picture is ready.
    pub fn start(ctx: &egui::Context) -> Result<CpuView, String> {
        let (jobs, job_rx) = crossbeam_channel::unbounded::<Job>();
        let (picture_tx, pictures) = crossbeam_channel::unbounded();
        let worker_ctx = ctx.clone();
        std::thread::Builder::new()
            .name("damage-twin-view".into())
            .spawn(move || render_loop(&job_rx, &picture_tx, &worker_ctx))
            .map_err(|e| format!("cannot start the view renderer thread: {e}"))?;
        Ok(CpuView {
            jobs,
            pictures,
            posted: None,
            posted_at: Instant::now(),
            texture: None,
            ctx: ctx.clone(),
        })
    }

    /// Posts `request` unless it is the last one posted, or differs from it only by a newer
    /// model less than [`MODEL_REFRESH`] after it (a later frame posts it). Returns true when it
    /// was posted.
    pub fn request(&mut self, request: ViewRequest, splats: &Arc<Splats>) -> bool {
        if let Some(posted) = &self.posted {
            let same_view = *posted
                == ViewRequest {
                    generation: posted.generation,
                    ..request.clone()
                };
            if same_view && posted.generation == request.generation {
                return false;
            }
            let since = self.posted_at.elapsed();
            if same_view && since < MODEL_REFRESH {
                // Come back for it: after training ends nothing else may repaint.
                self.ctx.request_repaint_after(MODEL_REFRESH - since);
                return false;
            }
        }
        self.posted = Some(request.clone());
        self.posted_at = Instant::now();
        // The worker is gone only if it panicked; the viewport then shows the last picture.
        self.jobs
            .send(Job {
                request,
                splats: splats.clone(),
            })
            .is_ok()
    }

    /// Takes finished pictures into the texture; returns the newest one's render time.
    pub fn receive(&mut self, ctx: &egui::Context) -> Option<f32> {
        // Only the newest picture matters; older ones were overtaken while this frame waited.
        let picture = self.pictures.try_iter().last()?;
        let options = egui::TextureOptions::LINEAR;
        match &mut self.texture {
            Some(texture) => texture.set(picture.image, options),
            None => self.texture = Some(ctx.load_texture("cpu view", picture.image, options)),
        }
        Some(picture.render_ms)
    }

    /// The last finished picture, if any.
    pub fn texture(&self) -> Option<&egui::TextureHandle> {
        self.texture.as_ref()
    }
}

/// Renders the newest request, again and again, until the client is dropped.
fn render_loop(jobs: &Receiver<Job>, pictures: &Sender<Picture>, ctx: &egui::Context) {
    // One thread: on a 2-core machine the other core is left to the UI (whose frames the
    // software driver also draws on the CPU) and to training.
    match rayon::ThreadPoolBuilder::new().num_threads(1).build() {
        Ok(pool) => pool.install(|| render_jobs(jobs, pictures, ctx)),
        Err(_) => render_jobs(jobs, pictures, ctx),
    }
}

fn render_jobs(jobs: &Receiver<Job>, pictures: &Sender<Picture>, ctx: &egui::Context) {
    let mut rasterizer = Rasterizer::new();
    let mut out = RenderOutput::default();
    // The display model (splat scale, damage colours) is rebuilt only when its inputs change.
    // It is a copy of the model even when nothing is changed, so the worker holds one model's
    // memory more; it keeps no `Arc` of an old snapshot alive.
    let mut display: Option<((u64, f32, DamageLayer), Splats)> = None;
    while let Ok(mut job) = jobs.recv() {
        // Skip requests that were overtaken while the last one rendered.
        while let Ok(newer) = jobs.try_recv() {
            job = newer;
        }
        let started = Instant::now();
        let r = &job.request;
        let key = (r.generation, r.splat_scale, r.damage.clone());
        if display.as_ref().is_none_or(|(k, _)| *k != key) {
            let shown = crate::damage::layer::display_splats(&job.splats, r.splat_scale, &r.damage);
            display = Some((key, shown.into_owned()));
        }
        let Some((_, shown)) = &display else {
            continue;
        };
        let settings = RenderSettings::new(glam::Vec3::from_array(r.background), shown.sh_degree);
        rasterizer.forward(shown, &r.camera, &settings, &mut out);
        let image = color_image(out.width as usize, out.height as usize, &out.color);
        let picture = Picture {
            request: job.request,
            image,
            render_ms: started.elapsed().as_secs_f32() * 1000.0,
        };
        if pictures.send(picture).is_err() {
            return;
        }
        ctx.request_repaint();
    }
}

/// Interleaved RGB in [0, 1] (a render as the rasterizer blends it, or a photo) as an opaque
/// 8-bit texture image, values taken as they are like the GPU path's `Rgba8Unorm` output; values
/// missing from a short buffer read as black.
pub fn color_image(width: usize, height: usize, rgb: &[f32]) -> egui::ColorImage {
    let byte = |i: usize| (rgb.get(i).copied().unwrap_or(0.0).clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    let pixels = (0..width * height)
        .map(|p| egui::Color32::from_rgb(byte(p * 3), byte(p * 3 + 1), byte(p * 3 + 2)))
        .collect();
    egui::ColorImage::new([width, height], pixels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Intrinsics;
    use glam::Vec3;

    fn request(generation: u64, eye_x: f32) -> ViewRequest {
        let k = Intrinsics {
            width: 16,
            height: 12,
            fx: 16.0,
            fy: 16.0,
            cx: 8.0,
            cy: 6.0,
        };
        ViewRequest {
            generation,
            camera: Camera::look_at(k, Vec3::new(eye_x, -4.0, 0.0), Vec3::ZERO, Vec3::Z),
            splat_scale: 1.0,
            damage: DamageLayer::default(),
            background: [0.2, 0.3, 0.4],
        }
    }

    #[test]
    fn posts_new_views_at_once_and_new_models_at_most_once_a_second() {
        let ctx = egui::Context::default();
        let mut view = CpuView::start(&ctx).expect("worker");
        let splats = Arc::new(Splats::empty(0, 0));
        assert!(view.request(request(1, 0.0), &splats), "first request");
        assert!(!view.request(request(1, 0.0), &splats), "the same again");
        assert!(
            !view.request(request(2, 0.0), &splats),
            "a newer model, too soon"
        );
        assert!(
            view.request(request(2, 1.0), &splats),
            "a new view, at once"
        );
        // The worker renders the background of an empty model.
        let deadline = Instant::now() + Duration::from_secs(30);
        while view.receive(&ctx).is_none() {
            assert!(Instant::now() < deadline, "no picture");
            std::thread::sleep(Duration::from_millis(5));
        }
        let texture = view.texture().expect("texture");
        assert_eq!(texture.size(), [16, 12]);
    }
}
