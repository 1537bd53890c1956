//! Damage measured on a known wall: a 2 m crack (with a 0.5 m branch) and a 0.3 m-radius spall
//! drawn with Gaussians on a wall of plain ones; the measurement's lengths and areas against the
//! drawn ones, the regions' classes and count, and report.json against docs/report.schema.json.

use std::collections::BTreeMap;

use glam::{Quat, Vec3};

use damage_twin::damage::DamageClass;
use damage_twin::damage::measure::{MeasureConfig, Measurement, measure_damage};
use damage_twin::report::georeference::ReportGeoreference;
use damage_twin::report::inspection::{InspectionReport, ReportSettings, report_html};
use damage_twin::report::project_runs::project_runs;
use damage_twin::scene::sfm::GeorefSource;
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::splats::Splats;
use damage_twin::timeline::georeference::GeodeticPosition;
use damage_twin::timeline::quantities::{ReportRegion, SurveyQuantities, Totals};

const ON: f32 = 6.0;
const OFF: f32 = -6.0;

/// A wall in the plane y = 0 (x 0..4, z 0..3) of 2 cm flat Gaussians, with damage on top of it.
fn damaged_wall() -> Splats {
    let mut s = Splats {
        label_channels: 3,
        ..Splats::default()
    };
    let grey = [0.2f32, 0.2, 0.2];
    let flat = Vec3::new(0.02f32, 0.001, 0.02).ln();
    let mut id = 0;
    let mut add =
        |s: &mut Splats, mean: Vec3, log_scale: Vec3, rotation: Quat, labels: [f32; 3]| {
            s.push(mean, log_scale, rotation, 4.0, &grey, &labels, id, 0);
            id += 1;
        };
    for i in 0..100 {
        for j in 0..75 {
            let p = Vec3::new(i as f32 * 0.04, 0.0, j as f32 * 0.04);
            add(&mut s, p, flat, Quat::IDENTITY, [OFF; 3]);
        }
    }
    // Crack Gaussians 1.5 cm apart along the line, 5 mm across: drawn in front of the wall.
    let mut line = |s: &mut Splats, from: Vec3, to: Vec3| {
        let d = to - from;
        let n = (d.length() / 0.015).round() as usize;
        let angle = d.z.atan2(d.x);
        let rotation = Quat::from_rotation_y(-angle);
        for k in 0..=n {
            let p = from + d * (k as f32 / n as f32) - Vec3::Y * 0.005;
            add(
                s,
                p,
                Vec3::new(0.01, 0.001, 0.004).ln(),
                rotation,
                [ON, OFF, OFF],
            );
        }
    };
    line(&mut s, Vec3::new(0.5, 0.0, 1.0), Vec3::new(2.5, 0.0, 1.0));
    line(&mut s, Vec3::new(1.5, 0.0, 1.0), Vec3::new(1.5, 0.0, 1.5));
    // The spall: a disc of 2 cm Gaussians 2 cm apart, centre (3.2, 2.2), radius 0.3.
    let centre = Vec3::new(3.2, -0.005, 2.2);
    for i in -15..=15 {
        for j in -15..=15 {
            let offset = Vec3::new(i as f32 * 0.02, 0.0, j as f32 * 0.02);
            if offset.length() <= 0.29 {
                add(
                    &mut s,
                    centre + offset,
                    flat,
                    Quat::IDENTITY,
                    [OFF, ON, OFF],
                );
            }
        }
    }
    s
}

/// A 60° camera at `eye` looking at the wall's middle.
fn camera_at(eye: Vec3) -> Camera {
    let intrinsics = Intrinsics {
        width: 640,
        height: 480,
        fx: 554.0,
        fy: 554.0,
        cx: 320.0,
        cy: 240.0,
    };
    Camera::look_at(intrinsics, eye, Vec3::new(2.0, 0.0, 1.5), Vec3::Z)
}

