//! `damage-twin twin set-scale DIR --from X,Y,Z --to X,Y,Z --metres D` (or
//! `--metres-per-unit K`): the project's scale, from a known distance between two model points.

use std::path::PathBuf;

use anyhow::bail;
use glam::DVec3;

use damage_twin::scene::project::check_metres_per_unit;

use crate::cli::args::LockArgs;

#[derive(clap::Args, Debug)]
pub struct Args {
    pub dir: PathBuf,
    /// One end of the known distance, in model coordinates.
    #[arg(long, value_parser = parse_point, requires_all = ["to", "metres"])]
    pub from: Option<DVec3>,
    #[arg(long, value_parser = parse_point)]
    pub to: Option<DVec3>,
    /// The distance between them in metres.
    #[arg(long)]
    pub metres: Option<f64>,
    /// Or the scale itself.
    #[arg(long, conflicts_with = "from")]
    pub metres_per_unit: Option<f64>,
    #[command(flatten)]
    pub lock: LockArgs,
}

fn parse_point(text: &str) -> Result<DVec3, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{text:?}: {e}"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(DVec3::new(x, y, z)),
        _ => Err(format!("{text:?}: expected three finite numbers X,Y,Z")),
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let scale = match (args.from, args.to, args.metres, args.metres_per_unit) {
        (_, _, _, Some(k)) => k,
        (Some(a), Some(b), Some(d), None) => {
            let units = a.distance(b);
            if !(units > 0.0) {
                bail!("--from and --to are the same point: no distance to scale by");
            }
            d / units
        }
        _ => bail!("give --from, --to and --metres, or --metres-per-unit"),
    };
    // The check `twin.ron`'s `settings.metres_per_unit` is held to when it loads.
    let given = if args.metres_per_unit.is_some() {
        "--metres-per-unit"
    } else {
        "--metres over the --from/--to distance"
    };
    check_metres_per_unit(scale).map_err(|why| anyhow::anyhow!("{given}: {why}"))?;
    let mut twin = super::open_to_write(&args.dir, &args.lock, "twin set-scale")?;
    twin.commit(|twin| {
        twin.project.settings.metres_per_unit = Some(scale);
        Ok(())
    })?;
    println!("{}: {scale} metres per model unit", twin.file().display());
    Ok(())
}
