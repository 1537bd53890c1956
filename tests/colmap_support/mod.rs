//! A posed survey and a fake `colmap` for the tests of COLMAP's callers (`twin add-survey
//! --photos`, the app's flows from photos): a dataset `s1` as `damage-twin pose` leaves it (its
//! model with known poses, photos, a COLMAP database), a twin made of it, new photos, and a shell
//! script standing in for COLMAP whose mapper writes a model the test made.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use damage_twin::scene::colmap::{self, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint};
use damage_twin::scene::{Camera, Intrinsics};
use damage_twin::timeline::Twin;
use glam::Vec3;

pub const K: Intrinsics = Intrinsics {
    width: 64,
    height: 48,
    fx: 50.0,
    fy: 50.0,
    cx: 32.0,
    cy: 24.0,
};

pub fn camera_at(x: f32) -> Camera {
    Camera::look_at(K, Vec3::new(x, -6.0, 2.0), Vec3::ZERO, Vec3::Z)
}

pub fn image(id: u32, camera_id: u32, name: &str, camera: &Camera) -> ColmapImage {
    let mut image = ColmapImage::from_camera(id, camera_id, name, camera);
    image.points2d = vec![([10.0, 10.0], -1), ([20.0, 20.0], -1)];
    image
}

pub fn point(id: u64, track: &[(u32, u32)], error: f64) -> ColmapPoint {
    ColmapPoint {
        id,
        xyz: [0.0, 0.0, id as f64 * 0.1],
        rgb: [200, 100, 50],
        error,
        track: track.to_vec(),
    }
}

pub fn noise_png(path: &Path, seed: u64) {
    let mut rng = fastrand::Rng::with_seed(seed);
    image::RgbImage::from_fn(64, 48, |_, _| {
        image::Rgb([rng.u8(..), rng.u8(..), rng.u8(..)])
    })
    .save(path)
    .unwrap();
}

/// The old survey: three photos `a`, `b`, `c` posed by "pose" (a model, its photos and a COLMAP
/// database), and the twin made of it.
pub struct Setup {
    pub dir: tempfile::TempDir,
}

impl Setup {
    pub fn new() -> Setup {
        let dir = tempfile::tempdir().unwrap();
        let reference = dir.path().join("s1");
        std::fs::create_dir_all(reference.join("images")).unwrap();
        std::fs::create_dir_all(reference.join("colmap")).unwrap();
        std::fs::write(reference.join("colmap/database.db"), "the old database").unwrap();
        let mut model = ColmapModel {
            cameras: vec![ColmapCamera::pinhole(1, &K)],
            ..Default::default()
        };
        for (i, name) in ["a.png", "b.png", "c.png"].iter().enumerate() {
            noise_png(&reference.join("images").join(name), i as u64);
            let id = i as u32 + 1;
            model
                .images
                .push(image(id, 1, name, &camera_at(i as f32 * 2.0 - 2.0)));
        }
        model.points = vec![point(1, &[(1, 0), (2, 0)], 2.0)];
        colmap::write_binary(&reference.join("sparse/0"), &model).unwrap();
        let mut twin = Twin::create(&dir.path().join("proj")).unwrap();
        twin.add_survey("s1", "2026-01-01", &reference).unwrap();
        twin.save().unwrap();
        let photos = dir.path().join("new");
        std::fs::create_dir_all(&photos).unwrap();
        noise_png(&photos.join("d.png"), 7);
        noise_png(&photos.join("e.png"), 8);
        Setup { dir }
    }

    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// The model the fake mapper "continues" to: the old photos held, `d` registered (its own
    /// camera) and `e` not, unless `register_d` is false.
    pub fn continued_model(&self, register_d: bool) -> PathBuf {
        let mut model = colmap::read_binary(&self.path("s1/sparse/0")).unwrap();
        if register_d {
            model.cameras.push(ColmapCamera::pinhole(2, &K));
            model.images.push(image(4, 2, "d.png", &camera_at(3.0)));
            model.points.push(point(2, &[(4, 0), (1, 1)], 0.5));
            model.points.push(point(3, &[(4, 1), (3, 0)], 0.7));
        }
        // COLMAP 3.8's mapper normalises what it writes (a shift and a scale, even with the
        // old poses held): the whole model is written moved by one, which must be undone.
        let (scale, shift) = (0.25_f64, glam::DVec3::new(3.0, -1.0, 2.0));
        for image in &mut model.images {
            let [w, x, y, z] = image.qvec;
            let q = glam::DQuat::from_xyzw(x, y, z, w);
            image.tvec = (scale * glam::DVec3::from_array(image.tvec) - q * shift).to_array();
        }
        for p in &mut model.points {
            p.xyz = (scale * glam::DVec3::from_array(p.xyz) + shift).to_array();
        }
        let out = self.path(if register_d { "continued" } else { "old-only" });
        colmap::write_binary(&out, &model).unwrap();
        out
    }

    /// A fake `colmap` on PATH: logs each call's arguments, runs `extra` (sh) for its command
    /// (`$cmd`), and its mapper copies `model` into `--output_path`.
    pub fn fake_colmap(&self, model: &Path, extra: &str) -> PathBuf {
        use std::os::unix::fs::PermissionsExt;
        let bin = self.path("bin");
        std::fs::create_dir_all(&bin).unwrap();
        let script = format!(
            "#!/bin/sh\nPATH=/usr/bin:/bin\necho \"$@\" >> \"$0.calls\"\ncmd=$1\nout=\nwhile [ $# -gt 0 ]; do \
             [ \"$1\" = --output_path ] && out=$2; shift; done\n{extra}\nif [ \"$cmd\" = mapper ]; \
             then echo 'Registering image #4 (4)'; cp {}/*.bin \"$out/\"; fi\nexit 0\n",
            model.display()
        );
        let path = bin.join("colmap");
        std::fs::write(&path, script).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
        bin
    }
}

/// Points `DAMAGE_TWIN_COLMAP`, once per test process, at a dispatcher that runs the fake of
/// whichever test's files COLMAP is given: `<test dir>/bin/colmap` (`Setup::fake_colmap`), found
/// from `--database_path <test dir>/<staging folder>/colmap/database.db`. In-process callers
/// (the app's jobs) cannot be handed a PATH of their own, and tests run side by side.
pub fn fake_colmap_in_process() {
    use std::os::unix::fs::PermissionsExt;
    static DISPATCHER: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
    DISPATCHER.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("colmap");
        std::fs::write(
            &path,
            "#!/bin/sh\ndb=\nprev=\nfor a in \"$@\"; do [ \"$prev\" = --database_path ] && db=$a; \
             prev=$a; done\n[ -z \"$db\" ] && exit 0\n\
             exec \"$(dirname \"$(dirname \"$(dirname \"$db\")\")\")/bin/colmap\" \"$@\"\n",
        )
        .unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
        // SAFETY: set once, to the same value for every test of the process, before the test
        // that sets it starts any job; other tests' threads read the environment through std,
        // which serialises access, and only this variable changes.
        unsafe { std::env::set_var("DAMAGE_TWIN_COLMAP", &path) };
        dir
    });
}
