//! `damage-twin masks import|export`: damage masks from COCO JSON, LabelMe JSON or class PNGs
//! into a dataset's `masks/<class>/`, and a twin's rendered masks out as COCO JSON for an
//! annotation tool. Parsing and printing only: the formats are `scene::mask_import`, the
//! rendering `damage::display::rendered_masks`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use glam::Vec3;

use damage_twin::damage::Palette;
use damage_twin::damage::display::rendered_masks;
use damage_twin::damage::evaluate::DamageReadout;
use damage_twin::scene::mask_import::coco::{ExportImage, read_coco, write_coco};
use damage_twin::scene::mask_import::destination::write_annotations;
use damage_twin::scene::mask_import::labelme::read_labelme_files;
use damage_twin::scene::mask_import::png_classes::read_png_folder;
use damage_twin::scene::mask_import::{ClassMapping, UnknownCategories, parse_colour, parse_pair};
use damage_twin::scene::{DamageClass, ImageScale};

use super::args::{open_dataset, parse_background, read_model};

#[derive(clap::Subcommand, Debug)]
pub enum Masks {
    /// Write a dataset's masks/<class>/<image>.png from COCO JSON, LabelMe JSON or class PNGs.
    Import(ImportArgs),
    /// A twin's damage rendered at every view of a dataset, as one COCO JSON (RLE per image and
    /// class) to correct in an annotation tool and import again.
    Export(ExportArgs),
}

#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["coco", "labelme", "png_dir"])))]
pub struct ImportArgs {
    /// The dataset whose views the masks belong to (they are written to its masks/).
    pub dataset: PathBuf,
    /// A COCO instance JSON (polygons, RLE lists or compact RLE strings).
    #[arg(long)]
    pub coco: Option<PathBuf>,
    /// LabelMe JSON files, one per image (or folders of them).
    #[arg(long, num_args = 1..)]
    pub labelme: Vec<PathBuf>,
    /// A folder of class PNGs named by image: grey class-index PNGs or colour / palette PNGs.
    #[arg(long)]
    pub png_dir: Option<PathBuf>,
    /// Category or label NAME=CLASS (crack, spalling, rebar), repeatable; replaces the default
    /// (each class's own name).
    #[arg(long = "class", value_name = "NAME=CLASS")]
    pub classes: Vec<String>,
    /// Grey PNG value N=CLASS, repeatable; replaces the default (1 crack, 2 spalling, 3 rebar).
    #[arg(long = "value", value_name = "N=CLASS")]
    pub values: Vec<String>,
    /// Colour RRGGBB=CLASS, repeatable; replaces the default (the dataset's class colours).
    #[arg(long = "colour", value_name = "RRGGBB=CLASS")]
    pub colours: Vec<String>,
    /// Skip annotations, values and colours that map to no class (counted in a warning) instead
    /// of refusing the file.
    #[arg(long)]
    pub skip_unknown: bool,
    /// Print what arrived as one JSON object.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// The twin's model (label mode, or overlay colours read back).
    pub model: PathBuf,
    /// The dataset whose views are rendered, at their images' stored size.
    pub dataset: PathBuf,
    /// The COCO JSON file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Background of the render the masks are read from: white, black or r,g,b.
    #[arg(long, default_value = "black", value_parser = parse_background)]
    pub background: Vec3,
}

pub fn run(command: Masks) -> anyhow::Result<()> {
    match command {
        Masks::Import(args) => import(args),
        Masks::Export(args) => export(args),
    }
}

/// The mapping the flags describe; each flag kind given replaces that kind's default.
fn mapping(args: &ImportArgs) -> anyhow::Result<ClassMapping> {
    let mut mapping = ClassMapping::default();
    if !args.classes.is_empty() {
        mapping.names = BTreeMap::new();
        for text in &args.classes {
            let (name, class) = parse_pair(text).map_err(|m| anyhow::anyhow!("--class {m}"))?;
            mapping.names.insert(name.to_string(), class);
        }
    }
    if !args.values.is_empty() {
        mapping.values = BTreeMap::new();
        for text in &args.values {
            let (value, class) = parse_pair(text).map_err(|m| anyhow::anyhow!("--value {m}"))?;
            let value: u16 = value
                .parse()
                .with_context(|| format!("--value {text:?}: {value:?} is not 0 to 65535"))?;
            mapping.values.insert(value, class);
        }
    }
    if !args.colours.is_empty() {
        mapping.colours = BTreeMap::new();
        for text in &args.colours {
            let (colour, class) = parse_pair(text).map_err(|m| anyhow::anyhow!("--colour {m}"))?;
            let colour = parse_colour(colour).map_err(|m| anyhow::anyhow!("--colour {m}"))?;
            mapping.colours.insert(colour, class);
        }
    }
    if args.skip_unknown {
        mapping.unknown = UnknownCategories::Skip;
    }
    Ok(mapping)
}

