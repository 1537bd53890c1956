//! The splats in the viewport through an egui-wgpu paint callback on eframe's own device: in
//! `prepare` the GPU forward pass (`gpu::GpuRenderer`) records into egui's encoder, in `paint` a
//! textured triangle stretches its output over the viewport rectangle. No CPU read-back.

use std::sync::{Arc, Mutex};

use eframe::egui_wgpu::{self, CallbackResources, CallbackTrait, ScreenDescriptor};

use crate::app::settings::Settings;
use crate::damage::layer::DamageLayer;
use crate::gpu::{GpuContext, GpuRenderSettings, GpuRenderer};
use crate::scene::Camera;
use crate::splats::Splats;

const BLIT_SHADER: &str = r"
struct VsOut { @builtin(position) pos: vec4<f32>, @location(0) uv: vec2<f32> };

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> VsOut {
    // One triangle covering the viewport (egui sets the viewport to the callback rectangle).
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var out: VsOut;
    out.pos = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

@group(0) @binding(0) var t_color: texture_2d<f32>;
@group(0) @binding(1) var s_color: sampler;

fn to_linear(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

// The render holds display (sRGB-encoded) values; egui's preferred framebuffers are not
// sRGB-aware, so they are written as they are.
@fragment
fn fs_gamma(in: VsOut) -> @location(0) vec4<f32> {
    let c = textureSample(t_color, s_color, in.uv);
    return vec4<f32>(c.rgb, 1.0);
}

@fragment
fn fs_linear(in: VsOut) -> @location(0) vec4<f32> {
    let c = textureSample(t_color, s_color, in.uv);
    return vec4<f32>(to_linear(c.rgb), 1.0);
}
";

/// What the model on the GPU was built from; a different key means re-upload.
#[derive(Clone, Debug, PartialEq)]
struct UploadKey {
    generation: u64,
    splat_scale: f32,
    damage: crate::damage::layer::DamageLayer,
}

/// One picture's GPU state: its renderer (model, output texture) and what it last drew. The
/// viewport draws one picture, or two when comparing surveys (slot 1 is made on first use).
struct Slot {
    renderer: GpuRenderer,
    bind_group: Option<(u64, wgpu::BindGroup)>,
    uploaded: Option<UploadKey>,
    /// The output texture holds a render of this frame's request (paint draws nothing else).
    rendered: bool,
    /// What the output texture shows: an identical request is not rendered again (on a software
    /// driver a repaint for the UI alone must not pay for a splat render).
    last_render: Option<(UploadKey, Camera, GpuRenderSettings)>,
}

impl Slot {
    fn new(renderer: GpuRenderer) -> Slot {
        Slot {
            renderer,
            bind_group: None,
            uploaded: None,
            rendered: false,
            last_render: None,
        }
    }
}

/// How many pictures the viewport draws at most (the model, and a survey beside it).
pub const SLOTS: usize = 2;

/// GPU state kept in egui-wgpu's callback resources (one per app).
struct SplatResources {
    ctx: GpuContext,
    slots: Vec<Slot>,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    error: Arc<Mutex<Option<String>>>,
}

/// Creates the GPU renderer and the blit pipeline on eframe's device, stored in the callback
/// resources. Returns the error slot the viewport shows, or why the renderer is unavailable.
pub fn install(
    render_state: &egui_wgpu::RenderState,
) -> Result<Arc<Mutex<Option<String>>>, String> {
    let ctx = GpuContext::from_device(
        &render_state.adapter,
        render_state.device.clone(),
        render_state.queue.clone(),
    );
    let renderer = GpuRenderer::new(&ctx).map_err(|e| format!("GPU renderer: {e}"))?;
    let device = &render_state.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("damage-twin blit"),
        source: wgpu::ShaderSource::Wgsl(BLIT_SHADER.into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("damage-twin blit"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    multisampled: false,
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: wgpu::TextureViewDimension::D2,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("damage-twin blit"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let format = render_state.target_format;
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("damage-twin blit"),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_main"),
            buffers: &[],
            compilation_options: wgpu::PipelineCompilationOptions::default(),
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some(if format.is_srgb() {
                "fs_linear"
            } else {
                "fs_gamma"
            }),
            targets: &[Some(wgpu::ColorTargetState {
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
            compilation_options: wgpu::PipelineCompilationOptions::default(),
        }),
        multiview_mask: None,
        cache: None,
    });
    // Linear magnification: a reduced-resolution render while moving is upscaled smoothly.
    let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("damage-twin blit"),
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        ..Default::default()
    });
    let error = Arc::new(Mutex::new(None));
    render_state
        .renderer
        .write()
        .callback_resources
        .insert(SplatResources {
            ctx,
            slots: vec![Slot::new(renderer)],
            pipeline,
            layout,
            sampler,
            error: error.clone(),
        });
    Ok(error)
}

/// One frame's request.
struct SplatCallback {
    slot: usize,
    splats: Arc<Splats>,
    key: UploadKey,
    camera: Camera,
    settings: GpuRenderSettings,
}

impl CallbackTrait for SplatCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        _queue: &wgpu::Queue,
        _screen_descriptor: &ScreenDescriptor,
        egui_encoder: &mut wgpu::CommandEncoder,
        resources: &mut CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(res) = resources.get_mut::<SplatResources>() else {
            return Vec::new();
        };
        while res.slots.len() <= self.slot.min(SLOTS - 1) {
            match GpuRenderer::new(&res.ctx) {
                Ok(renderer) => res.slots.push(Slot::new(renderer)),
                Err(e) => {
                    if let Ok(mut error) = res.error.lock() {
                        *error = Some(format!("GPU renderer: {e}"));
                    }
                    return Vec::new();
                }
            }
        }
        let (layout, sampler) = (&res.layout, &res.sampler);
        let slot = &mut res.slots[self.slot.min(SLOTS - 1)];
        let request = (self.key.clone(), self.camera, self.settings);
        if slot.rendered && slot.last_render.as_ref() == Some(&request) {
            return Vec::new();
        }
        slot.rendered = false;
        slot.last_render = None;
        let result = (|| -> Result<(), String> {
            if slot.uploaded.as_ref() != Some(&self.key) {
                let shown = crate::damage::layer::display_splats(
                    &self.splats,
                    self.key.splat_scale,
                    &self.key.damage,
                );
                slot.renderer.upload(&shown).map_err(|e| e.to_string())?;
                slot.uploaded = Some(self.key.clone());
            }
            if self.splats.is_empty() {
                return Ok(());
            }
            let view = slot
                .renderer
                .render(egui_encoder, &self.camera, &self.settings)
                .map_err(|e| e.to_string())?
                .clone();
            let generation = slot.renderer.output_generation();
            if slot
                .bind_group
                .as_ref()
                .is_none_or(|(g, _)| *g != generation)
            {
                let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("damage-twin blit"),
                    layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::TextureView(&view),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::Sampler(sampler),
                        },
                    ],
                });
                slot.bind_group = Some((generation, bind_group));
            }
            slot.rendered = true;
            slot.last_render = Some(request);
            Ok(())
        })();
        if let Ok(mut error) = res.error.lock() {
            *error = result.err();
        }
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        render_pass: &mut wgpu::RenderPass<'static>,
        resources: &CallbackResources,
    ) {
        let Some(res) = resources.get::<SplatResources>() else {
            return;
        };
        let Some(slot) = res.slots.get(self.slot) else {
            return;
        };
        let Some((_, bind_group)) = slot.bind_group.as_ref().filter(|_| slot.rendered) else {
            return;
        };
        render_pass.set_pipeline(&res.pipeline);
        render_pass.set_bind_group(0, bind_group, &[]);
        render_pass.draw(0..3, 0..1);
    }
}

