//! `damage-twin synth`: generates the procedural damaged building and its surveys into a
//! folder, with a progress bar. Argument parsing and reporting only; the work is `synth::generate`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use damage_twin::damage::DamageClass;
use damage_twin::synth::{self, Survey2Frame, SynthParams};
use indicatif::{ProgressBar, ProgressStyle};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output folder (survey-1/ and survey-2/ are written in it).
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    #[arg(long, default_value_t = 960)]
    pub width: u32,
    #[arg(long, default_value_t = 540)]
    pub height: u32,
    /// What to generate: `building` (the RC frame) or `bridge` (a multi-span girder bridge).
    #[arg(long, value_enum, default_value_t = StructureArg::Building)]
    pub structure: StructureArg,
    /// Spans of the bridge (`--structure bridge` only; 20 m each).
    #[arg(long)]
    pub spans: Option<u32>,
    /// Views of survey 1 (default: 60 for the building, 360 for the bridge).
    #[arg(long)]
    pub views: Option<usize>,
    /// Views of survey 2 (default: 12 for the building, 120 for the bridge).
    #[arg(long)]
    pub views_survey2: Option<usize>,
    /// Number of surveys (1 or 2).
    #[arg(long, default_value_t = 2)]
    pub surveys: u32,
    /// Fraction of views whose masks get random added and removed blobs (truth/ stays clean).
    #[arg(long, default_value_t = 0.0)]
    pub mask_noise: f32,
    /// Textureless variant: every component a flat colour.
    #[arg(long)]
    pub component_colours: bool,
    #[arg(long, default_value_t = 3)]
    pub floors: u32,
    #[arg(long, default_value_t = 4)]
    pub bays_x: u32,
    #[arg(long, default_value_t = 2)]
    pub bays_y: u32,
    /// Frame of survey 2's COLMAP model: `same` (survey 1's world frame) or `joint` (one model
    /// of the old and new images in a random similarity frame, as a user's COLMAP run gives).
    #[arg(long, default_value_t = Survey2Frame::Same)]
    pub survey2_frame: Survey2Frame,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum StructureArg {
    Building,
    Bridge,
}

/// The bridge's default span count.
const DEFAULT_SPANS: u32 = 6;

pub fn run(args: Args) -> anyhow::Result<()> {
    let base = match args.structure {
        StructureArg::Building => {
            if args.spans.is_some() {
                anyhow::bail!("--spans applies to --structure bridge only");
            }
            SynthParams::demo(&args.out)
        }
        StructureArg::Bridge => SynthParams::bridge(&args.out, args.spans.unwrap_or(DEFAULT_SPANS)),
    };
    let params = SynthParams {
        seed: args.seed,
        width: args.width,
        height: args.height,
        views: args.views.unwrap_or(base.views),
        views_survey2: args.views_survey2.unwrap_or(base.views_survey2),
        surveys: args.surveys,
        mask_noise: args.mask_noise,
        component_colours: args.component_colours,
        floors: args.floors,
        bays_x: args.bays_x,
        bays_y: args.bays_y,
        survey2_frame: args.survey2_frame,
        ..base
    };
    let start = Instant::now();
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} views, {elapsed} (ETA {eta})")
            .context("progress bar template")?
            .progress_chars("=> "),
    );
    bar.set_message("rendering");
    let output = synth::generate(&params, &|done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })
    .with_context(|| {
        format!(
            "generating the synthetic surveys into {}",
            args.out.display()
        )
    })?;
    bar.finish_and_clear();
    for s in &output.surveys {
        let q = &s.quantities;
        let classes: Vec<String> = DamageClass::ALL
            .iter()
            .map(|c| format!("{} in {}", c.id(), s.views_with_class[c.channel()]))
            .collect();
        println!(
            "{}: {} views, {} sparse points; damage visible: {}{}",
            s.dir.display(),
            s.views,
            s.points,
            classes.join(", "),
            if s.corrupted_views > 0 {
                format!("; {} views with corrupted masks", s.corrupted_views)
            } else {
                String::new()
            }
        );
        println!(
            "  true damage: cracks {:.2} m ({}), spalling {:.3} m² ({}), exposed rebar {:.2} m ({}); \
             {} regions new",
            q.crack_length_m,
            q.cracks,
            q.spalling_area_m2,
            q.spalls,
            q.rebar_length_m,
            q.rebar,
            q.new_regions
        );
    }
    println!("done in {:.1} s", start.elapsed().as_secs_f64());
    Ok(())
}
