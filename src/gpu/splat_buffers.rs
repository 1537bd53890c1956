//! The model on the GPU: three storage buffers (geometry, SH, label logits) that a training
//! snapshot replaces or patches in place; they grow (×1.5) when the Gaussian count outgrows them.
//! Pipelines never depend on them, so nothing is recompiled. No rendering logic here.

use std::ops::Range;

use super::kernel;
use super::project::MAX_LABELS;
use super::{GpuContext, GpuError};
use crate::splats::Splats;

/// Where each parameter section starts inside the geometry buffer, in `f32`s:
/// `means (3C) | log_scales (3C) | rotations (4C, x y z w) | raw_opacities (C)` for capacity C.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GeometryLayout {
    pub log_scales_at: u32,
    pub rotations_at: u32,
    pub opacities_at: u32,
}

impl GeometryLayout {
    fn for_capacity(capacity: usize) -> GeometryLayout {
        let c = capacity as u32;
        GeometryLayout {
            log_scales_at: 3 * c,
            rotations_at: 6 * c,
            opacities_at: 10 * c,
        }
    }
}

/// `f32`s per Gaussian in the geometry buffer.
const GEOMETRY_FLOATS: usize = 11;

pub struct SplatBuffers {
    geometry: wgpu::Buffer,
    sh: wgpu::Buffer,
    raw_labels: wgpu::Buffer,
    capacity: usize,
    len: usize,
    sh_degree: u32,
    label_channels: usize,
    /// Bumps whenever the buffers are re-created (cached bind groups must be rebuilt).
    generation: u64,
}