#[test]
fn a_drawn_crack_and_spall_measure_within_tolerance() {
    let splats = damaged_wall();
    let cameras = [
        camera_at(Vec3::new(2.0, -5.0, 1.5)),
        camera_at(Vec3::new(1.0, -4.0, 2.0)),
    ];
    let m = measure_damage(&splats, &cameras, &MeasureConfig::default());
    let cracks: Vec<_> = m.of(DamageClass::Crack).collect();
    let spalls: Vec<_> = m.of(DamageClass::Spalling).collect();
    assert_eq!(cracks.len(), 1, "one crack with its branch: {cracks:?}");
    assert_eq!(spalls.len(), 1);
    assert_eq!(m.of(DamageClass::Rebar).count(), 0);
    let length = m.total_length(DamageClass::Crack);
    assert!(
        (length - 2.5).abs() < 0.25,
        "crack length {length} m, drawn 2.5 m"
    );
    let area = m.total_area(DamageClass::Spalling);
    let drawn = std::f64::consts::PI * 0.3 * 0.3;
    assert!(
        (area - drawn).abs() < 0.15 * drawn,
        "spall {area} m², drawn {drawn}"
    );
    let width = cracks[0].width.unwrap();
    assert!(width > 0.005 && width < 0.04, "crack width {width}");
    let c = spalls[0].centroid;
    assert!(
        (c[0] - 3.2).abs() < 0.03 && (c[2] - 2.2).abs() < 0.03,
        "{c:?}"
    );
    // Seen from the cameras' side: the plane's normal points to -y.
    assert!(m.planes[0].normal[1] < -0.99, "{:?}", m.planes[0]);
}

#[test]
fn a_wall_seen_from_behind_hides_the_damage_drawn_in_front() {
    // The same wall photographed from +y: the plain wall is nearer than the damage drawn 5 mm in
    // front of it on the other side, so the blended labels stay below one half.
    let splats = damaged_wall();
    let m = measure_damage(
        &splats,
        &[camera_at(Vec3::new(2.0, 5.0, 1.5))],
        &MeasureConfig::default(),
    );
    assert!(m.total_length(DamageClass::Crack) < 0.5, "{:?}", m.regions);
}

#[test]
fn report_json_follows_its_documented_schema() {
    let splats = damaged_wall();
    let m = measure_damage(
        &splats,
        &[camera_at(Vec3::new(2.0, -5.0, 1.5))],
        &MeasureConfig::default(),
    );
    let regions: Vec<ReportRegion> = m
        .regions
        .iter()
        .enumerate()
        .map(|(i, r)| ReportRegion {
            id: format!("s1-{}-{i}", r.class.id()),
            class: r.class,
            centroid_m: r.centroid,
            height_m: r.centroid[2],
            // One region georeferenced, one not (a local control-point frame has no latitude).
            geodetic: (i == 0).then_some(GeodeticPosition {
                latitude: 55.698,
                longitude: 13.195,
                height_m: 41.5,
            }),
            component: Some("wall".into()),
            length_m: r.length,
            width_m: r.width,
            area_m2: r.area,
            gaussians: r.gaussians,
            first_seen: Some("s1".into()),
            new: false,
            previous: Vec::new(),
            growth: None,
        })
        .collect();
    let survey = SurveyQuantities {
        survey: "s1".into(),
        date: "2024-06-01".into(),
        gaussians: splats.len(),
        totals: Totals {
            crack_length_m: m.total_length(DamageClass::Crack),
            ..Totals::default()
        },
        regions,
        planes: m.planes.clone(),
        seconds: m.seconds,
    };
    let report = InspectionReport::new(
        "wall".into(),
        "2026-11-26".into(),
        ReportSettings {
            metres_per_unit: 1.0,
            scale_known: true,
            label_threshold: 0.5,
            map_cell_m: 0.01,
            region_gap_m: 0.05,
            plane_slab_m: 0.3,
        },
        vec![survey],
        BTreeMap::new(),
        project_runs(
            "s1",
            &serde_json::from_value(serde_json::json!({
                "seconds": 12.0, "heldout_psnr": 24.5, "heldout_ssim": null, "gaussians": 100,
                "iterations": 500, "scale": {"Factor": 4},
            }))
            .unwrap(),
        ),
    );
    let georeference = ReportGeoreference {
        survey: "s1".into(),
        source: GeorefSource::Gps,
        latitude: 55.698,
        longitude: 13.195,
        altitude: 37.0,
        metres_per_unit: 13.6,
        rms_m: 4.26,
        baseline_m: 52.2,
        positions: 26,
        scale_uncertainty: 0.016,
        trust: "the scale is good to ±1.6 %".into(),
    };
    let registration = serde_json::from_value(serde_json::json!({
        "reference_survey": "s0",
        "registration": {
            "engine": "COLMAP 3.8", "reference": "/data/s0", "photos": 2,
            "registered": ["d.jpg"], "unregistered": ["e.jpg"], "seconds": 60.0,
            "warnings": [],
            "residual": {
                "old_images": 3, "old_rotation_change_median_deg": 0.0,
                "old_rotation_change_max_deg": 0.0, "old_position_change_median": 0.0,
                "old_position_change_max": 0.0, "old_camera_spread": 2.0,
                "old_focal_change_relative": 0.001, "new_reprojection_error_px": 0.61,
                "new_points": 120
            }
        }
    }))
    .unwrap();
    let report = report.with_placement(
        Some(georeference),
        BTreeMap::from([("s1".to_string(), registration)]),
    );
    let json = serde_json::to_value(&report).unwrap();
    let schema_text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/report.schema.json"),
    )
    .unwrap();
    let schema: serde_json::Value = serde_json::from_str(&schema_text).unwrap();
    let mut errors = Vec::new();
    validate(&json, &schema, "$", &mut errors);
    assert!(errors.is_empty(), "{errors:#?}");
    // A report missing a required field fails the same check (the validator can fail).
    let mut broken = json.clone();
    broken["totals"]["s1"]
        .as_object_mut()
        .unwrap()
        .remove("crack_length_m");
    let mut errors = Vec::new();
    validate(&broken, &schema, "$", &mut errors);
    assert_eq!(errors.len(), 1, "{errors:?}");

    let html = report_html(&report, &[], &[]);
    assert!(html.starts_with("<!DOCTYPE html>") && html.ends_with("</html>"));
    assert!(html.contains("@media print") && html.contains("s1-crack-0"));
    // The run that made the model, in the speed-against-accuracy table.
    assert!(
        html.contains("Training and speed against accuracy")
            && html.contains("<td class=\"l\">trained</td><td>12 s</td><td>24.50 dB</td>"),
        "{html}"
    );
    assert_eq!(json["runs"][0]["step"], "trained");
    // Per region its latitude, longitude and height; the georeference's trust and the survey's
    // registration residual in words.
    assert!(
        html.contains("<td>55.6980000°, 13.1950000°, 41.5 m</td>"),
        "{html}"
    );
    assert!(html.contains("the scale is good to ±1.6 %"), "{html}");
    assert!(
        html.contains("new photos&#39; points 0.61 px")
            || html.contains("new photos' points 0.61 px"),
        "{html}"
    );
    assert!(json["surveys"][0]["regions"][1]["geodetic"].is_null());
}

