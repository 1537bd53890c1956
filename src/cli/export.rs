//! `damage-twin export MODEL.ply --out FILE [--format ply|spz]`: writes a model for other
//! viewers, as SPZ (Niantic's compressed format, `splats::spz`) or as our 3DGS PLY, and prints
//! its size per Gaussian beside the size of the same model as PLY. Soft-deleted Gaussians are
//! left out (no other viewer knows the state bit). SPZ has no place for damage label channels:
//! `--damage-colours` bakes the class colours into the Gaussians' colours instead.

use std::path::{Path, PathBuf};

use anyhow::Context;

use damage_twin::damage::bake::bake_damage_colours;
use damage_twin::splats::model::state::DELETED;
use damage_twin::splats::ply::{splats_file_bytes, write_splats};
use damage_twin::splats::spz::{SpzOptions, SpzVersion, write_spz};

use super::args::read_model;

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Ply,
    Spz,
}

impl Format {
    fn name(self) -> &'static str {
        match self {
            Format::Ply => "PLY",
            Format::Spz => "SPZ",
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The model (a PLY, e.g. a `train` run's model.ply).
    pub model: PathBuf,
    /// The file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Output format; by default the --out extension's (.ply or .spz), else spz.
    #[arg(long, value_enum)]
    pub format: Option<Format>,
    /// SPZ version: 3 (smallest-three rotations, the reference's default) or 2 (for readers
    /// that know only version 2; rotations less exact).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(2..=3))]
    pub spz_version: u32,
    /// SPZ: bits kept of each SH byte, degree 1 then degrees 2-3 (1 to 8). The reference keeps
    /// 5,4, which rounds most higher-degree coefficients of a trained model to zero (33-35 dB
    /// against the PLY's render on fox); one bit more gives 41 dB for 20 % more bytes, in a
    /// file every reader decodes the same way (docs/ENGINE.md).
    #[arg(long, default_value = "6,5", value_parser = parse_sh_bits)]
    pub sh_bits: [u8; 2],
    /// Paint each Gaussian whose damage label probability is at least 0.5 in its class colour
    /// (the damage layer's colours; view-dependent colour dropped), so damage shows in viewers
    /// that cannot read label channels.
    #[arg(long)]
    pub damage_colours: bool,
}

/// Refuses an `--out` that is the model itself (the same file, by any path or link): the export
/// would replace the user's PLY, damage channels and all, and nothing reads SPZ back.
fn refuse_overwriting_the_model(args: &Args) -> anyhow::Result<()> {
    let same = match (args.model.canonicalize(), args.out.canonicalize()) {
        (Ok(model), Ok(out)) => model == out,
        _ => false,
    };
    if same {
        anyhow::bail!(
            "--out {} is the model being exported ({}): writing it would replace the input;              choose another file",
            args.out.display(),
            args.model.display()
        );
    }
    Ok(())
}

pub fn run(args: Args) -> anyhow::Result<()> {
    refuse_overwriting_the_model(&args)?;
    let format = output_format(&args);
    let mut splats = read_model(&args.model)?;
    let keep: Vec<bool> = splats
        .meta
        .state
        .iter()
        .map(|&b| b & DELETED == 0)
        .collect();
    let deleted = keep.iter().filter(|&&k| !k).count();
    if deleted > 0 {
        splats.retain(&keep);
        println!("left out {deleted} soft-deleted Gaussians");
    }
    if args.damage_colours {
        if splats.label_channels == 0 {
            eprintln!(
                "warning: {} has no damage label channels: --damage-colours changes nothing",
                args.model.display()
            );
        } else {
            splats = bake_damage_colours(&splats);
        }
    }
    let (bytes, detail) = match format {
        Format::Spz => {
            let version = if args.spz_version == 2 {
                SpzVersion::V2
            } else {
                SpzVersion::V3
            };
            let options = SpzOptions {
                version,
                sh_bits: args.sh_bits,
            };
            let (header, bytes) = write_spz(&args.out, &splats, &options)?;
            let mut detail = format!(
                "SPZ v{}, positions to 1/{} unit",
                version.number(),
                1u32 << header.fractional_bits
            );
            if header.sh_degree > 0 {
                let [d1, rest] = args.sh_bits;
                detail.push_str(&format!(", SH at {d1},{rest} bits"));
            }
            (bytes, detail)
        }
        Format::Ply => {
            write_splats(&args.out, &splats)?;
            let bytes = std::fs::metadata(&args.out)
                .with_context(|| format!("{}", args.out.display()))?
                .len();
            (bytes, "PLY".to_string())
        }
    };
    let n = splats.len();
    println!(
        "wrote {} ({detail}): {n} Gaussians, SH degree {}",
        args.out.display(),
        splats.sh_degree
    );
    if format == Format::Ply {
        println!("{bytes} bytes, {} per Gaussian", per_gaussian(bytes, n));
    } else {
        let ply = splats_file_bytes(&splats);
        println!(
            "{bytes} bytes, {} per Gaussian; as PLY {ply} bytes, {} per Gaussian (from the PLY \
             layout); {:.2}x smaller than PLY",
            per_gaussian(bytes, n),
            per_gaussian(ply, n),
            ply as f64 / bytes.max(1) as f64
        );
    }
    if format == Format::Spz && splats.label_channels > 0 {
        let baked = if args.damage_colours {
            "their classes are baked into the colours"
        } else {
            "--damage-colours bakes the classes into the colours"
        };
        println!(
            "note: SPZ cannot carry the model's {} damage label channels: {baked}; --format ply \
             keeps them",
            splats.label_channels
        );
    }
    Ok(())
}

/// `--format`, else the `--out` extension, else SPZ; warns when the two disagree.
fn output_format(args: &Args) -> Format {
    let by_extension = match extension(&args.out).as_deref() {
        Some("ply") => Some(Format::Ply),
        Some("spz") => Some(Format::Spz),
        _ => None,
    };
    if let (Some(chosen), Some(implied)) = (args.format, by_extension)
        && chosen != implied
    {
        eprintln!(
            "warning: writing {} to {}, whose extension says {}",
            chosen.name(),
            args.out.display(),
            implied.name()
        );
    }
    args.format.or(by_extension).unwrap_or(Format::Spz)
}

fn parse_sh_bits(text: &str) -> Result<[u8; 2], String> {
    let bad = || format!("bad SH bits {text:?}: use two numbers from 1 to 8, e.g. 5,4");
    let bits: Vec<u8> = text
        .split(',')
        .map(|v| v.trim().parse::<u8>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad())?;
    match bits[..] {
        [d1, rest] if (1..=8).contains(&d1) && (1..=8).contains(&rest) => Ok([d1, rest]),
        _ => Err(bad()),
    }
}

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}

fn per_gaussian(bytes: u64, n: usize) -> String {
    if n == 0 {
        return "n/a".into();
    }
    format!("{:.1}", bytes as f64 / n as f64)
}