/// The viewport's handle on the GPU splat renderer.
#[derive(Default)]
pub struct SplatView {
    /// Set once `install` ran: the renderer's error slot, or why there is no renderer.
    installed: Option<Result<Arc<Mutex<Option<String>>>, String>>,
    /// Per slot, the last request queued, to tell frames that render from frames that reuse
    /// the picture.
    last_request: [Option<(UploadKey, Camera, GpuRenderSettings)>; SLOTS],
    /// eframe's adapter is a CPU implementation (lavapipe, llvmpipe).
    software: bool,
}

impl SplatView {
    /// Installs the renderer on eframe's device (once).
    pub fn install(&mut self, render_state: Option<&egui_wgpu::RenderState>) {
        if self.installed.is_none() {
            self.software = render_state
                .is_some_and(|rs| rs.adapter.get_info().device_type == wgpu::DeviceType::Cpu);
            self.installed = Some(match render_state {
                Some(rs) => install(rs),
                None => Err("no wgpu render state: the viewer needs eframe's wgpu backend".into()),
            });
        }
    }

    /// True when eframe draws through a software driver.
    pub fn is_software(&self) -> bool {
        self.software
    }

    /// True when splats can be drawn.
    pub fn is_available(&self) -> bool {
        matches!(self.installed, Some(Ok(_)))
    }

    /// The last render error, or why there is no renderer.
    pub fn error(&self) -> Option<String> {
        match &self.installed {
            None => None,
            Some(Err(e)) => Some(e.clone()),
            Some(Ok(slot)) => slot.lock().ok().and_then(|s| s.clone()),
        }
    }

    /// Queues the splats for drawing into `rect` with `camera` (its intrinsics set the render
    /// resolution; the output is stretched over `rect`) in picture `slot` (below [`SLOTS`]), with
    /// `damage` as the damage layer. Returns true when this frame renders, false when the request
    /// is the last one again and the picture is reused.
    #[allow(clippy::too_many_arguments)]
    pub fn paint(
        &mut self,
        painter: &egui::Painter,
        slot: usize,
        rect: egui::Rect,
        camera: &Camera,
        splats: &Arc<Splats>,
        generation: u64,
        settings: &Settings,
        damage: &DamageLayer,
    ) -> bool {
        if !self.is_available() {
            return false;
        }
        let slot = slot.min(SLOTS - 1);
        let callback = SplatCallback {
            slot,
            splats: splats.clone(),
            key: UploadKey {
                generation,
                splat_scale: settings.splat_scale,
                damage: damage.clone(),
            },
            camera: *camera,
            settings: GpuRenderSettings {
                background: glam::Vec3::from_array(settings.background),
                sh_degree: splats.sh_degree,
                ..GpuRenderSettings::default()
            },
        };
        let request = (callback.key.clone(), callback.camera, callback.settings);
        let renders = !splats.is_empty() && self.last_request[slot].as_ref() != Some(&request);
        self.last_request[slot] = Some(request);
        painter.add(egui_wgpu::Callback::new_paint_callback(rect, callback));
        renders
    }
}