impl SplatBuffers {
    /// Empty buffers (capacity 0).
    pub fn new(ctx: &GpuContext) -> SplatBuffers {
        let mut b = SplatBuffers {
            geometry: kernel::storage(
                &ctx.device,
                "splats.geometry",
                0,
                wgpu::BufferUsages::empty(),
            ),
            sh: kernel::storage(&ctx.device, "splats.sh", 0, wgpu::BufferUsages::empty()),
            raw_labels: kernel::storage(
                &ctx.device,
                "splats.raw_labels",
                0,
                wgpu::BufferUsages::empty(),
            ),
            capacity: 0,
            len: 0,
            sh_degree: 0,
            label_channels: 0,
            generation: 0,
        };
        b.generation = 0;
        b
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    pub fn sh_degree(&self) -> u32 {
        self.sh_degree
    }

    pub fn label_channels(&self) -> usize {
        self.label_channels
    }

    pub fn generation(&self) -> u64 {
        self.generation
    }

    pub fn layout(&self) -> GeometryLayout {
        GeometryLayout::for_capacity(self.capacity)
    }

    pub fn geometry(&self) -> &wgpu::Buffer {
        &self.geometry
    }

    pub fn sh(&self) -> &wgpu::Buffer {
        &self.sh
    }

    pub fn raw_labels(&self) -> &wgpu::Buffer {
        &self.raw_labels
    }

    /// Replaces the model. Writes in place when the count fits the capacity and the SH degree
    /// and label count are unchanged; otherwise re-creates the buffers with room to grow.
    pub fn upload(&mut self, ctx: &GpuContext, splats: &Splats) -> Result<(), GpuError> {
        splats.check_lengths().map_err(GpuError::InvalidSplats)?;
        if splats.label_channels > MAX_LABELS {
            return Err(GpuError::TooManyLabels {
                max: MAX_LABELS,
                got: splats.label_channels,
            });
        }
        let n = splats.len();
        let same_shape =
            splats.sh_degree == self.sh_degree && splats.label_channels == self.label_channels;
        if n > self.capacity || !same_shape {
            let grown = if same_shape {
                n.max(self.capacity + self.capacity / 2)
            } else {
                n
            };
            self.allocate(ctx, splats, grown.max(1), n)?;
        }
        self.len = n;
        self.write_range(ctx, splats, 0..n);
        Ok(())
    }

    /// Rewrites Gaussians `range` of a model with the same count and shape as the uploaded one
    /// (e.g. the trainable part of a snapshot while frozen Gaussians stay as they are).
    pub fn patch(
        &mut self,
        ctx: &GpuContext,
        splats: &Splats,
        range: Range<usize>,
    ) -> Result<(), GpuError> {
        if splats.len() != self.len
            || splats.sh_degree != self.sh_degree
            || splats.label_channels != self.label_channels
            || range.end > self.len
            || range.start > range.end
        {
            return Err(GpuError::InvalidSplats(format!(
                "patch {range:?} of a model with {} Gaussians (SH degree {}, {} labels) into buffers \
                 holding {} (SH degree {}, {} labels): upload the whole model instead",
                splats.len(),
                splats.sh_degree,
                splats.label_channels,
                self.len,
                self.sh_degree,
                self.label_channels
            )));
        }
        splats.check_lengths().map_err(GpuError::InvalidSplats)?;
        self.write_range(ctx, splats, range);
        Ok(())
    }

    fn allocate(
        &mut self,
        ctx: &GpuContext,
        splats: &Splats,
        capacity: usize,
        needed: usize,
    ) -> Result<(), GpuError> {
        let limit = ctx
            .limits
            .max_storage_buffer_binding_size
            .min(ctx.limits.max_buffer_size);
        let sh_floats = splats.sh_coeffs() * 3;
        let per_gaussian = [
            ("splat geometry", GEOMETRY_FLOATS * 4),
            ("splat SH coefficients", sh_floats * 4),
            ("splat labels", splats.label_channels * 4),
        ];
        // Growth headroom is dropped before failing: only the count actually needed must fit.
        let mut capacity = capacity;
        for (what, bytes) in per_gaussian {
            if bytes == 0 {
                continue;
            }
            let needed_bytes = (needed * bytes) as u64;
            if needed_bytes > limit {
                return Err(GpuError::TooLarge {
                    what,
                    needed: needed_bytes,
                    limit,
                });
            }
            capacity = capacity.min((limit / bytes as u64) as usize);
        }
        let none = wgpu::BufferUsages::empty();
        let device = &ctx.device;
        self.geometry = kernel::storage(
            device,
            "splats.geometry",
            (capacity * GEOMETRY_FLOATS * 4) as u64,
            none,
        );
        self.sh = kernel::storage(device, "splats.sh", (capacity * sh_floats * 4) as u64, none);
        self.raw_labels = kernel::storage(
            device,
            "splats.raw_labels",
            (capacity * splats.label_channels * 4) as u64,
            none,
        );
        self.capacity = capacity;
        self.sh_degree = splats.sh_degree;
        self.label_channels = splats.label_channels;
        self.generation += 1;
        Ok(())
    }

    fn write_range(&self, ctx: &GpuContext, splats: &Splats, range: Range<usize>) {
        if range.is_empty() {
            return;
        }
        let q = &ctx.queue;
        let layout = self.layout();
        let f = 4u64;
        let (a, b) = (range.start, range.end);
        q.write_buffer(
            &self.geometry,
            a as u64 * 3 * f,
            bytemuck::cast_slice(&splats.means[a..b]),
        );
        q.write_buffer(
            &self.geometry,
            (layout.log_scales_at as u64 + a as u64 * 3) * f,
            bytemuck::cast_slice(&splats.log_scales[a..b]),
        );
        // glam's Quat is (x, y, z, w) in memory, which is what the kernel reads.
        q.write_buffer(
            &self.geometry,
            (layout.rotations_at as u64 + a as u64 * 4) * f,
            bytemuck::cast_slice(&splats.rotations[a..b]),
        );
        q.write_buffer(
            &self.geometry,
            (layout.opacities_at as u64 + a as u64) * f,
            bytemuck::cast_slice(&splats.raw_opacities[a..b]),
        );
        let k = splats.sh_coeffs() * 3;
        q.write_buffer(
            &self.sh,
            (a * k) as u64 * f,
            bytemuck::cast_slice(&splats.sh[a * k..b * k]),
        );
        let l = splats.label_channels;
        if l > 0 {
            q.write_buffer(
                &self.raw_labels,
                (a * l) as u64 * f,
                bytemuck::cast_slice(&splats.raw_labels[a * l..b * l]),
            );
        }
    }
}
