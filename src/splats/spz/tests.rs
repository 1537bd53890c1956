//! Unit tests of `splats::spz` (kept apart: the codec alone is ~560 lines).

use super::*;
use crate::splats::sh::sh_basis;
use glam::Mat3;

/// Deterministic splats spread over the ranges SPZ encodes.
fn splats(sh_degree: u32, n: usize, seed: u64) -> Splats {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut s = Splats::empty(sh_degree, 0);
    let k = s.sh_coeffs();
    for g in 0..n {
        let mut r = |lo: f32, hi: f32| lo + (hi - lo) * rng.f32();
        let mean = Vec3::new(r(-100.0, 100.0), r(-100.0, 100.0), r(-100.0, 100.0));
        let log_scale = Vec3::new(r(-9.0, 5.0), r(-9.0, 5.0), r(-9.0, 5.0));
        let rotation = Quat::from_xyzw(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0));
        let mut sh: Vec<f32> = (0..k * 3).map(|_| r(-0.99, 0.99)).collect();
        for dc in &mut sh[..3] {
            *dc = r(-3.0, 3.0);
        }
        s.push(
            mean,
            log_scale,
            rotation,
            r(-8.0, 8.0),
            &sh,
            &[],
            g as u64,
            0,
        );
    }
    s
}

fn round_trip(s: &Splats, version: SpzVersion) -> (Splats, SpzHeader) {
    let (bytes, header) = encode(s, &SpzOptions::new(version)).expect("encodes");
    let (back, read_header) = decode(&bytes).expect("decodes");
    assert_eq!(header, read_header);
    assert_eq!(back.len(), s.len());
    assert_eq!(back.sh_degree, s.sh_degree);
    (back, header)
}

/// Angle in radians between the rotations of two quaternions (either normalised or not).
fn angle(a: Quat, b: Quat) -> f32 {
    let d = a.normalize().dot(b.normalize()).abs().min(1.0);
    2.0 * d.acos()
}

#[test]
fn flip_tables_are_a_half_turn_about_x() {
    let f = Mat3::from_diagonal(FLIP_POSITION);
    let mut rng = fastrand::Rng::with_seed(1);
    for _ in 0..100 {
        let d = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5).normalize();
        let (mut plain, mut flipped) = ([0.0; 16], [0.0; 16]);
        sh_basis(3, d, &mut plain);
        sh_basis(3, f * d, &mut flipped);
        for k in 1..16 {
            assert!(
                (flipped[k] - FLIP_SH[k - 1] * plain[k]).abs() < 1e-5,
                "k = {k}"
            );
        }
        let q = Quat::from_xyzw(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5, 0.7).normalize();
        let want = f * Mat3::from_quat(q) * f;
        let got = Mat3::from_quat(flip_quat(q));
        assert!(got.abs_diff_eq(want, 1e-6));
    }
}

#[test]
fn positions_come_back_within_half_a_fixed_point_step() {
    let s = splats(0, 2000, 2);
    let (back, header) = round_trip(&s, SpzVersion::V3);
    assert_eq!(header.fractional_bits, DEFAULT_FRACTIONAL_BITS);
    // Half a step, plus f32 rounding of a value near 100 (ulp 7.6e-6).
    let bound = 0.5 * header.position_step() + 1e-5;
    for (a, b) in s.means.iter().zip(&back.means) {
        assert!((*a - *b).abs().max_element() <= bound, "{a} vs {b}");
    }
}

#[test]
fn large_scenes_get_fewer_fractional_bits_not_wrapped_positions() {
    let mut s = splats(0, 50, 3);
    s.means[7] = Vec3::new(5000.0, -3000.5, 12.25);
    let (back, header) = round_trip(&s, SpzVersion::V3);
    // 5000 · 2^10 < 2^23 ≤ 5000 · 2^11.
    assert_eq!(header.fractional_bits, 10);
    assert!((back.means[7] - s.means[7]).abs().max_element() <= 0.5 / 1024.0 + 1e-4);
    assert!(fractional_bits_for(9.0e6).is_err());
    assert_eq!(fractional_bits_for(0.0), Ok(DEFAULT_FRACTIONAL_BITS));
}

