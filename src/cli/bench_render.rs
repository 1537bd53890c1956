//! `damage-twin bench-render MODEL.ply DATASET [--frames N] [--width W --height H]`: renders one
//! dataset view with the GPU forward pass and the CPU reference, reports ms per frame by stage for
//! both side by side (and how far their images differ) as JSON on stdout. No algorithms here.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use glam::Vec3;
use serde_json::json;

use damage_twin::gpu::{GpuContext, GpuRenderSettings, GpuRenderer};
use damage_twin::raster::{Rasterizer, RenderOutput, RenderSettings};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use damage_twin::splats::random::random_in_view;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// 3DGS PLY model (omit with `--random N`).
    pub model: Option<PathBuf>,
    /// Dataset whose camera is used (omit for a synthetic camera looking at the origin).
    pub dataset: Option<PathBuf>,
    /// Timed frames per backend (after one warm-up frame).
    #[arg(long, default_value_t = 10)]
    pub frames: usize,
    /// Render width; the height follows the view's aspect unless given.
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// View name in the dataset (default: the first view).
    #[arg(long)]
    pub view: Option<String>,
    /// Instead of MODEL.ply, N random Gaussians spread through the camera's view (SH degree 3).
    #[arg(long)]
    pub random: Option<usize>,
    /// Skip the CPU reference.
    #[arg(long)]
    pub no_cpu: bool,
    /// Also time a lasso selection (a 64-point circle over the middle of the view) on the GPU
    /// selection pass and on the CPU, straight through and front-most.
    #[arg(long)]
    pub select: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let (splats, model_name, dataset_path) = match (args.random, &args.model) {
        (Some(_), Some(first)) if args.dataset.is_none() => {
            (None, "random".to_string(), Some(first.clone()))
        }
        (Some(_), _) => (None, "random".to_string(), args.dataset.clone()),
        (None, Some(model)) => {
            let s = damage_twin::splats::ply::read_splats(model)
                .with_context(|| format!("reading model {}", model.display()))?;
            (Some(s), model.display().to_string(), args.dataset.clone())
        }
        (None, None) => bail!("give MODEL.ply or --random N"),
    };
    let camera = choose_camera(
        dataset_path.as_ref(),
        args.view.as_deref(),
        args.width,
        args.height,
    )?;
    let splats = match splats {
        Some(s) => s,
        None => random_in_view(args.random.unwrap_or(0), &camera, 7),
    };
    let frames = args.frames.max(1);
    let k = camera.intrinsics;

    let ctx = GpuContext::new().context("creating the GPU device")?;
    let mut renderer = GpuRenderer::new(&ctx)?;
    let upload_start = Instant::now();
    renderer.upload(&splats)?;
    ctx.wait_idle()?;
    let upload_ms = upload_start.elapsed().as_secs_f64() * 1e3;
    let cpu_settings = RenderSettings::new(Vec3::ZERO, splats.sh_degree);
    let gpu_settings = GpuRenderSettings::from(&cpu_settings);

    // GPU: one warm-up frame (pipelines, buffer sizes), then whole frames (submit → done) and
    // per-stage timings.
    let warm = Instant::now();
    let intersections = renderer.render_blocking(&camera, &gpu_settings)?;
    let gpu_first_ms = warm.elapsed().as_secs_f64() * 1e3;
    let mut frame_ms = Vec::with_capacity(frames);
    for _ in 0..frames {
        let t = Instant::now();
        renderer.render_blocking(&camera, &gpu_settings)?;
        frame_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let mut stage_sums: Vec<(&'static str, f64)> = Vec::new();
    let mut source = "";
    for _ in 0..frames {
        let timed = renderer.render_timed(&camera, &gpu_settings)?;
        source = timed.source;
        if stage_sums.is_empty() {
            stage_sums = timed.stages.iter().map(|&(n, _)| (n, 0.0)).collect();
        }
        for (sum, (_, ms)) in stage_sums.iter_mut().zip(&timed.stages) {
            sum.1 += ms;
        }
    }
    let gpu_frame = renderer.render_to_image(&camera, &gpu_settings)?;
    let gpu_stages: serde_json::Map<String, serde_json::Value> = stage_sums
        .iter()
        .map(|(n, s)| (n.to_string(), json!(round(s / frames as f64))))
        .collect();

    let cpu = if args.no_cpu {
        serde_json::Value::Null
    } else {
        let mut raster = Rasterizer::new();
        let mut out = RenderOutput::default();
        raster.forward(&splats, &camera, &cpu_settings, &mut out);
        let (mut project, mut sort, mut blend, mut total) = (0.0, 0.0, 0.0, 0.0);
        for _ in 0..frames {
            let t = Instant::now();
            raster.forward(&splats, &camera, &cpu_settings, &mut out);
            total += t.elapsed().as_secs_f64() * 1e3;
            let s = raster.timings();
            project += s.project.as_secs_f64() * 1e3;
            sort += s.sort.as_secs_f64() * 1e3;
            blend += s.raster_forward.as_secs_f64() * 1e3;
        }
        let f = frames as f64;
        let diff = image_difference(&gpu_frame.color, &out.color);
        json!({
            "threads": rayon::current_num_threads(),
            "simd": damage_twin::simd::simd_level().name(),
            "ms_per_frame": {
                "project": round(project / f),
                "sort": round(sort / f),
                "rasterize": round(blend / f),
                "total": round(total / f),
            },
            "intersections": raster.tile_bins().0.len(),
            "gpu_vs_cpu_image": diff,
        })
    };

    let selection = if args.select {
        time_selection(&ctx, &splats, &camera, &cpu_settings, frames, !args.no_cpu)?
    } else {
        serde_json::Value::Null
    };

    let report = json!({
        "adapter": ctx.describe(),
        "software_adapter": ctx.is_software(),
        "capabilities": ctx.capabilities,
        "model": model_name,
        "gaussians": splats.len(),
        "sh_degree": splats.sh_degree,
        "width": k.width,
        "height": k.height,
        "frames": frames,
        "gpu": {
            "upload_ms": round(upload_ms),
            "first_frame_ms": round(gpu_first_ms),
            "frame_ms_mean": round(mean(&frame_ms)),
            "frame_ms_min": round(frame_ms.iter().copied().fold(f64::INFINITY, f64::min)),
            "stage_timing_source": source,
            "ms_per_frame_by_stage": gpu_stages,
            "intersections": intersections,
        },
        "cpu": cpu,
        "selection": selection,
    });
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

/// Milliseconds per lasso selection on the GPU pass and (unless skipped) on the CPU, straight
/// through and front-most, and whether the two agree.
fn time_selection(
    ctx: &GpuContext,
    splats: &Splats,
    camera: &Camera,
    settings: &RenderSettings,
    frames: usize,
    with_cpu: bool,
) -> anyhow::Result<serde_json::Value> {
    use damage_twin::gpu::select::GpuSelector;
    use damage_twin::splats::selection::{Shape, hits};
    let k = camera.intrinsics;
    let centre = glam::Vec2::new(k.width as f32 / 2.0, k.height as f32 / 2.0);
    let radius = k.width.min(k.height) as f32 / 3.0;
    let lasso = Shape::Polygon(
        (0..64)
            .map(|i| {
                let a = i as f32 * std::f32::consts::TAU / 64.0;
                centre + radius * glam::Vec2::new(a.cos(), a.sin())
            })
            .collect(),
    );
    let gpu_settings = GpuRenderSettings::from(settings);
    let mut selector = GpuSelector::new(ctx)?;
    let upload = Instant::now();
    let gpu_hits = selector.hits(splats, 1, camera, &lasso, None)?;
    let first_ms = upload.elapsed().as_secs_f64() * 1e3;
    let time = |f: &mut dyn FnMut() -> anyhow::Result<Vec<bool>>| -> anyhow::Result<f64> {
        let t = Instant::now();
        for _ in 0..frames {
            f()?;
        }
        Ok(t.elapsed().as_secs_f64() * 1e3 / frames as f64)
    };
    let straight_ms = time(&mut || Ok(selector.hits(splats, 1, camera, &lasso, None)?))?;
    let front_ms =
        time(&mut || Ok(selector.hits(splats, 1, camera, &lasso, Some(&gpu_settings))?))?;
    let selected = gpu_hits.iter().filter(|&&h| h).count();
    let cpu = if with_cpu {
        let cpu_hits = hits(splats, camera, &lasso);
        let straight = time(&mut || Ok(hits(splats, camera, &lasso)))?;
        let front = time(&mut || {
            Ok(damage_twin::damage::pick::front_hits(
                splats, camera, &lasso, settings,
            ))
        })?;
        json!({
            "straight_ms": round(straight),
            "front_most_ms": round(front),
            "same_selection": cpu_hits == gpu_hits,
        })
    } else {
        serde_json::Value::Null
    };
    Ok(json!({
        "shape": "lasso, 64 points",
        "selected": selected,
        "gpu": {
            "first_ms_with_upload": round(first_ms),
            "straight_ms": round(straight_ms),
            "front_most_ms": round(front_ms),
        },
        "cpu": cpu,
    }))
}

fn round(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Max / mean absolute difference and PSNR between two RGB buffers.
fn image_difference(a: &[f32], b: &[f32]) -> serde_json::Value {
    let n = a.len().min(b.len()).max(1);
    let (mut max, mut sum, mut sq) = (0.0f64, 0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        let d = (*x as f64 - *y as f64).abs();
        max = max.max(d);
        sum += d;
        sq += d * d;
    }
    let mse = sq / n as f64;
    let psnr = if mse > 0.0 {
        10.0 * (1.0 / mse).log10()
    } else {
        f64::INFINITY
    };
    json!({ "max_abs": round(max), "mean_abs": mean_abs(sum, n), "psnr_db": if psnr.is_finite() { json!(round(psnr)) } else { json!("inf") } })
}

fn mean_abs(sum: f64, n: usize) -> f64 {
    (sum / n as f64 * 1e6).round() / 1e6
}

/// The dataset view's camera (or a synthetic one), resized to the requested size.
fn choose_camera(
    dataset: Option<&PathBuf>,
    view: Option<&str>,
    width: Option<u32>,
    height: Option<u32>,
) -> anyhow::Result<Camera> {
    let camera = match dataset {
        Some(path) => {
            let options = damage_twin::scene::open::OpenOptions::default();
            let ds = damage_twin::scene::Dataset::open(path, &options)
                .with_context(|| format!("opening dataset {}", path.display()))?;
            let found = match view {
                Some(name) => ds
                    .views
                    .iter()
                    .find(|v| v.name == name || v.name.ends_with(&format!("/{name}"))),
                None => ds.views.first(),
            };
            let Some(v) = found else {
                bail!(
                    "no view {:?} in {}",
                    view.unwrap_or("(any)"),
                    path.display()
                );
            };
            v.camera
        }
        None => {
            let k = Intrinsics {
                width: 960,
                height: 540,
                fx: 800.0,
                fy: 800.0,
                cx: 480.0,
                cy: 270.0,
            };
            Camera::look_at(k, Vec3::new(0.0, -1.0, -6.0), Vec3::ZERO, Vec3::NEG_Y)
        }
    };
    let k = camera.intrinsics;
    let (w, h) = match (width, height) {
        (Some(w), Some(h)) => (w, h),
        (Some(w), None) => (
            w,
            ((w as f64 * k.height as f64 / k.width as f64).round() as u32).max(1),
        ),
        (None, Some(h)) => (
            ((h as f64 * k.width as f64 / k.height as f64).round() as u32).max(1),
            h,
        ),
        (None, None) => (k.width, k.height),
    };
    if w == 0 || h == 0 {
        bail!("image size must be positive, got {w}x{h}");
    }
    Ok(camera.resized(w, h))
}
