//! `masks import` and `masks export` (`scene::mask_import`): COCO polygons, uncompressed and
//! compressed RLE, LabelMe and palette / class-index PNGs all arrive as the same masks; the
//! twin's rendered masks exported as COCO come back identical; hostile annotation files are
//! refused in one line naming the file. The COCO references were computed once with pycocotools
//! 2.0.11 (`mask.frPyObjects` + `merge` + `decode` for the polygon, `mask.encode` for the string).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use damage_twin::scene::mask_import::coco::read_coco;
use damage_twin::scene::mask_import::destination::write_annotations;
use damage_twin::scene::mask_import::labelme::read_labelme_files;
use damage_twin::scene::mask_import::png_classes::read_png_folder;
use damage_twin::scene::mask_import::{ClassMapping, UnknownCategories};
use damage_twin::scene::open::OpenOptions;
use damage_twin::scene::{DamageClass, Dataset, Mask, MaskFolder, MaskSource};

const W: u32 = 16;
const H: u32 = 12;

/// The polygon below as pycocotools draws it on a 16 × 12 image (`#` set).
const POLYGON_ART: [&str; 12] = [
    "................",
    "................",
    ".....#######....",
    ".....#######....",
    ".....######.....",
    ".....######.....",
    ".....#####......",
    ".....#####......",
    "......###.......",
    "......###.......",
    ".......#........",
    ".......#........",
];
const POLYGON: [f64; 10] = [7.3, 11.9, 4.6, 5.8, 4.7, 2.0, 10.9, 1.9, 12.7, 1.6];
/// pycocotools' compact string and uncompressed counts of `POLYGON_ART`.
const POLYGON_RLE_STRING: &str = "n1662N2NN2N2N2N`1";
const POLYGON_RLE_COUNTS: &str = "[62, 6, 6, 8, 4, 10, 2, 8, 4, 6, 6, 4, 8, 2, 56]";

fn art_mask(art: &[&str]) -> Mask {
    let (w, h) = (art[0].len() as u32, art.len() as u32);
    Mask {
        width: w,
        height: h,
        data: art
            .iter()
            .flat_map(|row| row.bytes().map(|b| u8::from(b == b'#')))
            .collect(),
    }
}

/// A rectangle x 1..4, y 8..11 (its pixels), the second shape of the fixtures.
fn rectangle_mask() -> Mask {
    let mut mask = Mask::empty(W, H);
    for y in 8..11 {
        for x in 1..4 {
            mask.data[(y * W + x) as usize] = 1;
        }
    }
    mask
}

/// A `transforms.json` dataset of 16 × 12 photos `images/a.png` and `images/b.png`.
fn dataset() -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    std::fs::create_dir_all(root.join("images")).unwrap();
    let mut frames = Vec::new();
    for (i, name) in ["a", "b"].into_iter().enumerate() {
        image::RgbImage::from_pixel(W, H, image::Rgb([90, 90, 90]))
            .save(root.join(format!("images/{name}.png")))
            .unwrap();
        frames.push(format!(
            r#"{{"file_path":"images/{name}.png","transform_matrix":[[1,0,0,{i}],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}}"#
        ));
    }
    std::fs::write(
        root.join("transforms.json"),
        format!(
            r#"{{"fl_x":16,"w":16,"h":12,"frames":[{}]}}"#,
            frames.join(",")
        ),
    )
    .unwrap();
    tmp
}

fn open(root: &Path) -> Dataset {
    Dataset::open(root, &OpenOptions::default()).unwrap()
}

/// The masks written under `root/masks` for view `name`.
fn written(root: &Path, name: &str) -> BTreeMap<DamageClass, Mask> {
    let dataset = open(root);
    let index = dataset.view_index(name).unwrap();
    let folder = MaskFolder::new(root.join("masks"));
    folder.damage_masks(&dataset.views[index], (W, H)).unwrap()
}

