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