/// The subset of JSON Schema the documented schema uses: type (one or a list), required,
/// properties, additionalProperties (a schema), items, enum.
fn validate(
    value: &serde_json::Value,
    schema: &serde_json::Value,
    at: &str,
    errors: &mut Vec<String>,
) {
    use serde_json::Value;
    if let Some(t) = schema.get("type") {
        let types: Vec<&str> = match t {
            Value::String(s) => vec![s.as_str()],
            Value::Array(a) => a.iter().filter_map(|v| v.as_str()).collect(),
            _ => Vec::new(),
        };
        let ok = types.iter().any(|&t| match t {
            "object" => value.is_object(),
            "array" => value.is_array(),
            "string" => value.is_string(),
            "number" => value.is_number(),
            "integer" => value.is_u64() || value.is_i64(),
            "boolean" => value.is_boolean(),
            "null" => value.is_null(),
            _ => false,
        });
        if !ok {
            errors.push(format!("{at}: expected {types:?}, found {value}"));
            return;
        }
    }
    if let Some(Value::Array(allowed)) = schema.get("enum")
        && !allowed.contains(value)
    {
        errors.push(format!("{at}: {value} not in {allowed:?}"));
    }
    if let Value::Object(map) = value {
        if let Some(Value::Array(required)) = schema.get("required") {
            for key in required.iter().filter_map(|k| k.as_str()) {
                if !map.contains_key(key) {
                    errors.push(format!("{at}: missing {key}"));
                }
            }
        }
        for (key, v) in map {
            let sub = schema
                .get("properties")
                .and_then(|p| p.get(key))
                .or_else(|| schema.get("additionalProperties").filter(|a| a.is_object()));
            if let Some(sub) = sub {
                validate(v, sub, &format!("{at}.{key}"), errors);
            }
        }
    }
    if let (Value::Array(items), Some(sub)) = (value, schema.get("items")) {
        for (i, v) in items.iter().enumerate() {
            validate(v, sub, &format!("{at}[{i}]"), errors);
        }
    }
}

