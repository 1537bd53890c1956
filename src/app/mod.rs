//! The desktop viewer (eframe + egui + wgpu): the app shell, panels, viewport and the client side
//! of training jobs. It holds no algorithm: rendering is `gpu`/`raster`, training is `train::job`,
//! files are `scene`. Everything the UI does is a `Command` a headless caller can apply too.

pub mod camera_controller;
pub mod commands;
pub mod cpu_view;
pub mod demo;
pub mod files;
pub mod frame_log;
pub mod overlay;
pub mod panels;
pub mod photo_damage;
pub mod resolution;
pub mod scene_frame;
pub mod settings;
pub mod splat_view;
pub mod state;
pub mod survey_form;
pub mod tools;
pub mod training;
pub mod twin_form;
pub mod viewport;
pub mod workers;

use std::path::PathBuf;
use std::sync::Arc;

use crate::app::commands::{Command, DialogKind};
use crate::app::demo::DemoPreparation;
use crate::app::panels::{
    AddSurveyPanel, ChartsPanel, ColmapLogPanel, LogPanel, NewTwinPanel, ProjectPanel,
    RegionsPanel, SelectionPanel, StatsPanel, TimelinePanel, TrainingPanel, ViewPanel,
};
use crate::app::settings::Settings;
use crate::app::state::AppState;
use crate::app::viewport::Viewport;

/// What the app opens on start.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Launch {
    /// Nothing: an empty viewer.
    #[default]
    Empty,
    /// The built-in demo building (generated into the cache on first run), training live.
    Demo,
    /// A dataset, project or model; `train` starts training once it is open.
    Open { path: PathBuf, train: bool },
}

/// The wgpu setup for the viewer and its tests: the adapter `gpu` prefers, with the adapter's
/// own limits (eframe's defaults allow too few storage buffers for the splat kernels, STACK.md).
pub fn wgpu_setup() -> eframe::egui_wgpu::WgpuSetup {
    let mut setup = eframe::egui_wgpu::WgpuSetupCreateNew::without_display_handle();
    setup.instance_descriptor.backends =
        wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY | wgpu::Backends::GL);
    setup.native_adapter_selector = Some(Arc::new(|adapters, _surface| {
        crate::gpu::context::pick_adapter(adapters)
            .cloned()
            .ok_or_else(|| "no wgpu adapter (install mesa-vulkan-drivers for lavapipe)".to_string())
    }));
    setup.device_descriptor = Arc::new(crate::gpu::context::device_descriptor);
    eframe::egui_wgpu::WgpuSetup::CreateNew(setup)
}

/// Opens the window and runs until it is closed.
pub fn run(launch: Launch) -> anyhow::Result<()> {
    let mut options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("damage-twin")
            .with_inner_size([1280.0, 800.0])
            .with_drag_and_drop(true),
        ..Default::default()
    };
    options.wgpu_options.wgpu_setup = wgpu_setup();
    eframe::run_native(
        "damage-twin",
        options,
        Box::new(move |cc| Ok(Box::new(TwinApp::new(cc, launch)))),
    )
    .map_err(|e| anyhow::anyhow!("the viewer stopped: {e}"))
}

/// The application: state, panels, viewport and the command queue between them.
pub struct TwinApp {
    pub state: AppState,
    pub viewport: Viewport,
    project: ProjectPanel,
    training: TrainingPanel,
    view: ViewPanel,
    stats: StatsPanel,
    selection: SelectionPanel,
    regions: RegionsPanel,
    charts: ChartsPanel,
    timeline: TimelinePanel,
    add_survey: AddSurveyPanel,
    new_twin: NewTwinPanel,
    colmap_log: ColmapLogPanel,
    log: LogPanel,
    commands: Vec<Command>,
    demo: Option<DemoPreparation>,
}