#[test]
fn rotations_come_back_within_a_small_angle() {
    let s = splats(0, 5000, 4);
    let (v3, _) = round_trip(&s, SpzVersion::V3);
    let worst = |back: &Splats| {
        s.rotations
            .iter()
            .zip(&back.rotations)
            .map(|(&a, &b)| angle(a, b))
            .fold(0.0f32, f32::max)
    };
    // Measured 0.0037 rad (0.21°) worst over these 5000: each stored component is within
    // √½/1022 of the truth, and the angle is twice the quaternion's distance.
    let v3_worst = worst(&v3);
    assert!(v3_worst < 0.005, "v3 worst {v3_worst} rad");
    for q in &v3.rotations {
        assert!((q.length() - 1.0).abs() < 1e-5);
    }
    // Version 2 derives w from x, y, z, which is ill-conditioned as w → 0: measured
    // 0.173 rad (9.9°) worst over all 5000, 0.038 rad (2.2°) where |w| ≥ 0.3.
    let (v2, _) = round_trip(&s, SpzVersion::V2);
    assert!(worst(&v2) < 0.25, "v2 worst {}", worst(&v2));
    let v2_typical = s
        .rotations
        .iter()
        .zip(&v2.rotations)
        .filter(|(a, _)| a.normalize().w.abs() >= 0.3)
        .map(|(&a, &b)| angle(a, b))
        .fold(0.0f32, f32::max);
    assert!(
        v2_typical < 0.05,
        "v2 worst where |w| ≥ 0.3: {v2_typical} rad"
    );
}

#[test]
fn scales_opacities_and_colours_come_back_within_half_a_byte() {
    let s = splats(0, 2000, 5);
    let (back, _) = round_trip(&s, SpzVersion::V3);
    for g in 0..s.len() {
        let ds = (s.log_scales[g] - back.log_scales[g]).abs().max_element();
        assert!(ds <= 0.5 / 16.0 + 1e-6, "log scale {g}: {ds}");
        let da = (sigmoid(s.raw_opacities[g]) - sigmoid(back.raw_opacities[g])).abs();
        assert!(da <= 0.5 / 255.0 + 1e-6, "opacity {g}: {da}");
        for c in 0..3 {
            let dc = (s.sh_of(g)[c] - back.sh_of(g)[c]).abs();
            assert!(dc <= 0.5 / (COLOR_SCALE * 255.0) + 1e-5, "DC {g}/{c}: {dc}");
        }
    }
    // Out-of-range values clamp to the ends of the byte, and alpha 0/255 decode finite.
    let mut edge = splats(0, 2, 6);
    edge.log_scales[0] = Vec3::new(-20.0, 9.0, 0.0);
    edge.raw_opacities = vec![-40.0, 40.0];
    let (back, _) = round_trip(&edge, SpzVersion::V3);
    assert_eq!(
        back.log_scales[0],
        Vec3::new(-10.0, 255.0 / 16.0 - 10.0, 0.0)
    );
    assert!(back.raw_opacities.iter().all(|v| v.is_finite()));
    assert!(sigmoid(back.raw_opacities[0]) < 1e-5 && sigmoid(back.raw_opacities[1]) > 0.99999);
}

#[test]
fn sh_rest_comes_back_within_its_buckets() {
    let s = splats(3, 2000, 7);
    let (back, _) = round_trip(&s, SpzVersion::V3);
    let (mut worst1, mut worst_rest) = (0.0f32, 0.0f32);
    for g in 0..s.len() {
        for j in 1..16 {
            for c in 0..3 {
                let d = (s.sh_of(g)[j * 3 + c] - back.sh_of(g)[j * 3 + c]).abs();
                if j < 4 {
                    worst1 = worst1.max(d);
                } else {
                    worst_rest = worst_rest.max(d);
                }
            }
        }
    }
    // Rounding (½) plus half a bucket (4 or 8), in units of 1/128.
    assert!(worst1 <= 4.5 / 128.0 + 1e-6, "degree 1: {worst1}");
    assert!(
        worst_rest <= 8.5 / 128.0 + 1e-6,
        "degrees 2-3: {worst_rest}"
    );
    // Zero stays exactly zero (128 is a bucket centre).
    assert_eq!(quantize_sh(0.0, 16), 128);
    // All 8 bits kept: only the rounding is left.
    let options = SpzOptions {
        sh_bits: [8, 8],
        ..SpzOptions::default()
    };
    let (back, _) = decode(&encode(&s, &options).unwrap().0).unwrap();
    let worst = (0..s.sh.len())
        .filter(|i| i % (16 * 3) >= 3)
        .map(|i| (s.sh[i] - back.sh[i]).abs())
        .fold(0.0f32, f32::max);
    assert!(worst <= 0.5 / 128.0 + 1e-6, "8 bits: {worst}");
    let options = SpzOptions {
        sh_bits: [0, 4],
        ..SpzOptions::default()
    };
    assert_eq!(
        encode(&s, &options).unwrap_err(),
        SpzProblem::ShBits([0, 4])
    );
}

