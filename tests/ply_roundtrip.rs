//! PLY write → read round-trips bit for bit for SH degrees 0..3, with and without label
//! channels, and the standard part of the file is laid out exactly as the original 3DGS
//! `save_ply` lays it out (header text and byte order of the values).

mod shared_data;

use std::path::Path;

use damage_twin::scene::PointCloud;
use damage_twin::scene::ply::{read_point_cloud, write_point_cloud};
use damage_twin::splats::Splats;
use damage_twin::splats::model::OverlayColours;
use damage_twin::splats::ply::{read_splats, write_splats};
use glam::{Quat, Vec3};

/// Deterministic pseudo-random splats with awkward values (negative zero, subnormals, huge).
fn splats(sh_degree: u32, label_channels: usize, n: usize, seed: u64) -> Splats {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut value = move || match rng.u32(0..20) {
        0 => -0.0,
        1 => f32::MIN_POSITIVE / 4.0,
        2 => 3.0e38,
        _ => rng.f32() * 20.0 - 10.0,
    };
    let mut s = Splats::empty(sh_degree, label_channels);
    let k = s.sh_coeffs();
    for g in 0..n {
        let sh: Vec<f32> = (0..k * 3).map(|_| value()).collect();
        let labels: Vec<f32> = (0..label_channels).map(|_| value()).collect();
        let rotation = Quat::from_xyzw(value(), value(), value(), 1.0 + value().abs());
        s.push(
            Vec3::new(value(), value(), value()),
            Vec3::new(value(), value(), value()),
            rotation,
            value(),
            &sh,
            &labels,
            (g as u64) * 1_000_003 + (1 << 40),
            (g % 7) as u16,
        );
        // History and state bits travel too (every third Gaussian never damage).
        s.meta.damage_survey[g] = if g % 3 == 0 {
            damage_twin::splats::model::NO_SURVEY
        } else {
            (g % 5) as u16
        };
        s.meta.state[g] = (g % 32) as u8;
    }
    s
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn assert_bitwise_equal(a: &Splats, b: &Splats) {
    assert_eq!(a.sh_degree, b.sh_degree);
    assert_eq!(a.label_channels, b.label_channels);
    let flat3 = |v: &[Vec3]| bits(&v.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>());
    let flat4 = |v: &[Quat]| bits(&v.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>());
    assert_eq!(flat3(&a.means), flat3(&b.means));
    assert_eq!(flat3(&a.log_scales), flat3(&b.log_scales));
    assert_eq!(flat4(&a.rotations), flat4(&b.rotations));
    assert_eq!(bits(&a.raw_opacities), bits(&b.raw_opacities));
    assert_eq!(bits(&a.sh), bits(&b.sh));
    assert_eq!(bits(&a.raw_labels), bits(&b.raw_labels));
    assert_eq!(a.meta, b.meta);
    assert_eq!(a.overlay, b.overlay);
}

#[test]
fn splats_round_trip_bitwise_for_every_sh_degree_with_and_without_labels() {
    let dir = tempfile::tempdir().unwrap();
    for degree in 0..=3 {
        for labels in [0, 3] {
            let original = splats(degree, labels, 57, u64::from(degree) * 10 + labels as u64);
            let path = dir.path().join(format!("d{degree}_l{labels}.ply"));
            write_splats(&path, &original).unwrap();
            let read = read_splats(&path).unwrap();
            assert_bitwise_equal(&original, &read);
            // Size: header + N × (4 bytes × (14 + 3K + labels + survey) + 8 bytes id + 4 bytes
            // damage_survey + 1 byte state).
            let k = (degree + 1) * (degree + 1);
            let header_len = header_of(&path).len();
            let row = 4 * (14 + 3 * k as usize + labels + 1) + 8 + 4 + 1;
            assert_eq!(
                std::fs::metadata(&path).unwrap().len() as usize,
                header_len + 57 * row
            );
        }
    }
}

#[test]
fn empty_model_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.ply");
    let original = Splats::empty(3, 3);
    write_splats(&path, &original).unwrap();
    assert_bitwise_equal(&original, &read_splats(&path).unwrap());
}

