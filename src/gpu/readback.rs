//! Blocking GPU→CPU copies of buffers, for tests, the bench and `render_to_image` only: the
//! rendering path never calls these (it would stall the frame).

use super::{GpuContext, GpuError};

/// Copies the first `bytes` bytes of `buffer` (which needs `COPY_SRC`) to the CPU, waiting.
pub fn read_bytes(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    bytes: u64,
) -> Result<Vec<u8>, GpuError> {
    if bytes == 0 {
        return Ok(Vec::new());
    }
    let size = bytes.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
    ctx.queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    ctx.wait_idle()?;
    rx.recv()
        .map_err(|e| GpuError::Readback(e.to_string()))?
        .map_err(|e| GpuError::Readback(e.to_string()))?;
    let data = staging
        .slice(..)
        .get_mapped_range()
        .map_err(|e| GpuError::Readback(e.to_string()))?[..bytes as usize]
        .to_vec();
    staging.unmap();
    Ok(data)
}

/// The first `count` `u32`s of a buffer.
pub fn read_u32(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    count: usize,
) -> Result<Vec<u32>, GpuError> {
    let bytes = read_bytes(ctx, buffer, count as u64 * 4)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}

/// The first `count` `f32`s of a buffer.
pub fn read_f32(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    count: usize,
) -> Result<Vec<f32>, GpuError> {
    let bytes = read_bytes(ctx, buffer, count as u64 * 4)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}