/// The LabelMe files named: files as given, folders as their `.json` files (sorted).
fn labelme_files(paths: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for path in paths {
        if path.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(path)
                .with_context(|| format!("listing {}", path.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.extension()
                        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
                })
                .collect();
            if found.is_empty() {
                bail!("{}: holds no LabelMe .json file", path.display());
            }
            found.sort();
            out.extend(found);
        } else {
            out.push(path.clone());
        }
    }
    Ok(out)
}

fn import(args: ImportArgs) -> anyhow::Result<()> {
    let mapping = mapping(&args)?;
    let dataset = open_dataset(&args.dataset, Vec3::ZERO)?;
    let annotations = if let Some(coco) = &args.coco {
        read_coco(coco, &mapping)?
    } else if let Some(dir) = &args.png_dir {
        read_png_folder(dir, &mapping)?
    } else {
        read_labelme_files(&labelme_files(&args.labelme)?, &mapping)?
    };
    let masks_dir = dataset.root.join("masks");
    let summary = write_annotations(&dataset, &annotations, &masks_dir)?;
    for warning in summary.warnings() {
        eprintln!("warning: {warning}");
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
        return Ok(());
    }
    println!(
        "wrote the masks of {} images to {}",
        summary.images,
        masks_dir.display()
    );
    for (class, arrival) in &summary.classes {
        println!(
            "  {:<9} {} files ({} with damage, {} pixels)",
            class.id(),
            arrival.files,
            arrival.with_damage,
            arrival.pixels
        );
    }
    Ok(())
}

/// The name an annotation tool knows a view's image by: its path under `images/` when it is
/// there, else its file name.
fn tool_file_name(dataset_root: &Path, image: &Path) -> String {
    image
        .strip_prefix(dataset_root.join("images"))
        .ok()
        .or_else(|| image.file_name().map(Path::new))
        .unwrap_or(image)
        .to_string_lossy()
        .replace('\\', "/")
}

fn export(args: ExportArgs) -> anyhow::Result<()> {
    let splats = read_model(&args.model)?;
    let dataset = open_dataset(&args.dataset, args.background)?;
    let readout = DamageReadout::for_model(&splats, Palette::default());
    let mut images = Vec::with_capacity(dataset.views.len());
    let mut damage: BTreeMap<DamageClass, usize> = BTreeMap::new();
    for (index, view) in dataset.views.iter().enumerate() {
        if view.distortion.is_some() {
            eprintln!(
                "warning: view {} has lens distortion: its mask is drawn on the undistorted \
                 image, not on {}",
                view.name,
                view.image_path.display()
            );
        }
        let camera = dataset.view_camera(index, ImageScale::Factor(1))?;
        let masks = rendered_masks(&splats, &camera, &readout, args.background);
        let masks: BTreeMap<DamageClass, _> = DamageClass::ALL.into_iter().zip(masks).collect();
        for (&class, mask) in &masks {
            *damage.entry(class).or_insert(0) += usize::from(mask.count() > 0);
        }
        images.push(ExportImage {
            file_name: tool_file_name(&dataset.root, &view.image_path),
            width: camera.intrinsics.width,
            height: camera.intrinsics.height,
            masks,
        });
    }
    write_coco(&args.out, &images)?;
    let per_class: Vec<String> = damage
        .iter()
        .map(|(class, n)| format!("{class} in {n}"))
        .collect();
    println!(
        "wrote {} ({} views, {} mode; damage: {})",
        args.out.display(),
        images.len(),
        readout.mode,
        per_class.join(", ")
    );
    Ok(())
}
