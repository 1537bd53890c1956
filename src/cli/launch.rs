//! The one place the CLI reaches the desktop app, which only builds with the `app` feature (the
//! default). A headless build (`--no-default-features`) says so instead of opening a window.

#[cfg(feature = "app")]
pub fn demo_window() -> anyhow::Result<()> {
    damage_twin::app::run(damage_twin::app::Launch::Demo)
}

#[cfg(not(feature = "app"))]
pub fn demo_window() -> anyhow::Result<()> {
    anyhow::bail!(
        "this damage-twin was built without the app (--no-default-features): run a subcommand \
         instead, for example `damage-twin demo --headless` (`damage-twin help` lists them)"
    )
}

/// `damage-twin open PATH`: the app on a dataset, a twin project or a PLY model.
#[derive(clap::Args, Debug)]
pub struct OpenArgs {
    /// A dataset folder, a twin project (its folder or `twin.ron`) or a `.ply` model.
    pub path: std::path::PathBuf,
    /// Start training once it is open.
    #[arg(long)]
    pub train: bool,
}

#[cfg(feature = "app")]
pub fn open_window(args: OpenArgs) -> anyhow::Result<()> {
    if !args.path.exists() {
        anyhow::bail!("{}: no such file or folder", args.path.display());
    }
    damage_twin::app::run(damage_twin::app::Launch::Open {
        path: args.path,
        train: args.train,
    })
}

#[cfg(not(feature = "app"))]
pub fn open_window(_args: OpenArgs) -> anyhow::Result<()> {
    demo_window()
}
