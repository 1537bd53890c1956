//! Host side of `shaders/adam.wgsl`: Adam's moments and density control's statistics on the
//! GPU, beside the model in `SplatBuffers`, so a training step reads back 4 bytes instead of the
//! gradients. The moments cross the bus only when the trainer syncs (density control,
//! checkpoints), in the CPU optimiser's per-group layout so `train::adam::Adam` stays the state
//! that densification edits.

use bytemuck::{Pod, Zeroable};

use super::backward::BackwardBuffers;
use super::kernel::{self, Bind};
use super::splat_buffers::{GeometryLayout, SplatBuffers};
use super::{GpuContext, GpuError, readback};

const SHADER: &str = super::kernel::stage_source!("adam.wgsl");

/// Floats per Gaussian in the geometry buffer (`splat_buffers`).
const GEOMETRY_FLOATS: usize = 11;
/// Words before the per-Gaussian statistics (word 0: the non-finite bits).
const STATS_AT: usize = 4;
const STATS_WORDS: usize = 4;

/// The optimiser's groups in `train::adam::ParamGroup` order.
pub const GROUPS: usize = 7;

/// One group's update this step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GroupStep {
    /// `lr / (1 - β1^t)`.
    pub step_size: f32,
    /// `1 / sqrt(1 - β2^t)`.
    pub inv_bias2_sqrt: f32,
    pub on: bool,
}

/// Byte for byte `AdamUniforms` in `shaders/adam.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct AdamUniforms {
    groups: [[f32; 4]; GROUPS],
    beta1: f32,
    beta2: f32,
    eps: f32,
    num_gaussians: u32,
    log_scales_at: u32,
    rotations_at: u32,
    opacities_at: u32,
    sh_floats: u32,
    label_channels: u32,
    v_geometry_at: u32,
    m_sh_at: u32,
    v_sh_at: u32,
    m_labels_at: u32,
    v_labels_at: u32,
    pad: [u32; 2],
}

/// Where each moment section lies in the moments buffer (f32s), for capacity C.
#[derive(Clone, Copy, Debug, PartialEq)]
struct MomentLayout {
    capacity: usize,
    sh_floats: usize,
    label_channels: usize,
}

impl MomentLayout {
    fn v_geometry_at(&self) -> usize {
        GEOMETRY_FLOATS * self.capacity
    }
    fn m_sh_at(&self) -> usize {
        2 * GEOMETRY_FLOATS * self.capacity
    }
    fn v_sh_at(&self) -> usize {
        self.m_sh_at() + self.sh_floats * self.capacity
    }
    fn m_labels_at(&self) -> usize {
        self.v_sh_at() + self.sh_floats * self.capacity
    }
    fn v_labels_at(&self) -> usize {
        self.m_labels_at() + self.label_channels * self.capacity
    }
    fn len(&self) -> usize {
        self.v_labels_at() + self.label_channels * self.capacity
    }

    /// Per group, for Gaussian `g` and value `i` of the group's `per` values, the index of its
    /// first moment in the buffer (the second is at `+ v_offset(group)`).
    fn m_index(&self, geo: &GeometryLayout, group: usize, g: usize, i: usize) -> usize {
        let (k, l) = (self.sh_floats, self.label_channels);
        match group {
            0 => 3 * g + i,
            1 => geo.log_scales_at as usize + 3 * g + i,
            2 => geo.rotations_at as usize + 4 * g + i,
            3 => geo.opacities_at as usize + g,
            4 => self.m_sh_at() + g * k + i,
            5 => self.m_sh_at() + g * k + 3 + i,
            _ => self.m_labels_at() + g * l + i,
        }
    }

    fn v_offset(&self, group: usize) -> usize {
        match group {
            0..=3 => self.v_geometry_at(),
            4 | 5 => self.sh_floats * self.capacity,
            _ => self.label_channels * self.capacity,
        }
    }

    /// Values per Gaussian of each group.
    fn per_gaussian(&self) -> [usize; GROUPS] {
        [
            3,
            3,
            4,
            1,
            3.min(self.sh_floats),
            self.sh_floats.saturating_sub(3),
            self.label_channels,
        ]
    }
}

/// Values per Gaussian of each group for `splats` (`train::adam::Adam::new`'s layout).
pub fn per_group_counts(splats: &crate::splats::Splats) -> [usize; GROUPS] {
    MomentLayout {
        capacity: 1,
        sh_floats: splats.sh_coeffs() * 3,
        label_channels: splats.label_channels,
    }
    .per_gaussian()
}

