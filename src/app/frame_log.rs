//! Frame-time statistics of the viewport, printed with `DAMAGE_TWIN_FRAME_STATS=1` (how the
//! frame times in docs/APP.md were measured).

/// With `DAMAGE_TWIN_FRAME_STATS=1`, prints frame-time statistics every 5 s to stderr (how the
/// frame times in the docs were measured): all frames, and separately the frames that rendered
/// splats (the others only redrew the panels and reused the picture).
pub struct FrameLog {
    enabled: bool,
    frames_ms: Vec<f32>,
    render_frames_ms: Vec<f32>,
    scales: Vec<f32>,
    /// Why egui repainted ("file:line reason" → frames), to find what keeps frames coming.
    repaint_causes: std::collections::BTreeMap<String, usize>,
    since: std::time::Instant,
}

impl Default for FrameLog {
    fn default() -> Self {
        FrameLog {
            enabled: std::env::var_os("DAMAGE_TWIN_FRAME_STATS").is_some_and(|v| v != "0"),
            frames_ms: Vec::new(),
            render_frames_ms: Vec::new(),
            scales: Vec::new(),
            repaint_causes: std::collections::BTreeMap::new(),
            since: std::time::Instant::now(),
        }
    }
}

/// "n frames, median …, p95 …, max …" of a list of frame times.
fn frame_summary(frames_ms: &[f32]) -> String {
    if frames_ms.is_empty() {
        return "0 frames".into();
    }
    let mut sorted = frames_ms.to_vec();
    sorted.sort_by(f32::total_cmp);
    let n = sorted.len();
    format!(
        "{n} frames, median {:.1} ms, p95 {:.1} ms, max {:.1} ms",
        sorted[n / 2],
        sorted[(n * 95 / 100).min(n - 1)],
        sorted[n - 1],
    )
}

impl FrameLog {
    /// A CPU-worker render's own time (its pictures arrive between UI frames).
    pub fn record_render(&mut self, render_ms: f32) {
        if self.enabled && render_ms > 0.0 {
            self.render_frames_ms.push(render_ms);
        }
    }

    /// `frame_ms` is the last frame's time; `rendered` says whether that frame rendered splats.
    pub fn record(&mut self, ctx: &egui::Context, frame_ms: f32, scale: f32, rendered: bool) {
        if !self.enabled || !(frame_ms > 0.0) {
            return;
        }
        for cause in ctx.repaint_causes() {
            *self.repaint_causes.entry(cause.to_string()).or_default() += 1;
        }
        self.frames_ms.push(frame_ms);
        if rendered {
            self.render_frames_ms.push(frame_ms);
        }
        self.scales.push(scale);
        let seconds = self.since.elapsed().as_secs_f32();
        if seconds < 5.0 {
            return;
        }
        let mean_scale = self.scales.iter().sum::<f32>() / self.scales.len() as f32;
        eprintln!(
            "frames in {seconds:.1} s: all {}; splat renders {}; mean render scale {mean_scale:.2}",
            frame_summary(&self.frames_ms),
            frame_summary(&self.render_frames_ms),
        );
        let mut causes: Vec<_> = std::mem::take(&mut self.repaint_causes)
            .into_iter()
            .collect();
        causes.sort_by_key(|(_, frames)| std::cmp::Reverse(*frames));
        for (cause, frames) in causes.iter().take(4) {
            eprintln!("  repaint cause ({frames} frames): {cause}");
        }
        self.frames_ms.clear();
        self.render_frames_ms.clear();
        self.scales.clear();
        self.since = std::time::Instant::now();
    }
}
