//! `twin add-survey --photos DIR --align colmap`: a later survey's photos registered by COLMAP into
//! the posed survey's model. The plumbing and the refusals run against a fake `colmap` (a shell
//! script whose mapper writes a model the test made, with known poses and points), so the
//! residual it must report is known: the old cameras held but the whole model shifted and scaled
//! as COLMAP 3.8's mapper normalises it, the new photo's points with known errors.

use std::path::Path;
use std::process::{Command, Output};

mod colmap_support;

use colmap_support::{Setup, camera_at, noise_png};
use damage_twin::timeline::Twin;

fn binary() -> Command {
    Command::new(env!("CARGO_BIN_EXE_damage-twin"))
}

impl Setup {
    fn add_survey(&self, bin: &Path, photos: &str, extra: &[&str]) -> Output {
        binary()
            .args(["twin", "add-survey", "--quiet"])
            .arg(self.path("proj"))
            .args([
                "--survey",
                "s2",
                "--date",
                "2026-02-01",
                "--align",
                "colmap",
                // The fake on PATH is COLMAP's CLI, whichever engine is the default.
                "--engine",
                "colmap",
            ])
            .arg("--photos")
            .arg(self.path(photos))
            .arg("--dataset")
            .arg(self.path("s2"))
            .args(extra)
            .env("PATH", bin)
            .env_remove("DAMAGE_TWIN_COLMAP")
            .output()
            .unwrap()
    }

    /// Nothing of the new survey was left: no dataset or staging folder, the project unchanged.
    fn assert_nothing_added(&self) {
        let left: Vec<String> = std::fs::read_dir(self.dir.path())
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains("s2") && !n.ends_with(".pose-failed.log"))
            .collect();
        assert!(left.is_empty(), "left behind: {left:?}");
        let twin = Twin::open(&self.path("proj")).unwrap();
        assert_eq!(twin.project.surveys.len(), 1);
        assert!(!self.path("proj/surveys/s2").exists());
        assert_eq!(
            std::fs::read_to_string(self.path("s1/colmap/database.db")).unwrap(),
            "the old database"
        );
    }
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn new_photos_are_registered_into_the_posed_survey_and_the_residual_is_kept() {
    let setup = Setup::new();
    let bin = setup.fake_colmap(&setup.continued_model(true), "");
    let out = setup.add_survey(&bin, "new", &[]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("registered 1 of 2 photos"), "{stdout}");
    assert!(
        stderr.contains("e.png"),
        "the unregistered photo is named: {stderr}"
    );

    // COLMAP was driven on a copy of the old database: new photos only extracted, each matched
    // with every old photo and every other new one, the old poses held by the mapper.
    let calls = std::fs::read_to_string(bin.join("colmap.calls")).unwrap();
    assert!(calls.contains("feature_extractor") && calls.contains("new_images.txt"));
    assert!(calls.contains("matches_importer") && calls.contains("--match_type pairs"));
    assert!(calls.contains("--Mapper.fix_existing_images 1"), "{calls}");
    // e.png did not register with COLMAP's thresholds: the mapper ran again with looser ones.
    let mappers: Vec<&str> = calls.lines().filter(|l| l.starts_with("mapper")).collect();
    assert_eq!(mappers.len(), 2, "{calls}");
    assert!(
        mappers[1].contains("--Mapper.abs_pose_min_num_inliers 15"),
        "{calls}"
    );
    assert!(
        calls.contains("--input_path") && calls.contains("s1/sparse/0"),
        "{calls}"
    );
    let pairs = std::fs::read_to_string(setup.path("s2/colmap/pairs.txt")).unwrap();
    let mut pairs: Vec<&str> = pairs.lines().collect();
    pairs.sort();
    assert_eq!(
        pairs,
        [
            "d.png a.png",
            "d.png b.png",
            "d.png c.png",
            "d.png e.png",
            "e.png a.png",
            "e.png b.png",
            "e.png c.png"
        ]
    );
    assert_eq!(
        std::fs::read_to_string(setup.path("s2/colmap/database.db")).unwrap(),
        "the old database",
        "the copy the fake left untouched"
    );

    // The dataset: old and registered new photos, the model in the old frame, register.json.
    let images = setup.path("s2/images");
    for name in ["a.png", "b.png", "c.png", "d.png"] {
        assert!(images.join(name).is_file(), "{name}");
    }
    assert!(
        !images.join("e.png").exists(),
        "the unregistered photo is left out"
    );
    assert!(setup.path("s2/register.json").is_file());

    // The survey: its views are the new photo only, placed where the mapper put it.
    let twin = Twin::open(&setup.path("proj")).unwrap();
    let survey = twin.survey("s2").unwrap();
    assert_eq!(survey.views.as_deref(), Some(&["d".to_string()][..]));
    assert!(survey.alignment.is_none(), "survey 1's frame is the twin's");
    let placed = twin.open_survey_dataset("s2").unwrap();
    assert_eq!(placed.views.len(), 1);
    let expected = camera_at(3.0).position();
    assert!(placed.views[0].camera.position().distance(expected) < 1e-4);

    // The residual, as the fake made it: the old poses held (the mapper's normalisation undone:
    // 160 % of the spread before), d's points 0.5 and 0.7 px.
    let record = twin.load_registration("s2").unwrap().expect("a record");
    let r = &record.registration.residual;
    assert_eq!(record.reference_survey, "s1");
    assert_eq!(r.old_images, 3);
    assert!(r.old_position_change_max < 1e-5, "{r:?}");
    assert!(r.old_rotation_change_max_deg < 1e-4, "{r:?}");
    assert!((r.new_reprojection_error_px - 0.6).abs() < 1e-9, "{r:?}");
    assert_eq!(r.new_points, 2);
    assert_eq!(record.registration.unregistered, ["e.png"]);

    // `twin status` says it, in words and in JSON.
    let status = binary()
        .args(["twin", "status"])
        .arg(setup.path("proj"))
        .output()
        .unwrap();
    let status = text(&status.stdout);
    assert!(
        status.contains("1 of 2 photos registered into survey s1's model"),
        "{status}"
    );
    let json = binary()
        .args(["twin", "status", "--json"])
        .arg(setup.path("proj"))
        .output()
        .unwrap();
    let json: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    assert_eq!(
        json["surveys"][1]["registration"]["registration"]["residual"]["new_points"],
        2
    );
    assert!(json["surveys"][0]["registration"].is_null());
}

