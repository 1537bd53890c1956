//! Adaptive render resolution: while the camera moves, the render scale drops until the measured
//! frame time meets the target, so interaction stays fluid on a software driver; once the view
//! rests it returns to full resolution. Pure arithmetic, driven by the viewport.

/// Seconds the camera must rest before full resolution comes back.
const SETTLE_SECONDS: f32 = 0.25;

/// Picks the render scale (fraction of the viewport's pixel size) each frame.
#[derive(Clone, Debug, PartialEq)]
pub struct AdaptiveResolution {
    scale: f32,
    rest_seconds: f32,
    /// Smoothed frame time, milliseconds.
    frame_ms: f32,
}

impl Default for AdaptiveResolution {
    fn default() -> Self {
        AdaptiveResolution {
            scale: 1.0,
            rest_seconds: SETTLE_SECONDS,
            frame_ms: 0.0,
        }
    }
}

impl AdaptiveResolution {
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// Smoothed frame time the controller reacts to, milliseconds.
    pub fn frame_ms(&self) -> f32 {
        self.frame_ms
    }

    /// Feeds one frame: `moving` when the camera changed this frame, `frame_ms` the wall time of
    /// the last frame. Render cost scales with pixel count, i.e. with scale², so the correction
    /// is the square root of the time ratio, limited per frame to avoid oscillation.
    pub fn update(&mut self, moving: bool, frame_ms: f32, target_ms: f32, min_scale: f32) -> f32 {
        let min_scale = if min_scale.is_finite() {
            min_scale.clamp(0.05, 1.0)
        } else {
            0.25
        };
        if frame_ms.is_finite() && frame_ms > 0.0 {
            self.frame_ms = if self.frame_ms > 0.0 {
                0.7 * self.frame_ms + 0.3 * frame_ms
            } else {
                frame_ms
            };
        }
        if !moving {
            self.rest_seconds += frame_ms.max(0.0) / 1000.0;
            if self.rest_seconds >= SETTLE_SECONDS {
                self.scale = 1.0;
            }
            return self.scale;
        }
        self.rest_seconds = 0.0;
        if self.frame_ms > 0.0 && target_ms > 0.0 {
            let ratio = (target_ms / self.frame_ms).sqrt().clamp(0.7, 1.2);
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