/// The viewer measures the same regions, lists them, and a click selects one region's damage
/// Gaussians (and only those) and frames it.
#[cfg(feature = "app")]
#[test]
fn the_viewer_selects_and_frames_a_measured_region() {
    use std::sync::Arc;
    use std::time::{Duration, Instant};

    use damage_twin::app::commands::Command;
    use damage_twin::app::settings::Settings;
    use damage_twin::app::state::{AppState, WorkerResult};
    use damage_twin::scene::{Dataset, DatasetFormat, Split, View};
    use damage_twin::splats::model::state::SELECTED;

    let mut state = AppState::new(Settings::default());
    let views = [Vec3::new(2.0, -5.0, 1.5), Vec3::new(1.0, -4.0, 2.0)]
        .iter()
        .enumerate()
        .map(|(i, &eye)| View {
            name: format!("view{i}"),
            image_path: format!("missing{i}.png").into(),
            camera: camera_at(eye),
            distortion: None,
            split: Split::Unspecified,
            ignore_mask: None,
        })
        .collect();
    let dataset = Dataset {
        root: "wall".into(),
        format: DatasetFormat::ColmapText,
        views,
        image_files: 2,
        camera_count: 1,
        camera_models: BTreeMap::new(),
        points: None,
        masks: None,
        mask_counts: BTreeMap::new(),
        background: [0.0; 3],
        warnings: Vec::new(),
        view_cache: None,
    };
    state
        .results_sender()
        .send(WorkerResult::Opened {
            source: "wall".into(),
            dataset: Some(Arc::new(dataset)),
            splats: Some(Arc::new(damaged_wall())),
            project_dir: None,
        })
        .unwrap();
    state.poll();
    state.apply(Command::MeasureRegions);
    let start = Instant::now();
    while state.regions.is_none() {
        state.poll();
        assert!(start.elapsed() < Duration::from_secs(20), "{:?}", state.log);
        std::thread::sleep(Duration::from_millis(5));
    }
    let measurement = state.regions.as_ref().unwrap().measurement.clone();
    let spall = measurement
        .regions
        .iter()
        .position(|r| r.class == DamageClass::Spalling)
        .expect("the spall is a region");
    state.apply(Command::FocusRegion(spall));
    let splats = state.splats.as_ref().unwrap();
    let selected: Vec<u32> = (0..splats.len() as u32)
        .filter(|&g| splats.meta.state[g as usize] & SELECTED != 0)
        .collect();
    assert_eq!(selected, measurement.regions[spall].members);
    // The spall's Gaussians are the last ones pushed; the wall's and crack's are not selected.
    assert!(
        selected.len() > 500 && selected[0] as usize > 7500 + 160,
        "{}",
        selected.len()
    );
    let goal = state.camera.goal();
    assert!(
        (goal.target - Vec3::new(3.2, 0.0, 2.2)).length() < 0.05,
        "{:?}",
        goal.target
    );
    // The measurement stays current: selecting changed no geometry.
    assert_eq!(
        state.regions.as_ref().unwrap().generation,
        state.splats_generation
    );
}

#[test]
fn a_stray_damage_gaussian_far_out_in_the_plane_does_not_blow_up_the_map() {
    // Three crack Gaussians 300 m along the wall's plane: the plane's map would be 300 m wide;
    // it is mapped with larger cells instead of ~40 million 1 cm ones.
    let mut splats = damaged_wall();
    for k in 0..3 {
        let p = Vec3::new(300.0 + k as f32 * 0.01, -0.005, 1.0);
        splats.push(
            p,
            Vec3::new(0.01, 0.001, 0.004).ln(),
            Quat::IDENTITY,
            4.0,
            &[0.2, 0.2, 0.2],
            &[ON, OFF, OFF],
            90_000 + k,
            0,
        );
    }
    let cameras = [camera_at(Vec3::new(2.0, -5.0, 1.5))];
    let m = measure_damage(&splats, &cameras, &MeasureConfig::default());
    let cells: usize = m
        .planes
        .iter()
        .map(|p| p.map_cells[0] * p.map_cells[1])
        .max()
        .unwrap();
    assert!(cells <= 8_000_000, "{cells} cells");
    let length = m.total_length(DamageClass::Crack);
    assert!((length - 2.5).abs() < 0.4, "crack length {length} m");
}

#[test]
fn a_class_without_regions_totals_zero_not_minus_zero() {
    // `Iterator::sum` of no f64 is −0: `study real` wrote "measured -0.000" for lund's rebar.
    let none = Measurement::default();
    for class in DamageClass::ALL {
        for total in [none.total_length(class), none.total_area(class)] {
            assert!(total.is_sign_positive(), "{class:?}: {total}");
            assert_eq!(format!("{total:.3}"), "0.000");
        }
    }
}
