//! COLMAP's log in a window, one click from the dialogs that run it: the last lines of the log of
//! the run writing the dataset (`state::colmap_log_of`: the running job's, the dataset's, or the
//! copy a failed run kept), read again each frame while the window is open. Also the progress bar
//! of a COLMAP job, from the stages COLMAP prints.

use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use crate::app::commands::Command;
use crate::app::state::{AppState, colmap_log_of};
use crate::train::job::Progress;

/// The log's tail shown (bytes): a mapper's log runs to megabytes.
const TAIL_BYTES: u64 = 64 * 1024;

#[derive(Default)]
pub struct ColmapLogPanel;

impl ColmapLogPanel {
    pub fn ui(&mut self, ctx: &egui::Context, state: &AppState, commands: &mut Vec<Command>) {
        let Some(dataset) = &state.colmap_log else {
            return;
        };
        let mut open = true;
        egui::Window::new("COLMAP log")
            .open(&mut open)
            .default_width(640.0)
            .default_height(360.0)
            .show(ctx, |ui| match colmap_log_of(dataset) {
                Some(path) => {
                    ui.label(path.display().to_string());
                    let text = log_tail(&path).unwrap_or_else(|e| format!("cannot read it: {e}"));
                    egui::ScrollArea::vertical()
                        .stick_to_bottom(true)
                        .show(ui, |ui| {
                            ui.add(egui::Label::new(egui::RichText::new(text).monospace()));
                        });
                }
                None => {
                    ui.weak(format!(
                        "No COLMAP log for {} (not run yet, or cancelled: a cancel keeps nothing)",
                        dataset.display()
                    ));
                }
            });
        if !open {
            commands.push(Command::ShowColmapLog(None));
        }
    }
}

/// The last `TAIL_BYTES` of the log, from a line start.
fn log_tail(path: &Path) -> std::io::Result<String> {
    let mut file = std::fs::File::open(path)?;
    let length = file.metadata()?.len();
    let start = length.saturating_sub(TAIL_BYTES);
    file.seek(SeekFrom::Start(start))?;
    let mut bytes = Vec::new();
    file.take(TAIL_BYTES).read_to_end(&mut bytes)?;
    let text = String::from_utf8_lossy(&bytes).into_owned();
    Ok(match (start > 0, text.split_once('\n')) {
        (true, Some((_, rest))) => rest.to_string(),
        _ => text,
    })
}

/// A COLMAP job's progress bar: the stage COLMAP is in ("features 3/29", "matching", "mapping:
/// 14 of 29 registered") and the project steps after it.
pub fn colmap_progress(ui: &mut egui::Ui, progress: Option<&Progress>) {
    let (fraction, text) = match progress {
        Some(p) => {
            let fraction = p.step as f32 / p.total.max(1) as f32;
            let text = match p.phase {
                "features" => format!("COLMAP: features of photo {}/{}", p.step, p.total),
                "matching" => format!("COLMAP: matching {}/{}", p.step, p.total),
                "mapping" => format!(
                    "COLMAP: mapping, {} of {} photos registered",
                    p.step, p.total
                ),
                "writing" => "writing the dataset".to_string(),
                "segment" => format!("segmenting photo {}/{}", p.step, p.total),
                "project" => "making the twin project".to_string(),
                _ => "adding the survey to the project".to_string(),
            };
            (fraction, text)
        }
        None => (0.0, "starting COLMAP…".to_string()),
    };
    ui.add(
        egui::ProgressBar::new(fraction)
            .text(text)
            .desired_width(320.0),
    );
}
