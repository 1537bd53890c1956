//! `damage-twin report DIR --out R`: the twin project's damage measured per survey (regions,
//! lengths, widths, areas, growth, new regions) as `R/report.json` and a self-contained
//! `R/report.html` with renders of the twin.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;

use damage_twin::damage::display::{DisplayStyle, png_bytes, render_view};
use damage_twin::damage::layer::{EARLIER_DAMAGE, display_by_survey};
use damage_twin::damage::measure::MeasureConfig;
use damage_twin::report::georeference::ReportGeoreference;
use damage_twin::report::inspection::{
    Figure, InspectionReport, ReportSettings, TruthTotals, report_html,
};
use damage_twin::report::project_runs::project_runs;
use damage_twin::report::tradeoff_chart::tradeoff_svg;
use damage_twin::report::training_chart::training_svg;
use damage_twin::scene::atomic::write_atomic;
use damage_twin::scene::files::{is_present, read_regular};
use damage_twin::scene::limits::MAX_PROJECT_JSON_BYTES;
use damage_twin::scene::run_folder::remove_dead_temp_files;
use damage_twin::timeline::quantities::survey_quantities;
use damage_twin::timeline::twin::{HISTORY_FILE, today};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The twin project folder.
    pub dir: PathBuf,
    /// Folder for report.html and report.json (created).
    #[arg(long)]
    pub out: PathBuf,
    /// Renders per survey, from its photos' poses spread over the survey.
    #[arg(long, default_value_t = 4)]
    pub views: usize,
    /// Renders are this many times smaller than the photos (1 to 64).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=MAX_DOWNSCALE))]
    pub downscale: u32,
}

/// Largest `--downscale`: a 32 768-pixel photo (`scene::limits::MAX_IMAGE_SIDE`) still renders
/// 512 pixels wide. Checked when the arguments are parsed, before anything is measured (1000
/// measured every survey and then failed on a render of zero width).
const MAX_DOWNSCALE: i64 = 64;