#[test]
fn overlay_colours_travel_in_a_header_comment_and_bad_ones_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("overlay.ply");
    let mut original = splats(1, 0, 5, 3);
    original.overlay = Some(OverlayColours {
        colours: [[0, 0, 255], [0, 255, 0], [255, 0, 255]],
        tolerance: 87.5,
    });
    write_splats(&path, &original).unwrap();
    assert!(header_of(&path).contains(
        "comment damage_twin overlay_colours 0,0,255 0,255,0 255,0,255 tolerance 87.5\n"
    ));
    assert_bitwise_equal(&original, &read_splats(&path).unwrap());
    // Our comment with a bad colour names the file and the comment; other comments are fine.
    let mut bytes = std::fs::read(&path).unwrap();
    let at = bytes.windows(8).position(|w| w == b"0,255,0 ").unwrap();
    bytes[at + 4] = b'6'; // 0,256,0: not a byte
    let bad_path = dir.path().join("bad.ply");
    std::fs::write(&bad_path, &bytes).unwrap();
    let err = read_splats(&bad_path).unwrap_err().to_string();
    assert!(
        err.contains("bad.ply") && err.contains("overlay_colours"),
        "{err}"
    );
}

fn header_of(path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap();
    String::from_utf8(bytes[..end + 11].to_vec()).unwrap()
}

/// The header plyfile writes for 3DGS's `save_ply` with `sh_degree = 3`, spelled out by hand
/// (`construct_list_of_attributes`: x y z nx ny nz, f_dc_0..2, f_rest_0..44, opacity,
/// scale_0..2, rot_0..3; every field numpy `f4` → `float`).
fn original_3dgs_header(n: usize) -> String {
    let mut h = format!("ply\nformat binary_little_endian 1.0\nelement vertex {n}\n");
    for name in [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ] {
        h += &format!("property float {name}\n");
    }
    for i in 0..45 {
        h += &format!("property float f_rest_{i}\n");
    }
    h += "property float opacity\n";
    for name in [
        "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        h += &format!("property float {name}\n");
    }
    h
}

#[test]
fn standard_fields_match_the_original_3dgs_layout() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.ply");
    let s = splats(3, 3, 4, 99);
    write_splats(&path, &s).unwrap();
    let header = header_of(&path);
    let standard = original_3dgs_header(4);
    assert!(header.starts_with(&standard), "{header}");
    assert_eq!(
        &header[standard.len()..],
        "property float label_crack\nproperty float label_spalling\nproperty float label_rebar\n\
         property float survey\nproperty double id\nproperty float damage_survey\n\
         property uchar state\nend_header\n"
    );
    // Values of Gaussian 2 straight from the bytes, in 3DGS's order.
    let bytes = std::fs::read(&path).unwrap();
    let row_len = 4 * (14 + 48 + 3 + 1) + 8 + 4 + 1;
    let row = &bytes[header.len() + 2 * row_len..header.len() + 3 * row_len];
    let f = |i: usize| f32::from_le_bytes(row[4 * i..4 * i + 4].try_into().unwrap());
    assert_eq!(f(0).to_bits(), s.means[2].x.to_bits());
    assert_eq!([f(3), f(4), f(5)], [0.0; 3], "normals are zero");
    let sh = s.sh_of(2);
    for c in 0..3 {
        assert_eq!(f(6 + c).to_bits(), sh[c].to_bits(), "f_dc_{c}");
        for k in 1..16 {
            // f_rest is channel-major: f_rest_{c*15 + k-1} = coefficient k of channel c.
            let i = 9 + c * 15 + (k - 1);
            assert_eq!(
                f(i).to_bits(),
                sh[k * 3 + c].to_bits(),
                "coeff {k} channel {c}"
            );
        }
    }
    assert_eq!(f(54).to_bits(), s.raw_opacities[2].to_bits());
    assert_eq!(f(57).to_bits(), s.log_scales[2].z.to_bits());
    let q = s.rotations[2];
    assert_eq!(
        [f(58), f(59), f(60), f(61)].map(f32::to_bits),
        [q.w, q.x, q.y, q.z].map(f32::to_bits)
    );
    assert_eq!(f(64).to_bits(), s.raw_labels[2 * 3 + 2].to_bits());
    assert_eq!(f(65), 2.0, "survey");
    let id = f64::from_le_bytes(row[4 * 66..4 * 66 + 8].try_into().unwrap());
    assert_eq!(id as u64, s.meta.ids[2]);
    let damage_survey = f32::from_le_bytes(row[4 * 66 + 8..4 * 66 + 12].try_into().unwrap());
    assert_eq!(damage_survey, f32::from(s.meta.damage_survey[2]));
    assert_eq!(row[4 * 66 + 12], s.meta.state[2], "state");
}