impl TwinApp {
    /// The app inside eframe: settings from storage, the GPU renderer on eframe's device.
    pub fn new(cc: &eframe::CreationContext<'_>, launch: Launch) -> TwinApp {
        let settings = Settings::load(cc.storage);
        let mut app = TwinApp::with_settings(settings, launch);
        app.state.interactive = true;
        app.viewport.install_renderer(cc.wgpu_render_state.as_ref());
        app
    }

    /// The app without a window (tests, headless callers): no dialogs, no GPU until
    /// `viewport.install_renderer` is called.
    pub fn with_settings(settings: Settings, launch: Launch) -> TwinApp {
        let mut app = TwinApp {
            state: AppState::new(settings),
            viewport: Viewport::default(),
            project: ProjectPanel,
            training: TrainingPanel,
            view: ViewPanel,
            stats: StatsPanel,
            selection: SelectionPanel::default(),
            regions: RegionsPanel,
            charts: ChartsPanel,
            timeline: TimelinePanel::default(),
            add_survey: AddSurveyPanel,
            new_twin: NewTwinPanel,
            colmap_log: ColmapLogPanel,
            log: LogPanel,
            commands: Vec::new(),
            demo: None,
        };
        match launch {
            Launch::Empty => {}
            Launch::Demo => {
                app.state.train_on_open = true;
                app.demo = Some(DemoPreparation::start(crate::synth::demo::cache_dir()));
            }
            Launch::Open { path, train } => {
                app.state.train_on_open = train;
                app.state.apply(Command::Open(path));
            }
        }
        app
    }

    /// Queues a command (as a panel would).
    pub fn push(&mut self, command: Command) {
        self.commands.push(command);
    }

    /// Applies queued commands and drains worker results; what a frame does besides drawing.
    pub fn update_state(&mut self) -> bool {
        let mut changed = !self.commands.is_empty();
        for command in std::mem::take(&mut self.commands) {
            self.state.apply(command);
        }
        if let Some(demo) = &mut self.demo {
            changed = true;
            if let Some(result) = demo.poll() {
                match result {
                    Ok(dir) => self.state.apply(Command::Open(dir)),
                    Err(e) => self
                        .state
                        .log_line(format!("error: the demo could not be generated: {e}")),
                }
                self.demo = None;
            }
        }
        self.state.poll() || changed
    }

    fn shortcuts(&mut self, ctx: &egui::Context) {
        let (open, save, frame) = ctx.input_mut(|i| {
            (
                i.consume_key(egui::Modifiers::COMMAND, egui::Key::O),
                i.consume_key(egui::Modifiers::COMMAND, egui::Key::S),
                i.consume_key(egui::Modifiers::NONE, egui::Key::F),
            )
        });
        if !ctx.egui_wants_keyboard_input() {
            let shift_command = egui::Modifiers::SHIFT | egui::Modifiers::COMMAND;
            // Longer chords first: consume_key matches modifiers exactly.
            for (modifiers, key, command) in [
                (shift_command, egui::Key::A, Command::SelectNone),
                (egui::Modifiers::COMMAND, egui::Key::A, Command::SelectAll),
                (
                    egui::Modifiers::COMMAND,
                    egui::Key::I,
                    Command::InvertSelection,
                ),
                (shift_command, egui::Key::Z, Command::Redo),
                (egui::Modifiers::COMMAND, egui::Key::Z, Command::Undo),
                (egui::Modifiers::SHIFT, egui::Key::H, Command::UnhideAll),
                (egui::Modifiers::NONE, egui::Key::H, Command::HideSelected),
            ] {
                if ctx.input_mut(|i| i.consume_key(modifiers, key)) {
                    self.commands.push(command);
                }
            }
        }
        if open {
            self.commands
                .push(Command::ShowDialog(DialogKind::OpenFolder));
        }
        if save {
            self.commands.push(Command::SaveProjectHere);
        }
        if frame && !ctx.egui_wants_keyboard_input() {
            self.commands.push(Command::FrameSelection);
        }
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        for path in dropped {
            self.commands.push(Command::Open(path));
        }
    }