/// A COCO file: image `a` with the polygon as a crack and the compact RLE as spalling, image
/// `b` (named by a Windows path, as some tools write) with the uncompressed RLE as a crack and
/// the rectangle as a polygon of category "Spall" (mapped by name).
fn coco_text(polygon: &str, crack_counts: &str, extra: &str) -> String {
    format!(
        r#"{{"images": [{{"id": 1, "file_name": "images/a.jpg", "width": 16, "height": 12}},
                        {{"id": 7, "file_name": "C:\\survey\\images\\b.png", "width": 16, "height": 12}}],
            "categories": [{{"id": 1, "name": "crack"}}, {{"id": 2, "name": "Spall"}}],
            "annotations": [
              {{"id": 1, "image_id": 1, "category_id": 1, "segmentation": [{polygon}], "iscrowd": 0}},
              {{"id": 2, "image_id": 1, "category_id": 2, "segmentation": {{"size": [12, 16], "counts": "{POLYGON_RLE_STRING}"}}, "iscrowd": 1}},
              {{"id": 3, "image_id": 7, "category_id": 1, "segmentation": {{"size": [12, 16], "counts": {crack_counts}}}, "iscrowd": 1}},
              {{"id": 4, "image_id": 7, "category_id": 2, "segmentation": [[1, 8, 4, 8, 4, 11, 1, 11]]}}
              {extra}
            ]}}"#
    )
}

fn polygon_json() -> String {
    format!("{:?}", POLYGON.to_vec())
}

fn mapping() -> ClassMapping {
    let mut mapping = ClassMapping::default();
    mapping
        .names
        .insert("spall".to_string(), DamageClass::Spalling);
    mapping
}

#[test]
fn coco_polygons_and_both_rles_arrive_as_pycocotools_draws_them() {
    let data = dataset();
    let root = data.path();
    let coco = root.join("annotations.json");
    std::fs::write(&coco, coco_text(&polygon_json(), POLYGON_RLE_COUNTS, "")).unwrap();
    let annotations = read_coco(&coco, &mapping()).unwrap();
    let summary = write_annotations(&open(root), &annotations, &root.join("masks")).unwrap();
    assert_eq!(summary.images, 2);
    assert!(summary.unmatched.is_empty() && summary.skipped.is_empty());

    let reference = art_mask(&POLYGON_ART);
    let a = written(root, "a");
    assert_eq!(a[&DamageClass::Crack], reference, "polygon vs pycocotools");
    assert_eq!(a[&DamageClass::Spalling], reference, "compact RLE string");
    // The file's categories are crack and spalling: no rebar mask is written.
    assert!(!a.contains_key(&DamageClass::Rebar));
    let b = written(root, "b");
    assert_eq!(b[&DamageClass::Crack], reference, "uncompressed RLE");
    assert_eq!(b[&DamageClass::Spalling], rectangle_mask());

    // `inspect` counts what arrived per class.
    let counts = open(root).mask_counts;
    assert_eq!(counts.get(&DamageClass::Crack), Some(&2));
    assert_eq!(counts.get(&DamageClass::Spalling), Some(&2));
    assert_eq!(counts.get(&DamageClass::Rebar), None);
    let c = summary.classes[&DamageClass::Crack].clone();
    assert_eq!((c.files, c.with_damage), (2, 2));
    assert_eq!(c.pixels, 2 * reference.count() as u64);
}

/// Writes an indexed (palette) PNG whose indices are `index` per pixel.
fn write_palette_png(path: &Path, palette: &[[u8; 3]], index: &[u8]) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut encoder = png::Encoder::new(file, W, H);
    encoder.set_color(png::ColorType::Indexed);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_palette(palette.concat());
    let mut writer = encoder.write_header().unwrap();
    writer.write_image_data(index).unwrap();
}

