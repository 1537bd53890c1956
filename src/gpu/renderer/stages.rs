//! The renderer stage by stage: each stage's output of the last frame read back (the stage
//! tests compare them with `raster`), and one frame timed per stage (`bench`, the GPU
//! trainer's timed steps).

use std::time::Instant;

use super::{GpuRenderSettings, GpuRenderer, StageTimings};
use crate::gpu::GpuError;
use crate::gpu::project::{PROJECTED_BYTES, ProjectedSplat};
use crate::gpu::readback;
use crate::gpu::timing::{Stage, TimestampQueries};
use crate::scene::Camera;

impl GpuRenderer {
    /// The unclamped number of tile/Gaussian intersections of the last frame (blocking).
    pub fn read_intersection_count(&self) -> Result<u32, GpuError> {
        Ok(readback::read_u32(&self.ctx, &self.isect_count, 1)?[0])
    }

    /// The last frame's projection, per Gaussian in model order (blocking; stage tests).
    pub fn read_projected(&self) -> Result<Vec<ProjectedSplat>, GpuError> {
        let frame = self.last_frame()?;
        let n = self.splats.len();
        let bytes = readback::read_bytes(&self.ctx, &frame.projected, n as u64 * PROJECTED_BYTES)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// The last frame's Gaussian ids in depth order (blocking; stage tests).
    pub fn read_depth_order(&self) -> Result<Vec<u32>, GpuError> {
        let frame = self.last_frame()?;
        readback::read_u32(&self.ctx, &frame.depth_gids, self.splats.len())
    }

    /// The last frame's sorted intersections (Gaussian id per intersection, ordered by tile then
    /// depth) and per tile its `[start, end)` range, like `raster::Rasterizer::tile_bins`.
    pub fn read_tile_bins(&self) -> Result<(Vec<u32>, Vec<[u32; 2]>), GpuError> {
        let frame = self.last_frame()?;
        let plan = self
            .plan
            .ok_or(GpuError::Readback("nothing rendered yet".into()))?;
        let count = self.read_intersection_count()?.min(self.isect.capacity);
        let (_, gids) = self.sorted_isects(&plan);
        let gids = readback::read_u32(&self.ctx, gids, count as usize)?;
        let tiles = (plan.tile_bounds[0] * plan.tile_bounds[1]) as usize;
        let flat = readback::read_u32(&self.ctx, &frame.ranges, tiles * 2)?;
        Ok((gids, flat.chunks_exact(2).map(|c| [c[0], c[1]]).collect()))
    }

    /// One frame with per-stage timings: GPU timestamps when the device has them, otherwise
    /// each stage submitted and waited for on its own (wall time, includes submit overhead).
    /// Call [`GpuRenderer::render_blocking`] for the same view first, so that the buffers
    /// already fit and the timed frame is an ordinary one.
    pub fn render_timed(
        &mut self,
        camera: &Camera,
        settings: &GpuRenderSettings,
    ) -> Result<StageTimings, GpuError> {
        let plan = self.prepare(camera, settings)?;
        let start = Instant::now();
        let mut stages = Vec::with_capacity(Stage::ALL.len());
        let source = if let Some(queries) = TimestampQueries::new(&self.ctx) {
            let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
            encoder.clear_buffer(&self.isect_count, 0, None);
            for stage in Stage::ALL {
                self.encode_stage(&mut encoder, stage, &plan, Some(queries.writes(stage)));
            }
            queries.resolve(&mut encoder);
            self.ctx.queue.submit([encoder.finish()]);
            self.ctx.wait_idle()?;
            let ms = queries.read_ms(&self.ctx)?;
            stages.extend(Stage::ALL.iter().zip(ms).map(|(s, ms)| (s.name(), ms)));
            "gpu-timestamps"
        } else {
            for (i, stage) in Stage::ALL.into_iter().enumerate() {
                let t0 = Instant::now();
                let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
                if i == 0 {
                    encoder.clear_buffer(&self.isect_count, 0, None);
                }
                self.encode_stage(&mut encoder, stage, &plan, None);
                self.ctx.queue.submit([encoder.finish()]);
                self.ctx.wait_idle()?;
                stages.push((stage.name(), t0.elapsed().as_secs_f64() * 1e3));
            }
            "wall-clock"
        };
        let total_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(StageTimings {
            source,
            stages,
            total_ms,
            intersections: self.read_intersection_count()?,
        })
    }
}