    fn top_bar(&mut self, ui: &mut egui::Ui) {
        egui::Panel::top("top-bar").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.strong("damage-twin");
                ui.separator();
                if let Some(demo) = &self.demo {
                    ui.add(
                        egui::ProgressBar::new(demo.fraction())
                            .text(format!("preparing the demo building: {}", demo.message()))
                            .desired_width(360.0)
                            .animate(true),
                    );
                } else if let Some(t) = &self.state.training {
                    ui.add(
                        egui::ProgressBar::new(t.fraction())
                            .desired_width(200.0)
                            .show_percentage(),
                    );
                }
                if let Some(line) = self.state.log.back() {
                    ui.weak(line);
                }
            });
        });
    }
}

impl eframe::App for TwinApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.shortcuts(&ctx);
        if self.update_state() {
            // Progress arrives every step: a few repaints a second show it without taking the
            // training thread's core on a software renderer.
            ctx.request_repaint_after(std::time::Duration::from_millis(250));
        } else if self.state.timeline.is_some() {
            // An open project is watched for other writers (state::project_watch) once a second.
            ctx.request_repaint_after(std::time::Duration::from_secs(1));
        }
        self.top_bar(ui);

        let state = &self.state;
        let commands = &mut self.commands;
        egui::Panel::left("controls")
            .resizable(true)
            .default_size(300.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| {
                    egui::CollapsingHeader::new("Project")
                        .default_open(true)
                        .show(ui, |ui| self.project.ui(ui, state, commands));
                    egui::CollapsingHeader::new("Training")
                        .default_open(true)
                        .show(ui, |ui| self.training.ui(ui, state, commands));
                    egui::CollapsingHeader::new("Statistics")
                        .default_open(true)
                        .show(ui, |ui| self.stats.ui(ui, state, commands));
                    egui::CollapsingHeader::new("Selection")
                        .default_open(false)
                        .show(ui, |ui| self.selection.ui(ui, state, commands));
                    egui::CollapsingHeader::new("Damage regions")
                        .default_open(false)
                        .show(ui, |ui| self.regions.ui(ui, state, commands));
                    egui::CollapsingHeader::new("View")
                        .default_open(false)
                        .show(ui, |ui| self.view.ui(ui, state, commands));
                });
            });
        if state.settings.show_charts {
            egui::Panel::right("charts")
                .resizable(true)
                .default_size(280.0)
                .show(ui, |ui| self.charts.ui(ui, state, commands));
        }
        egui::Panel::bottom("log")
            .resizable(true)
            .default_size(90.0)
            .show(ui, |ui| self.log.ui(ui, state, commands));
        if state.timeline.is_some() {
            egui::Panel::bottom("timeline")
                .resizable(false)
                .show(ui, |ui| self.timeline.ui(ui, state, commands));
        }
        self.add_survey.ui(&ctx, state, commands);
        self.new_twin.ui(&ctx, state, commands);
        self.colmap_log.ui(&ctx, state, commands);
        egui::CentralPanel::no_frame().show(ui, |ui| {
            // What the viewport drew with applies now, not after the next frame's panels: they
            // and the queued commands see the camera and size the picture shows.
            for command in self.viewport.ui(ui, &self.state, &mut self.commands) {
                self.state.apply(command);
            }
        });
        if self.demo.is_some()
            || self.state.measuring
            || self.state.refine.is_some()
            || self
                .state
                .timeline
                .as_ref()
                .is_some_and(|t| t.job.is_some() || !t.loading.is_empty())
            || self.state.training.as_ref().is_some_and(|t| t.is_running())
        {
            // Keep polling the workers while they run (events arrive between input events), as
            // often as snapshots come: on a software driver every UI frame costs CPU time that
            // training needs.
            ctx.request_repaint_after(std::time::Duration::from_millis(250));
        } else if self.state.timeline.is_some() {
            // An open project is watched for other writers (state::project_watch) once a second.
            ctx.request_repaint_after(std::time::Duration::from_secs(1));
        }
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        self.state.settings.save(storage);
    }
}