#[test]
fn labelme_and_palette_and_index_pngs_arrive_as_the_same_masks_as_coco() {
    let reference = art_mask(&POLYGON_ART);
    let rectangle = rectangle_mask();

    // LabelMe: the polygon as a crack, the rectangle as a rectangle shape of spalling.
    let data = dataset();
    let root = data.path();
    let points: Vec<[f64; 2]> = POLYGON.chunks(2).map(|c| [c[0], c[1]]).collect();
    let labelme = root.join("a.json");
    std::fs::write(
        &labelme,
        format!(
            r#"{{"version": "5.4.1", "imagePath": "../images/a.png", "imageData": null,
                "imageWidth": 16, "imageHeight": 12, "shapes": [
                {{"label": "crack", "points": {points:?}, "shape_type": "polygon"}},
                {{"label": "spalling", "points": [[1, 8], [4, 11]], "shape_type": "rectangle"}}]}}"#
        ),
    )
    .unwrap();
    let annotations = read_labelme_files(&[labelme], &mapping()).unwrap();
    write_annotations(&open(root), &annotations, &root.join("masks")).unwrap();
    let a = written(root, "a");
    assert_eq!(a[&DamageClass::Crack], reference);
    assert_eq!(a[&DamageClass::Spalling], rectangle);

    // A palette PNG (index 0 black, 1 a crack colour, 2 a spalling colour) with a colour table,
    // and a grey class-index PNG with the default values (1 crack, 2 spalling).
    let pngs = root.join("segmentation");
    std::fs::create_dir_all(&pngs).unwrap();
    let index: Vec<u8> = reference
        .data
        .iter()
        .zip(&rectangle.data)
        .map(|(&c, &s)| {
            if c != 0 {
                1
            } else if s != 0 {
                2
            } else {
                0
            }
        })
        .collect();
    let palette = [[0, 0, 0], [200, 30, 30], [30, 30, 200]];
    write_palette_png(&pngs.join("a.png"), &palette, &index);
    image::GrayImage::from_raw(W, H, index.clone())
        .unwrap()
        .save(pngs.join("b.png"))
        .unwrap();
    let mut table = mapping();
    table.colours = [
        ([200, 30, 30], DamageClass::Crack),
        ([30, 30, 200], DamageClass::Spalling),
    ]
    .into_iter()
    .collect();
    let annotations = read_png_folder(&pngs, &table).unwrap();
    std::fs::remove_dir_all(root.join("masks")).unwrap();
    write_annotations(&open(root), &annotations, &root.join("masks")).unwrap();
    for name in ["a", "b"] {
        let masks = written(root, name);
        assert_eq!(masks[&DamageClass::Crack], reference, "{name}");
        assert_eq!(masks[&DamageClass::Spalling], rectangle, "{name}");
    }
    // The palette PNG speaks of the colour table's classes; the grey PNG of all three values.
    assert!(!written(root, "a").contains_key(&DamageClass::Rebar));
    assert_eq!(written(root, "b")[&DamageClass::Rebar].count(), 0);
}

