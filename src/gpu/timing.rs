//! Per-stage GPU timings for the bench: timestamp queries at compute-pass boundaries when the
//! adapter has them; the renderer falls back to wall time per stage (submit, wait) otherwise.
//! Never used on the viewer's rendering path.

use super::{GpuContext, GpuError, readback};

/// The forward pass's stages, in execution order; each is one compute pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    Project,
    DepthSort,
    Offsets,
    Emit,
    TileSort,
    TileRanges,
    Rasterize,
}

impl Stage {
    pub const ALL: [Stage; 7] = [
        Stage::Project,
        Stage::DepthSort,
        Stage::Offsets,
        Stage::Emit,
        Stage::TileSort,
        Stage::TileRanges,
        Stage::Rasterize,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Project => "project",
            Stage::DepthSort => "depth_sort",
            Stage::Offsets => "offsets",
            Stage::Emit => "emit",
            Stage::TileSort => "tile_sort",
            Stage::TileRanges => "tile_ranges",
            Stage::Rasterize => "rasterize",
        }
    }

    fn index(self) -> u32 {
        Stage::ALL.iter().position(|&s| s == self).unwrap_or(0) as u32
    }
}

/// A query set with a begin and an end timestamp per stage.
pub struct TimestampQueries {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    period_ns: f32,
}

const QUERIES: u32 = 2 * Stage::ALL.len() as u32;

impl TimestampQueries {
    /// `None` when the device was created without `TIMESTAMP_QUERY`.
    pub fn new(ctx: &GpuContext) -> Option<TimestampQueries> {
        if !ctx.capabilities.timestamps {
            return None;
        }
        let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("stage timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count: QUERIES,
        });
        let resolve = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("stage timestamps.resolve"),
            size: QUERIES as u64 * 8,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Some(TimestampQueries {
            set,
            resolve,
            period_ns: ctx.queue.get_timestamp_period(),
        })
    }

    /// Timestamp writes for the compute pass of `stage`.
    pub fn writes(&self, stage: Stage) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: Some(2 * stage.index()),
            end_of_pass_write_index: Some(2 * stage.index() + 1),
        }
    }

    /// Records the resolve of all queries (after the last stage).
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.set, 0..QUERIES, &self.resolve, 0);
    }

    /// Milliseconds per stage, in [`Stage::ALL`] order (blocking read-back).
    pub fn read_ms(&self, ctx: &GpuContext) -> Result<Vec<f64>, GpuError> {
        let bytes = readback::read_bytes(ctx, &self.resolve, QUERIES as u64 * 8)?;
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(ticks
            .chunks(2)
            .map(|c| c[1].saturating_sub(c[0]) as f64 * self.period_ns as f64 / 1e6)
            .collect())
    }
}
