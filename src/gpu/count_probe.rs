//! The renderer's intersection-count probe: a non-blocking read of the last frame's
//! intersection total, so later frames can grow the intersection buffers without stalling.

use std::sync::{Arc, Mutex};

/// Non-blocking read of the last frame's intersection total, so the next frames can grow the
/// intersection buffers without stalling: copy (frame k), map (frame k+1), read when mapped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ProbeState {
    Idle,
    Copied,
    Mapping,
    Mapped,
    Failed,
}

pub(super) struct CountProbe {
    staging: wgpu::Buffer,
    state: Arc<Mutex<ProbeState>>,
}

impl CountProbe {
    pub(super) fn new(device: &wgpu::Device) -> CountProbe {
        CountProbe {
            staging: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("isect count probe"),
                size: 4,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            state: Arc::new(Mutex::new(ProbeState::Idle)),
        }
    }

    fn state(&self) -> ProbeState {
        self.state.lock().map(|s| *s).unwrap_or(ProbeState::Failed)
    }

    fn set(&self, s: ProbeState) {
        if let Ok(mut g) = self.state.lock() {
            *g = s;
        }
    }

    /// Advances the probe; returns the total once a copy has been mapped.
    pub(super) fn poll(&self, device: &wgpu::Device) -> Option<u32> {
        match self.state() {
            ProbeState::Copied => {
                // The encoder holding the copy was submitted by now (one render per frame).
                self.set(ProbeState::Mapping);
                let state = self.state.clone();
                self.staging
                    .slice(..)
                    .map_async(wgpu::MapMode::Read, move |r| {
                        if let Ok(mut g) = state.lock() {
                            *g = if r.is_ok() {
                                ProbeState::Mapped
                            } else {
                                ProbeState::Failed
                            };
                        }
                    });
                let _ = device.poll(wgpu::PollType::Poll);
                None
            }
            ProbeState::Mapping => {
                let _ = device.poll(wgpu::PollType::Poll);
                None
            }
            ProbeState::Mapped => {
                // wgpu 30: mapping a range can fail; a failed probe just reports nothing this frame.
                let total = match self.staging.slice(..).get_mapped_range() {
                    Ok(data) => Some(u32::from_le_bytes([data[0], data[1], data[2], data[3]])),
                    Err(_) => None,
                };
                self.staging.unmap();
                self.set(ProbeState::Idle);
                total
            }
            ProbeState::Idle | ProbeState::Failed => None,
        }
    }

    pub(super) fn record_copy(&self, encoder: &mut wgpu::CommandEncoder, count: &wgpu::Buffer) {
        if self.state() == ProbeState::Idle {
            encoder.copy_buffer_to_buffer(count, 0, &self.staging, 0, 4);
            self.set(ProbeState::Copied);
        }
    }
}
