//! `damage-twin twin …`: the survey timeline of a twin project (`timeline`): create it, add
//! surveys, detect changes, update the twin, show its state. One file per subcommand; the work
//! is the library's.

mod add_survey;
mod detect;
mod new;
mod set_scale;
mod status;
mod update;
mod update_blocks;

#[derive(clap::Subcommand, Debug)]
pub enum Twin {
    /// Create a twin project from a first survey (trains its model unless one is given).
    New(new::Args),
    /// Add a later survey, placed in the twin's frame (same-frame or through a joint COLMAP
    /// model).
    AddSurvey(add_survey::Args),
    /// Find new damage: the twin rendered at a survey's poses against the survey's masks.
    Detect(detect::Args),
    /// Update the twin with a survey: its damage refined with its photos, the rest frozen.
    Update(update::Args),
    /// The project's surveys, models and damage.
    Status(status::Args),
    /// The project's scale: metres per model unit, from a known distance.
    SetScale(set_scale::Args),
}

pub fn run(command: Twin) -> anyhow::Result<()> {
    match command {
        Twin::New(args) => new::run(args),
        Twin::AddSurvey(args) => add_survey::run(args),
        Twin::Detect(args) => detect::run(args),
        Twin::Update(args) => update::run(args),
        Twin::Status(args) => status::run(args),
        Twin::SetScale(args) => set_scale::run(args),
    }
}

/// Opens a project folder for the CLI, saying what it cleaned up after a killed command.
pub(crate) fn open(dir: &std::path::Path) -> anyhow::Result<damage_twin::timeline::Twin> {
    use anyhow::Context;
    let twin = damage_twin::timeline::Twin::open(dir)
        .with_context(|| format!("opening the twin project {}", dir.display()))?;
    if !twin.recovered().is_empty() {
        eprintln!(
            "{}",
            damage_twin::timeline::twin::cleanup_message(twin.dir(), twin.recovered())
        );
    }
    Ok(twin)
}

/// Opens a project folder for a command that writes it, named `command` to other writers.
pub(crate) fn open_to_write(
    dir: &std::path::Path,
    lock: &crate::cli::args::LockArgs,
    command: &str,
) -> anyhow::Result<damage_twin::timeline::Twin> {
    Ok(open(dir)?.with_writer(lock.writer(command)))
}
