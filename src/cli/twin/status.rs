//! `damage-twin twin status DIR [--json]`: the project's surveys in date order, each with its
//! dataset and model (paths relative to DIR), Gaussians, damage Gaussians per class and those
//! first seen in that survey, and for a survey registered by COLMAP the registration's residual.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::Serialize;

use damage_twin::damage::DamageClass;
use damage_twin::splats::model::sigmoid;
use damage_twin::timeline::register_survey::SurveyRegistration;

#[derive(clap::Args, Debug)]
pub struct Args {
    pub dir: PathBuf,
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct SurveyStatus {
    name: String,
    date: String,
    dataset: PathBuf,
    model: Option<PathBuf>,
    model_bytes: Option<u64>,
    gaussians: Option<usize>,
    /// Damage Gaussians (label probability above one half) per class.
    damage: BTreeMap<String, usize>,
    /// Of those, first seen in this survey.
    new_damage: BTreeMap<String, usize>,
    aligned: bool,
    changes: Option<PathBuf>,
    /// How the survey was registered by COLMAP into an earlier one's model (`--align colmap`).
    registration: Option<SurveyRegistration>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let twin = super::open(&args.dir)?;
    let mut surveys = Vec::new();
    for (index, survey) in twin.project.surveys.iter().enumerate() {
        let splats = twin.load_model(&survey.name)?;
        let mut damage = BTreeMap::new();
        let mut new_damage = BTreeMap::new();
        if let Some(s) = &splats {
            for class in DamageClass::ALL {
                if s.label_channels <= class.channel() {
                    continue;
                }
                let is_damage: Vec<usize> = (0..s.len())
                    .filter(|&g| sigmoid(s.labels_of(g)[class.channel()]) > 0.5)
                    .collect();
                let new = is_damage
                    .iter()
                    .filter(|&&g| usize::from(s.meta.damage_survey[g]) == index)
                    .count();
                damage.insert(class.id().to_string(), is_damage.len());
                new_damage.insert(class.id().to_string(), new);
            }
        }
        let model_bytes = twin
            .model_path(&survey.name)?
            .and_then(|p| std::fs::metadata(p).ok())
            .map(|m| m.len());
        surveys.push(SurveyStatus {
            name: survey.name.clone(),
            date: survey.date.clone(),
            dataset: survey.dataset.clone(),
            model: survey.model.clone(),
            model_bytes,
            gaussians: splats.as_ref().map(|s| s.len()),
            damage,
            new_damage,
            aligned: survey.alignment.is_some(),
            changes: survey.changes.clone(),
            registration: twin.load_registration(&survey.name)?,
        });
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({ "surveys": surveys }))?
        );
        return Ok(());
    }
    println!("{}", twin.file().display());
    for s in &surveys {
        println!(
            "  {} {:<12} {} Gaussians  damage {:?}  new {:?}  model {}",
            s.date,
            s.name,
            s.gaussians.map_or("-".into(), |n| n.to_string()),
            s.damage,
            s.new_damage,
            s.model
                .as_ref()
                .map_or("-".into(), |p| p.display().to_string())
        );
        if let Some(record) = &s.registration {
            println!("    {}", record.describe());
        }
    }
    Ok(())
}