/// Runs the binary; returns (exit code, stdout, stderr).
fn run(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_damage-twin"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The flags that map the fixtures' categories ("Spall" as spalling).
const MAPPED: [&str; 4] = ["--class", "crack=crack", "--class", "Spall=spalling"];

/// `masks import ROOT FLAG FILE MAPPING…` fails with one error line naming `named` and saying
/// `what`, and writes no mask.
fn assert_refused(root: &Path, flag: &str, file: &Path, mapping: &[&str], named: &str, what: &str) {
    let mut args = vec![
        "masks",
        "import",
        root.to_str().unwrap(),
        flag,
        file.to_str().unwrap(),
    ];
    args.extend_from_slice(mapping);
    let (code, _, stderr) = run(&args);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(errors.len(), 1, "{stderr}");
    assert!(
        errors[0].contains(named) && errors[0].contains(what),
        "wanted {named:?} and {what:?}: {stderr}"
    );
    assert!(!root.join("masks").exists(), "a refused import wrote masks");
}

#[test]
fn hostile_annotations_are_refused_in_one_line_naming_the_file() {
    let data = dataset();
    let root = data.path();
    let file = |name: &str, text: &str| -> PathBuf {
        let path = root.join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let good = coco_text(&polygon_json(), POLYGON_RLE_COUNTS, "");
    // Malformed JSON: the file cut short.
    let cut = file("cut.json", &good[..good.len() / 2]);
    assert_refused(root, "--coco", &cut, &MAPPED, "cut.json", "not COCO JSON");
    // A polygon vertex beyond the image.
    let outside = file(
        "outside.json",
        &coco_text("[1, 1, 30.5, 2, 5, 9]", POLYGON_RLE_COUNTS, ""),
    );
    assert_refused(
        root,
        "--coco",
        &outside,
        &MAPPED,
        "outside.json",
        "(30.5, 2) outside the 16×12 image",
    );
    // An RLE one pixel short.
    let short = file(
        "short.json",
        &coco_text(
            &polygon_json(),
            "[62, 6, 6, 8, 4, 10, 2, 8, 4, 6, 6, 4, 8, 2, 55]",
            "",
        ),
    );
    assert_refused(
        root,
        "--coco",
        &short,
        &MAPPED,
        "short.json",
        "add up to 191 pixels",
    );
    // A category with no class: "Spall" without the mapping, named.
    let named = file("spall.json", &good);
    assert_refused(
        root,
        "--coco",
        &named,
        &[],
        "spall.json",
        "category \"Spall\"",
    );
    // A PNG of the wrong size for its image.
    let pngs = root.join("pngs");
    std::fs::create_dir_all(&pngs).unwrap();
    image::GrayImage::new(8, 6)
        .save(pngs.join("a.png"))
        .unwrap();
    assert_refused(
        root,
        "--png-dir",
        &pngs,
        &MAPPED,
        "pngs/a.png",
        "is 8×6 here but",
    );
    // LabelMe malformed and a line shape (no area).
    let broken = file("broken.json", "{\"imagePath\": \"a.png\", \"shapes\": [}");
    assert_refused(
        root,
        "--labelme",
        &broken,
        &MAPPED,
        "broken.json",
        "not LabelMe JSON",
    );
    let line = file(
        "line.json",
        r#"{"imagePath": "a.png", "imageWidth": 16, "imageHeight": 12,
            "shapes": [{"label": "crack", "points": [[1, 1], [5, 5]], "shape_type": "line"}]}"#,
    );
    assert_refused(
        root,
        "--labelme",
        &line,
        &MAPPED,
        "line.json",
        "a line has no area",
    );

    // The unknown category skipped on request: imported, counted in a warning.
    let skip = ClassMapping {
        unknown: UnknownCategories::Skip,
        ..ClassMapping::default()
    };
    let annotations = read_coco(&named, &skip).unwrap();
    assert_eq!(annotations.skipped.get("Spall"), Some(&2));
    let (code, stdout, stderr) = run(&[
        "masks",
        "import",
        root.to_str().unwrap(),
        "--coco",
        named.to_str().unwrap(),
        "--skip-unknown",
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("skipped 2 of \"Spall\""), "{stderr}");
    assert!(
        stdout.contains("crack     2 files (2 with damage"),
        "{stdout}"
    );
}

/// A labelled model over a synthetic survey: a Gaussian at every SfM point, about 2 % of the
/// scene across, labelled crack on one side of the scene, spalling on the other, rebar nowhere.
fn labelled_model(dataset: &Dataset) -> damage_twin::splats::Splats {
    use glam::{Quat, Vec3};
    let points = dataset.points.as_ref().expect("synth writes SfM points");
    let (lo, hi) = points
        .positions
        .iter()
        .fold((Vec3::MAX, Vec3::MIN), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        });
    let mid = (lo + hi) / 2.0;
    let size = (hi - lo).length() * 0.02;
    let mut splats = damage_twin::splats::Splats::empty(0, 3);
    for (g, &p) in points.positions.iter().enumerate() {
        let logit = |yes: bool| if yes { 6.0 } else { -6.0 };
        splats.push(
            p,
            Vec3::splat(size.ln()),
            Quat::IDENTITY,
            4.0,
            &[0.2, 0.2, 0.2],
            &[logit(p.x > mid.x), logit(p.x <= mid.x), logit(false)],
            g as u64,
            0,
        );
    }
    splats
}

#[test]
fn exported_twin_masks_import_back_identical() {
    use damage_twin::damage::Palette;
    use damage_twin::damage::display::rendered_masks;
    use damage_twin::damage::evaluate::DamageReadout;
    use damage_twin::scene::ImageScale;

    let dir = tempfile::tempdir().unwrap();
    let params = damage_twin::synth::SynthParams {
        width: 64,
        height: 36,
        views: 4,
        surveys: 1,
        sparse_points: 300,
        ..damage_twin::synth::SynthParams::demo(dir.path().join("synth"))
    };
    damage_twin::synth::generate(&params, &|_, _| {}).expect("synth");
    let root = dir.path().join("synth/survey-1");
    let dataset = open(&root);
    let splats = labelled_model(&dataset);
    let model = dir.path().join("model.ply");
    damage_twin::splats::ply::write_splats(&model, &splats).unwrap();

    let coco = dir.path().join("twin.json");
    let (code, stdout, stderr) = run(&[
        "masks",
        "export",
        model.to_str().unwrap(),
        root.to_str().unwrap(),
        "--out",
        coco.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stdout.contains("4 views, label mode"), "{stdout}");
    // The survey's own (noisy) masks go; the exported ones come back in their place.
    std::fs::remove_dir_all(root.join("masks")).unwrap();
    let (code, _, stderr) = run(&[
        "masks",
        "import",
        root.to_str().unwrap(),
        "--coco",
        coco.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{stderr}");

    let readout = DamageReadout::for_model(&splats, Palette::default());
    let folder = MaskFolder::new(root.join("masks"));
    let mut damage_pixels = [0usize; 3];
    for (index, view) in dataset.views.iter().enumerate() {
        let camera = dataset.view_camera(index, ImageScale::Factor(1)).unwrap();
        let size = (camera.intrinsics.width, camera.intrinsics.height);
        let rendered = rendered_masks(&splats, &camera, &readout, glam::Vec3::ZERO);
        let imported = folder.damage_masks(view, size).unwrap();
        for (class, mask) in DamageClass::ALL.into_iter().zip(rendered) {
            assert_eq!(imported[&class], mask, "view {} {class}", view.name);
            damage_pixels[class.channel()] += mask.count();
        }
    }
    // Not an empty round trip: crack and spalling were rendered, rebar was not.
    assert!(
        damage_pixels[0] > 100 && damage_pixels[1] > 100,
        "{damage_pixels:?}"
    );
    assert_eq!(damage_pixels[2], 0);
}

/// The viewer tints a snapped photo with its imported masks, or with the segmenter's
/// probabilities where they exist (`probabilities/<class>/<stem>.png`), and leaves it as it is
/// with the setting off.
#[cfg(feature = "app")]
#[test]
fn the_viewer_shows_a_photo_with_its_mask_or_probability_over_it() {
    use damage_twin::app::commands::Command;
    use damage_twin::app::photo_damage::PhotoDamage;
    use damage_twin::app::settings::Settings;
    use damage_twin::app::state::{AppState, Photo};

    let data = dataset();
    let root = data.path();
    let coco = root.join("annotations.json");
    std::fs::write(&coco, coco_text(&polygon_json(), POLYGON_RLE_COUNTS, "")).unwrap();
    let annotations = read_coco(&coco, &mapping()).unwrap();
    write_annotations(&open(root), &annotations, &root.join("masks")).unwrap();
    // View b's crack probability: 255 on the left half, 0 on the right.
    std::fs::create_dir_all(root.join("probabilities/crack")).unwrap();
    image::GrayImage::from_fn(W, H, |x, _| image::Luma([if x < 8 { 255 } else { 0 }]))
        .save(root.join("probabilities/crack/b.png"))
        .unwrap();

    let photo = |mode: PhotoDamage, view: &str| {
        let mut state = AppState::new(Settings {
            photo_damage: mode,
            ..Settings::default()
        });
        state.apply(Command::Open(root.to_path_buf()));
        let start = std::time::Instant::now();
        while state.scene.is_none() {
            state.poll();
            assert!(start.elapsed().as_secs() < 10, "{:?}", state.log);
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let dataset = state.scene.as_ref().unwrap().dataset.clone().unwrap();
        state.apply(Command::SnapToView(dataset.view_index(view).unwrap()));
        loop {
            state.poll();
            if let Some(Photo::Loaded(image)) = state.snap.as_ref().map(|s| s.photo.clone()) {
                return image;
            }
            assert!(start.elapsed().as_secs() < 10, "{:?}", state.log);
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    };
    let red = |image: &damage_twin::scene::RgbImage, x: u32, y: u32| {
        let i = ((y * W + x) * 3) as usize;
        image.data[i] - image.data[i + 1]
    };
    let grey = 90.0 / 255.0;
    let plain = photo(PhotoDamage::Off, "a");
    assert!(plain.data.iter().all(|&v| (v - grey).abs() < 0.01));
    // Masks: the polygon's pixels (crack, red by default) tinted, the rest as it was.
    let masked = photo(PhotoDamage::Masks, "a");
    let reference = art_mask(&POLYGON_ART);
    for y in 0..H {
        for x in 0..W {
            let tinted = red(&masked, x, y) > 0.3;
            assert_eq!(tinted, reference.get(x, y), "pixel {x},{y}");
        }
    }
    // Probabilities replace view b's crack mask (the RLE polygon): the left half tinted.
    let probable = photo(PhotoDamage::Probabilities, "b");
    assert!(red(&probable, 1, 1) > 0.3 && red(&probable, 14, 1) < 0.01);
    let b_masks = photo(PhotoDamage::Masks, "b");
    assert!(red(&b_masks, 1, 1) < 0.01 && red(&b_masks, 7, 3) > 0.3);
}