#[test]
fn the_header_and_layout_are_the_references() {
    let s = splats(1, 3, 8);
    let (bytes, _) = encode(&s, &SpzOptions::new(SpzVersion::V2)).unwrap();
    let mut raw = Vec::new();
    GzDecoder::new(&bytes[..]).read_to_end(&mut raw).unwrap();
    assert_eq!(&raw[..4], b"NGSP");
    assert_eq!(&raw[4..16], &[2, 0, 0, 0, 3, 0, 0, 0, 1, 12, 0, 0]);
    // 3 · (9 position + 1 alpha + 3 colour + 3 scale + 3 rotation + 9 SH) bytes.
    assert_eq!(raw.len(), 16 + 3 * 28);
    // The first position: x as written, y negated (RDF → RUB), 12 fractional bits.
    let x = i32::from_le_bytes([0, raw[16], raw[17], raw[18]]) >> 8;
    let y = i32::from_le_bytes([0, raw[19], raw[20], raw[21]]) >> 8;
    assert_eq!(x, (s.means[0].x * 4096.0).round() as i32);
    assert_eq!(y, (-s.means[0].y * 4096.0).round() as i32);
}

fn gzip(raw: &[u8]) -> Vec<u8> {
    let mut gz = GzEncoder::new(Vec::new(), Compression::fast());
    gz.write_all(raw).unwrap();
    gz.finish().unwrap()
}

fn raw_of(s: &Splats) -> Vec<u8> {
    let (bytes, _) = encode(s, &SpzOptions::default()).unwrap();
    let mut raw = Vec::new();
    GzDecoder::new(&bytes[..]).read_to_end(&mut raw).unwrap();
    raw
}

#[test]
fn a_header_that_lies_is_refused_before_anything_is_sized_from_it() {
    let raw = raw_of(&splats(2, 10, 9));
    // One more Gaussian than the data holds.
    let mut lie = raw.clone();
    lie[8..12].copy_from_slice(&11u32.to_le_bytes());
    assert!(matches!(
        decode(&gzip(&lie)),
        Err(SpzProblem::LengthMismatch { points: 11, actual, .. }) if actual == raw.len() - 16
    ));
    // Ten million and one: refused from the header alone.
    lie[8..12].copy_from_slice(&10_000_001u32.to_le_bytes());
    assert_eq!(
        decode(&gzip(&lie)).unwrap_err(),
        SpzProblem::TooManyPoints(10_000_001)
    );
    // Ten million: allowed by the cap, so the stream must hold 10 M Gaussians' bytes; it is
    // read only as far as it goes.
    lie[8..12].copy_from_slice(&10_000_000u32.to_le_bytes());
    assert!(matches!(
        decode(&gzip(&lie)),
        Err(SpzProblem::LengthMismatch { .. })
    ));
    // Fewer than promised and more than promised.
    let mut short = raw.clone();
    short.pop();
    assert!(matches!(
        decode(&gzip(&short)),
        Err(SpzProblem::LengthMismatch { .. })
    ));
    let mut long = raw.clone();
    long.push(0);
    assert!(matches!(
        decode(&gzip(&long)),
        Err(SpzProblem::LengthMismatch { .. })
    ));
    let mut bad = raw.clone();
    bad[0] = b'X';
    assert!(matches!(decode(&gzip(&bad)), Err(SpzProblem::BadMagic(_))));
    let mut bad = raw.clone();
    bad[4] = 4;
    assert_eq!(
        decode(&gzip(&bad)).unwrap_err(),
        SpzProblem::UnsupportedVersion(4)
    );
    let mut bad = raw.clone();
    bad[12] = 4;
    assert_eq!(decode(&gzip(&bad)).unwrap_err(), SpzProblem::ShDegree(4));
    let mut bad = raw.clone();
    bad[14] = FLAG_EXTENSIONS;
    assert_eq!(decode(&gzip(&bad)).unwrap_err(), SpzProblem::Extensions);
    assert_eq!(
        decode(&gzip(&raw[..10])).unwrap_err(),
        SpzProblem::ShortHeader(10)
    );
}