/// A degree-1 file as another tool might write it: ASCII, properties in another order, no
/// normals, no extras, `double` positions.
#[test]
fn reads_ascii_files_with_other_property_orders_and_types() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("other.ply");
    let mut text =
        String::from("ply\nformat ascii 1.0\ncomment written by hand\nelement vertex 2\n");
    for name in ["rot_0", "rot_1", "rot_2", "rot_3", "opacity"] {
        text += &format!("property float {name}\n");
    }
    for name in ["x", "y", "z"] {
        text += &format!("property double {name}\n");
    }
    for i in (0..9).rev() {
        text += &format!("property float f_rest_{i}\n");
    }
    text += "property float scale_0\nproperty float scale_1\nproperty float scale_2\n";
    text += "property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\n";
    text += "element face 0\nproperty list uchar int vertex_indices\nend_header\n";
    for g in 0..2 {
        let g = g as f32;
        text += &format!("1 0 0 {g} -2.5 {g} 1.5 -3 ");
        text += &(0..9)
            .rev()
            .map(|i| format!("{}", 10.0 * g + i as f32))
            .collect::<Vec<_>>()
            .join(" ");
        text += &format!(" -1 -2 -3 0.1 0.2 {}\n", 0.3 + g);
    }
    std::fs::write(&path, text).unwrap();
    let s = read_splats(&path).unwrap();
    assert_eq!((s.len(), s.sh_degree, s.label_channels), (2, 1, 0));
    assert_eq!(s.means[1], Vec3::new(1.0, 1.5, -3.0));
    assert_eq!(s.rotations[1], Quat::from_xyzw(0.0, 0.0, 1.0, 1.0));
    assert_eq!(s.raw_opacities[0], -2.5);
    assert_eq!(s.log_scales[0], Vec3::new(-1.0, -2.0, -3.0));
    // Gaussian 1: f_rest_i = 10 + i; coefficient k of channel c is f_rest_{c*3 + k-1}.
    let sh = s.sh_of(1);
    assert_eq!(&sh[..3], &[0.1, 0.2, 1.3]);
    assert_eq!(sh[3 + 1], 10.0 + 3.0, "k=1, channel 1");
    assert_eq!(sh[3 * 3 + 2], 10.0 + 8.0, "k=3, channel 2");
    assert_eq!(s.meta.ids, vec![0, 1]);
    assert_eq!(s.meta.survey, vec![0, 0]);
}

#[test]
fn point_clouds_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("points.ply");
    let cloud = PointCloud {
        positions: vec![Vec3::new(1.0, -2.0, 3.5), Vec3::new(-0.0, 1e-20, 7.0)],
        colours: vec![[1, 2, 3], [255, 128, 0]],
    };
    write_point_cloud(&path, &cloud).unwrap();
    assert_eq!(read_point_cloud(&path).unwrap(), cloud);
}

#[test]
fn the_bench_points_load() {
    let Some(bench) = shared_data::path("fox_bench_ds8/points.ply") else {
        return;
    };
    let points = read_point_cloud(&bench).unwrap();
    assert_eq!(points.len(), 20_000);
    assert!(points.positions.iter().all(|p| p.is_finite()));
}