/// Adam's moments in the CPU optimiser's per-group layout: `(m, v)` per group.
pub type Moments = [(Vec<f32>, Vec<f32>); GROUPS];

/// Density control's statistics gathered on the GPU since the last read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DensifyStats {
    pub grad_accum: Vec<f32>,
    pub visible_count: Vec<u32>,
    pub max_radii: Vec<f32>,
}

pub struct GpuAdam {
    pipeline: wgpu::ComputePipeline,
    /// This step's rates (rewritten every step).
    uniforms: wgpu::Buffer,
    layout: Option<MomentLayout>,
    moments: wgpu::Buffer,
    stats: wgpu::Buffer,
    frozen: Vec<bool>,
}

impl GpuAdam {
    pub fn new(ctx: &GpuContext) -> GpuAdam {
        let none = wgpu::BufferUsages::empty();
        GpuAdam {
            pipeline: kernel::pipeline(&ctx.device, "adam", SHADER, "adam_step"),
            uniforms: kernel::uniform::<AdamUniforms>(&ctx.device, "adam uniforms"),
            layout: None,
            moments: kernel::storage(&ctx.device, "adam moments", 0, none),
            stats: kernel::storage(&ctx.device, "adam stats", 0, none),
            frozen: Vec::new(),
        }
    }

    /// Writes the moments (`moments[group] = (m, v)`, the CPU optimiser's per-group layout for
    /// the `splats.len()` Gaussians uploaded in `splats`), zeroes the statistics and records
    /// which Gaussians are frozen.
    pub fn upload(
        &mut self,
        ctx: &GpuContext,
        splats: &SplatBuffers,
        moments: [(&[f32], &[f32]); GROUPS],
        frozen: &[bool],
    ) -> Result<(), GpuError> {
        let n = splats.len();
        let layout = MomentLayout {
            capacity: splats.capacity().max(1),
            sh_floats: crate::splats::model::sh_coeffs_for_degree(splats.sh_degree()) * 3,
            label_channels: splats.label_channels(),
        };
        let per = layout.per_gaussian();
        for (group, (m, v)) in moments.iter().enumerate() {
            if m.len() != n * per[group] || v.len() != m.len() {
                return Err(GpuError::InvalidSplats(format!(
                    "Adam group {group} has {} moments for {n} Gaussians × {}",
                    m.len(),
                    per[group]
                )));
            }
        }
        if frozen.len() != n {
            return Err(GpuError::InvalidSplats(format!(
                "{} frozen flags for {n} Gaussians",
                frozen.len()
            )));
        }
        let device = &ctx.device;
        let none = wgpu::BufferUsages::empty();
        if self.layout != Some(layout) {
            self.moments = kernel::storage(device, "adam moments", layout.len() as u64 * 4, none);
            self.stats = kernel::storage(
                device,
                "adam stats",
                ((STATS_AT + STATS_WORDS * layout.capacity) * 4) as u64,
                none,
            );
            self.layout = Some(layout);
        }
        let geo = splats.layout();
        let mut flat = vec![0.0f32; layout.len()];
        for (group, (m, v)) in moments.iter().enumerate() {
            let p = per[group];
            let v_offset = layout.v_offset(group);
            for g in 0..n {
                for i in 0..p {
                    let at = layout.m_index(&geo, group, g, i);
                    flat[at] = m[g * p + i];
                    flat[at + v_offset] = v[g * p + i];
                }
            }
        }
        ctx.queue
            .write_buffer(&self.moments, 0, bytemuck::cast_slice(&flat));
        self.frozen = frozen.to_vec();
        self.write_zero_stats(ctx);
        Ok(())
    }

    fn write_zero_stats(&self, ctx: &GpuContext) {
        let mut words = vec![0u32; STATS_AT + STATS_WORDS * self.frozen.len()];
        for (g, &frozen) in self.frozen.iter().enumerate() {
            words[STATS_AT + STATS_WORDS * g + 3] = u32::from(frozen);
        }
        ctx.queue
            .write_buffer(&self.stats, 0, bytemuck::cast_slice(&words));
    }