#[test]
fn truncated_or_foreign_bytes_are_refused() {
    let (bytes, _) = encode(&splats(3, 200, 10), &SpzOptions::default()).unwrap();
    for cut in [0, 5, 20, bytes.len() / 2, bytes.len() - 1] {
        let result = decode(&bytes[..cut]);
        assert!(
            matches!(
                result,
                Err(SpzProblem::Gzip(_) | SpzProblem::ShortHeader(_))
            ),
            "cut at {cut}: {result:?}"
        );
    }
    assert!(matches!(
        decode(b"ply\nformat ascii"),
        Err(SpzProblem::Gzip(_))
    ));
}

#[test]
fn mutated_files_decode_or_fail_without_panicking() {
    let s = splats(3, 40, 13);
    let raw = raw_of(&s);
    let (compressed, _) = encode(&s, &SpzOptions::default()).unwrap();
    let mut rng = fastrand::Rng::with_seed(14);
    for round in 0..400 {
        // Odd rounds mutate the stream as stored, even rounds the data inside it.
        let mut bytes = if round % 2 == 1 {
            compressed.clone()
        } else {
            raw.clone()
        };
        for _ in 0..rng.usize(1..6) {
            let i = rng.usize(..bytes.len());
            bytes[i] = rng.u8(..);
        }
        if rng.bool() {
            bytes.truncate(rng.usize(..=bytes.len()));
        }
        let bytes = if round % 2 == 1 { bytes } else { gzip(&bytes) };
        if let Ok((back, header)) = decode(&bytes) {
            assert_eq!(back.len(), header.points as usize);
            assert!(back.check_lengths().is_ok());
            assert!(back.means.iter().all(|m| m.is_finite()));
            assert!(back.raw_opacities.iter().all(|v| v.is_finite()));
        }
    }
}

#[test]
fn models_spz_cannot_hold_are_refused_on_write() {
    let mut s = splats(0, 3, 11);
    s.raw_opacities[1] = f32::NAN;
    assert_eq!(
        encode(&s, &SpzOptions::default()).unwrap_err(),
        SpzProblem::NonFinite {
            gaussian: 1,
            what: "opacity"
        }
    );
    let mut s = splats(0, 3, 11);
    s.rotations[2] = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
    assert_eq!(
        encode(&s, &SpzOptions::default()).unwrap_err(),
        SpzProblem::ZeroRotation { gaussian: 2 }
    );
    // Rotations whose squared length leaves f32's range still encode: only all zeros fail.
    let mut s = splats(0, 2, 11);
    let turn = Quat::from_rotation_y(1.0);
    s.rotations = vec![turn * 1.0e30, turn * 1.0e-30];
    let (back, _) = round_trip(&s, SpzVersion::V3);
    assert!(back.rotations.iter().all(|q| angle(*q, turn) < 0.005));
    let mut s = splats(0, 3, 11);
    s.means[0].z = 1.0e7;
    assert!(matches!(
        encode(&s, &SpzOptions::default()),
        Err(SpzProblem::PositionRange(_))
    ));
    let mut s = splats(0, 3, 11);
    s.sh.pop();
    assert!(matches!(
        encode(&s, &SpzOptions::default()),
        Err(SpzProblem::Inconsistent(_))
    ));
}

#[test]
fn file_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.spz");
    let s = splats(3, 100, 12);
    let (header, size) = write_spz(&path, &s, &SpzOptions::default()).unwrap();
    assert_eq!(size, std::fs::metadata(&path).unwrap().len());
    let (back, read_header) = read_spz(&path).unwrap();
    assert_eq!((back.len(), read_header), (100, header));

    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let message = read_spz(&path).unwrap_err().to_string();
    assert!(
        message.starts_with(&path.display().to_string()),
        "{message}"
    );
    let missing = dir.path().join("missing.spz");
    let message = read_spz(&missing).unwrap_err().to_string();
    assert!(message.contains("missing.spz"), "{message}");
    let mut bad = s.clone();
    bad.means[3].x = f32::INFINITY;
    let message = write_spz(&path, &bad, &SpzOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("model.spz") && message.contains("Gaussian 3"),
        "{message}"
    );
}
