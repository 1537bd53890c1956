//! Adaptive render resolution: while the picture keeps changing (the camera moves, or training
//! streams new models), the render scale drops until a frame that renders splats meets the
//! target time, so interaction stays fluid on a software driver; once both camera and model
//! rest it returns to full resolution. Pure arithmetic, driven by the viewport.

/// Seconds the picture must rest before full resolution comes back.
const SETTLE_SECONDS: f32 = 0.25;

/// Per-frame correction limits. The downward one is wider: a full-resolution render on a
/// software driver can take seconds, and each slow frame spent converging is felt.
const MAX_DROP: f32 = 0.5;
const MAX_RISE: f32 = 1.2;

/// Picks the render scale (fraction of the viewport's pixel size) each frame.
#[derive(Clone, Debug, PartialEq)]
pub struct AdaptiveResolution {
    scale: f32,
    rest_seconds: f32,
    /// The last frame was neither moving nor training.
    resting: bool,
    /// Smoothed time of frames that rendered splats, milliseconds.
    frame_ms: f32,
}

impl Default for AdaptiveResolution {
    fn default() -> Self {
        AdaptiveResolution {
            scale: 1.0,
            rest_seconds: SETTLE_SECONDS,
            resting: true,
            frame_ms: 0.0,
        }
    }
}

/// One frame as the controller sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSample {
    /// The camera moves or the model is being trained: renders must keep to the budget.
    pub changing: bool,
    /// Wall time of the last frame, milliseconds.
    pub frame_ms: f32,
    /// Whether the last frame rendered splats. Frames that only redrew the panels say nothing
    /// about the render's cost; they only advance the rest timer.
    pub last_frame_rendered: bool,
}

impl AdaptiveResolution {
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// Smoothed time of rendering frames the controller reacts to, milliseconds.
    pub fn frame_ms(&self) -> f32 {
        self.frame_ms
    }

    /// True while the scale is below full resolution and the picture rests, i.e. one more
    /// frame after the settle time will bring full resolution back.
    pub fn settling(&self) -> bool {
        self.resting && self.scale < 1.0
    }

    /// Feeds one frame and returns the scale to render it at. Render cost scales with pixel
    /// count, i.e. with scale², so the correction is the square root of the time ratio,
    /// limited per frame to avoid oscillation.
    pub fn update(&mut self, frame: FrameSample, target_ms: f32, min_scale: f32) -> f32 {
        let min_scale = if min_scale.is_finite() {
            min_scale.clamp(0.05, 1.0)
        } else {
            0.25
        };
        let measured =
            frame.last_frame_rendered && frame.frame_ms.is_finite() && frame.frame_ms > 0.0;
        if measured {
            self.frame_ms = if self.frame_ms > 0.0 {
                0.7 * self.frame_ms + 0.3 * frame.frame_ms
            } else {
                frame.frame_ms
            };
        }
        self.resting = !frame.changing;
        if !frame.changing {
            self.rest_seconds += frame.frame_ms.max(0.0) / 1000.0;
            if self.rest_seconds >= SETTLE_SECONDS {
                self.scale = 1.0;
            }
            return self.scale;
        }
        self.rest_seconds = 0.0;
        if measured && self.frame_ms > 0.0 && target_ms > 0.0 {
            let ratio = (target_ms / self.frame_ms).sqrt().clamp(MAX_DROP, MAX_RISE);
            self.scale = (self.scale * ratio).clamp(min_scale, 1.0);
        }
        self.scale
    }
}

/// Render size in pixels for a viewport of `width × height` pixels at `scale` (at least 1×1).
pub fn scaled_size(width: u32, height: u32, scale: f32) -> (u32, u32) {
    let s = if scale.is_finite() {
        scale.clamp(0.01, 1.0)
    } else {
        1.0
    };
    (
        ((width as f32 * s).round() as u32).max(1),
        ((height as f32 * s).round() as u32).max(1),
    )
}