    /// The moments in the CPU optimiser's per-group layout for the first `n` Gaussians.
    pub fn download(&self, ctx: &GpuContext, splats: &SplatBuffers) -> Result<Moments, GpuError> {
        let layout = self
            .layout
            .ok_or(GpuError::Readback("no Adam state uploaded".into()))?;
        let n = splats.len();
        let flat = readback::read_f32(ctx, &self.moments, layout.len())?;
        let geo = splats.layout();
        let per = layout.per_gaussian();
        Ok(std::array::from_fn(|group| {
            let p = per[group];
            let v_offset = layout.v_offset(group);
            let mut m = vec![0.0; n * p];
            let mut v = vec![0.0; n * p];
            for g in 0..n {
                for i in 0..p {
                    let at = layout.m_index(&geo, group, g, i);
                    m[g * p + i] = flat[at];
                    v[g * p + i] = flat[at + v_offset];
                }
            }
            (m, v)
        }))
    }

    /// Reads the statistics gathered since the last upload or read, and zeroes them.
    pub fn take_stats(&mut self, ctx: &GpuContext) -> Result<DensifyStats, GpuError> {
        let n = self.frozen.len();
        let words = readback::read_u32(ctx, &self.stats, STATS_AT + STATS_WORDS * n)?;
        let mut stats = DensifyStats::default();
        for g in 0..n {
            let s = STATS_AT + STATS_WORDS * g;
            stats.grad_accum.push(f32::from_bits(words[s]));
            stats.visible_count.push(words[s + 1]);
            stats.max_radii.push(f32::from_bits(words[s + 2]));
        }
        self.write_zero_stats(ctx);
        Ok(stats)
    }

    /// The non-finite bits of the steps since the last call (bit g: a gradient of group g,
    /// bit 8 + g: a parameter it wrote), zeroed after reading.
    pub fn take_non_finite(&self, ctx: &GpuContext) -> Result<u32, GpuError> {
        let bits = readback::read_u32(ctx, &self.stats, 1)?[0];
        if bits != 0 {
            ctx.queue
                .write_buffer(&self.stats, 0, bytemuck::bytes_of(&0u32));
        }
        Ok(bits)
    }

    /// Records one Adam step of the model in `splats` with the gradients in `grads`.
    pub(super) fn encode_step(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        splats: &SplatBuffers,
        grads: &BackwardBuffers,
        groups: &[GroupStep; GROUPS],
        betas: (f32, f32, f32),
    ) -> Result<(), GpuError> {
        let layout = self
            .layout
            .ok_or(GpuError::Device("no Adam state uploaded".into()))?;
        let geo = splats.layout();
        let u32_of = |v: usize| v as u32;
        let uniforms = AdamUniforms {
            groups: groups.map(|s| {
                [
                    s.step_size,
                    s.inv_bias2_sqrt,
                    f32::from(u8::from(s.on)),
                    0.0,
                ]
            }),
            beta1: betas.0,
            beta2: betas.1,
            eps: betas.2,
            num_gaussians: u32_of(splats.len()),
            log_scales_at: geo.log_scales_at,
            rotations_at: geo.rotations_at,
            opacities_at: geo.opacities_at,
            sh_floats: u32_of(layout.sh_floats),
            label_channels: u32_of(layout.label_channels),
            v_geometry_at: u32_of(layout.v_geometry_at()),
            m_sh_at: u32_of(layout.m_sh_at()),
            v_sh_at: u32_of(layout.v_sh_at()),
            m_labels_at: u32_of(layout.m_labels_at()),
            v_labels_at: u32_of(layout.v_labels_at()),
            pad: [0; 2],
        };
        let device = &ctx.device;
        // Written in queue order, before the submission that holds this step.
        ctx.queue
            .write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&uniforms));
        let group = kernel::bind_group(
            device,
            &self.pipeline,
            &[
                (0, Bind::Buffer(&self.uniforms)),
                (1, Bind::Buffer(splats.geometry())),
                (2, Bind::Buffer(splats.sh())),
                (3, Bind::Buffer(splats.raw_labels())),
                (4, Bind::Buffer(&grads.param_grads)),
                (5, Bind::Buffer(&grads.v_sh)),
                (6, Bind::Buffer(&grads.v_raw_labels)),
                (7, Bind::Buffer(&self.moments)),
                (8, Bind::Buffer(&self.stats)),
            ],
        );
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("adam"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        kernel::dispatch(&mut pass, (splats.len() as u32).div_ceil(kernel::WORKGROUP));
        Ok(())
    }
}