#[test]
fn no_registered_photo_is_a_clear_error_and_adds_nothing() {
    let setup = Setup::new();
    let bin = setup.fake_colmap(&setup.continued_model(false), "");
    let out = setup.add_survey(&bin, "new", &[]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("registered none of the 2 new photos"),
        "{stderr}"
    );
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    setup.assert_nothing_added();
}

#[test]
fn a_failing_colmap_reports_its_command_and_last_lines_and_adds_nothing() {
    let setup = Setup::new();
    let bin = setup.fake_colmap(
        &setup.continued_model(true),
        "if [ \"$cmd\" = matches_importer ]; then echo 'Matching block [1/1]'; \
         echo 'F0101 matching.cc:1] Check failed: pairs' >&2; exit 134; fi",
    );
    let out = setup.add_survey(&bin, "new", &[]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("matches_importer --database_path"),
        "{stderr}"
    );
    assert!(stderr.contains("Check failed: pairs"), "{stderr}");
    assert!(stderr.contains("exit status: 134"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    setup.assert_nothing_added();
    let log = std::fs::read_to_string(setup.path("s2.pose-failed.log")).unwrap();
    assert!(log.contains("feature_extractor"), "{log}");
}

#[test]
fn a_survey_without_a_colmap_workspace_or_clashing_names_is_refused() {
    let setup = Setup::new();
    let bin = setup.fake_colmap(&setup.continued_model(true), "");
    // A new photo named like an old one: views are named by stem.
    noise_png(&setup.path("new/a.jpg"), 9);
    let out = setup.add_survey(&bin, "new", &[]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("already has a photo named a.*"), "{stderr}");
    assert!(!bin.join("colmap.calls").exists(), "COLMAP ran");
    setup.assert_nothing_added();
    std::fs::remove_file(setup.path("new/a.jpg")).unwrap();

    // --photos takes --align colmap.
    let out = binary()
        .args(["twin", "add-survey", "--quiet"])
        .arg(setup.path("proj"))
        .args([
            "--survey",
            "s2",
            "--date",
            "2026-02-01",
            "--align",
            "joint",
            "--photos",
        ])
        .arg(setup.path("new"))
        .arg("--dataset")
        .arg(setup.path("s2"))
        .env("PATH", &bin)
        .output()
        .unwrap();
    assert!(
        text(&out.stderr).contains("give --align colmap"),
        "{}",
        text(&out.stderr)
    );

    // Survey 1 not made by `pose`: no database to register into.
    std::fs::remove_file(setup.path("s1/colmap/database.db")).unwrap();
    let out = setup.add_survey(&bin, "new", &[]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("damage-twin pose"), "{stderr}");
    assert!(!bin.join("colmap.calls").exists(), "COLMAP ran");
}