fn colour_name(colour: [u8; 3]) -> String {
    match colour {
        [0, 255, 0] => "green".to_string(),
        [r, g, b] => format!("#{r:02x}{g:02x}{b:02x}"),
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let twin = super::twin::open(&args.dir)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    // A report killed while writing left its temporary files here. (The folder is not replaced
    // whole as a run folder is: it may be any folder of the user's, the project's own included.)
    for left in remove_dead_temp_files(&args.out, 0) {
        eprintln!(
            "{}: removed, left by a report that was killed",
            left.display()
        );
    }
    let metres = twin.project.settings.metres_per_unit;
    let config = MeasureConfig::for_scale(metres.unwrap_or(1.0));
    let surveys = survey_quantities(&twin)?;

    // Earlier surveys' damage blue, the latest survey's in the project's new-damage colour.
    let latest_colour = twin.project.settings.new_damage_colour;
    let latest = twin
        .project
        .surveys
        .last()
        .map(|s| s.name.clone())
        .unwrap_or_default();
    let mut survey_colours = vec![EARLIER_DAMAGE; twin.project.surveys.len().saturating_sub(1)];
    survey_colours.push(latest_colour);
    let mut truth = BTreeMap::new();
    let mut figures = Vec::new();
    for s in &surveys {
        let own_survey = twin.survey_index(&s.survey)?;
        let dataset = twin.open_survey_dataset(&s.survey)?;
        let truth_file = dataset.root.join("truth").join("quantities.json");
        if is_present(&truth_file) {
            let bytes = read_regular(&truth_file, MAX_PROJECT_JSON_BYTES)?;
            let totals = TruthTotals::from_quantities_json(&bytes)
                .with_context(|| format!("{}: not a quantities file", truth_file.display()))?;
            truth.insert(s.survey.clone(), totals);
        }
        let Some(splats) = twin.load_model(&s.survey)? else {
            continue;
        };
        let mut style = DisplayStyle {
            background: twin.project.settings.background.into(),
            ..DisplayStyle::default()
        };
        style.damage.enabled = true;
        let by_survey = display_by_survey(&splats, &survey_colours, own_survey as u16);
        let mut plain = style.clone();
        plain.damage.enabled = false;
        let count = args.views.min(dataset.views.len());
        for k in 0..count {
            let view = &dataset.views[k * dataset.views.len() / count];
            let camera = &view.camera;
            let d = args.downscale.max(1);
            // A photo smaller than the downscale still renders one pixel.
            let camera = camera.resized(
                (camera.intrinsics.width / d).max(1),
                (camera.intrinsics.height / d).max(1),
            );
            let png =
                png_bytes(&render_view(&splats, &camera, &style)).context("encoding a render")?;
            figures.push(Figure::png(
                format!("survey {}, from {}: by class", s.survey, view.name),
                png,
            ));
            // Damage by survey for half the views (earlier surveys blue, the latest its colour).
            if k % 2 == 0 {
                let png = png_bytes(&render_view(&by_survey, &camera, &plain))
                    .context("encoding a render")?;
                figures.push(Figure::png(
                    format!(
                        "survey {}, from {}: by survey (blue earlier, {} {latest})",
                        s.survey,
                        view.name,
                        colour_name(latest_colour),
                    ),
                    png,
                ));
            }
        }
        eprintln!(
            "survey {}: {} regions on {} planes in {:.1} s; crack {:.2}, spalling {:.2}, rebar {:.2}",
            s.survey,
            s.regions.len(),
            s.planes.len(),
            s.seconds,
            s.totals.crack_length_m,
            s.totals.spalling_area_m2,
            s.totals.rebar_length_m
        );
    }

    // What made each survey's model, and how its training went.
    let mut runs = Vec::new();
    let mut charts = Vec::new();
    for survey in &twin.project.surveys {
        if let Some(metrics) = twin.load_metrics(&survey.name)? {
            runs.extend(project_runs(&survey.name, &metrics));
        }
        if let Some(history) = twin.load_history(&survey.name)? {
            let name = twin.survey_file(&survey.name, HISTORY_FILE)?;
            charts.push(Figure::svg(
                format!(
                    "survey {}: training (loss, held-out PSNR, Gaussians)",
                    survey.name
                ),
                training_svg(&name, &history)?,
            ));
        }
    }
    if !runs.is_empty() {
        let points: Vec<_> = runs.iter().map(|r| r.point()).collect();
        charts.push(Figure::svg(
            "held-out IoU and PSNR against wall time, per step".to_string(),
            tradeoff_svg(&args.out.join("report.html"), &points)?,
        ));
    }

    let settings = ReportSettings {
        metres_per_unit: metres.unwrap_or(1.0),
        scale_known: metres.is_some(),
        label_threshold: config.threshold,
        map_cell_m: config.cell * metres.unwrap_or(1.0),
        region_gap_m: config.gap * metres.unwrap_or(1.0),
        plane_slab_m: config.slab * metres.unwrap_or(1.0),
    };
    let report = InspectionReport::new(
        args.dir.display().to_string(),
        today(),
        settings,
        surveys,
        truth,
        runs,
    );
    let mut registrations = BTreeMap::new();
    for survey in &twin.project.surveys {
        if let Some(record) = twin.load_registration(&survey.name)? {
            registrations.insert(survey.name.clone(), record);
        }
    }
    let report = report.with_placement(
        twin.georeference()?.as_ref().map(ReportGeoreference::of),
        registrations,
    );
    let json = serde_json::to_string_pretty(&report)?;
    let json_path = args.out.join("report.json");
    write_atomic(&json_path, |w| {
        std::io::Write::write_all(w, json.as_bytes())
    })?;
    let html_path = args.out.join("report.html");
    let html = report_html(&report, &figures, &charts);
    write_atomic(&html_path, |w| {
        std::io::Write::write_all(w, html.as_bytes())
    })?;
    println!("wrote {} and {}", html_path.display(), json_path.display());
    Ok(())
}
