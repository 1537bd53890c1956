//! Runtime CPU-feature dispatch shared by the CPU hot loops (rasterizer, SSIM, Adam).
//!
//! The build a kernel runs is the best the CPU has, or a lower one named in the
//! `DAMAGE_TWIN_SIMD` environment variable (`avx512`, `avx2` or `baseline`), read once per
//! process. The lower builds are what machines without AVX-512 or AVX2 run; the variable lets
//! the tests check them and the benchmarks time them on any machine.

use std::sync::OnceLock;

/// The environment variable that caps the SIMD build (see the module docs).
pub const SIMD_ENV: &str = "DAMAGE_TWIN_SIMD";

/// A build of the dispatched kernels, lowest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum SimdLevel {
    /// The target's baseline (SSE2 on x86-64): 4-lane vectors, separate multiply and add.
    Baseline,
    /// AVX2 with FMA and POPCNT: 8-lane vectors, fused multiply-adds.
    Avx2,
    /// The AVX2 code with AVX-512F/VL encodings: 32 vector registers and mask registers.
    Avx512,
}

impl SimdLevel {
    /// The name `DAMAGE_TWIN_SIMD` takes for this build.
    pub fn name(self) -> &'static str {
        match self {
            SimdLevel::Baseline => "baseline",
            SimdLevel::Avx2 => "avx2",
            SimdLevel::Avx512 => "avx512",
        }
    }

    /// Reads a build's name (case-insensitive); `None` for anything else.
    pub fn parse(name: &str) -> Option<SimdLevel> {
        [SimdLevel::Baseline, SimdLevel::Avx2, SimdLevel::Avx512]
            .into_iter()
            .find(|level| level.name().eq_ignore_ascii_case(name.trim()))
    }

    /// The best build this CPU can run.
    pub fn detected() -> SimdLevel {
        #[cfg(target_arch = "x86_64")]
        {
            let avx2_fma = std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
                && std::arch::is_x86_feature_detected!("popcnt");
            if avx2_fma
                && std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vl")
            {
                return SimdLevel::Avx512;
            }
            if avx2_fma {
                return SimdLevel::Avx2;
            }
        }
        SimdLevel::Baseline
    }
}

/// The build the dispatched kernels run in this process: [`SimdLevel::detected`], capped by
/// `DAMAGE_TWIN_SIMD` when it names a build. Never above what the CPU has, which is what
/// makes the dispatch's `unsafe` calls sound.
pub fn simd_level() -> SimdLevel {
    static LEVEL: OnceLock<SimdLevel> = OnceLock::new();
    *LEVEL.get_or_init(|| {
        let requested = std::env::var(SIMD_ENV).ok();
        level_for(SimdLevel::detected(), requested.as_deref())
    })
}

/// The build to run on a CPU that has `detected`, given the variable's value: the named build
/// capped at the CPU's, or the CPU's when the value names none ([`environment_warning`] says so).
fn level_for(detected: SimdLevel, requested: Option<&str>) -> SimdLevel {
    requested
        .and_then(SimdLevel::parse)
        .map_or(detected, |level| level.min(detected))
}

/// What is wrong with `DAMAGE_TWIN_SIMD`, if anything: a value that names no build, or a build
/// this CPU cannot run (it then runs its best). For the clients to show; `None` when unset.
pub fn environment_warning() -> Option<String> {
    let requested = std::env::var(SIMD_ENV).ok();
    warning_for(SimdLevel::detected(), requested.as_deref())
}

fn warning_for(detected: SimdLevel, requested: Option<&str>) -> Option<String> {
    let requested = requested?;
    match SimdLevel::parse(requested) {
        None if requested.trim().is_empty() => None,
        None => Some(format!(
            "{SIMD_ENV}={requested:?} names no SIMD build (avx512, avx2 or baseline); \
             running {}",
            detected.name()
        )),
        Some(level) if level > detected => Some(format!(
            "{SIMD_ENV}={requested}, but this CPU runs at most {}; running that",
            detected.name()
        )),
        Some(_) => None,
    }
}

/// The arithmetic a build compiles to, where the builds differ: `a · b + c`, and `floor` /
/// `ceil`. Kernels generic over it are built with [`Fused`] in the AVX builds and with
/// [`Separate`] in the baseline one. Both directions of a computation that must agree bit for
/// bit run in the same build. Call it from `#[inline(always)]` functions, not from large
/// closures: a closure LLVM keeps out of line is compiled for the baseline CPU, where each
/// `mul_add` becomes a libm call (10× slower).
pub(crate) trait Arith {
    /// `a · b + c`; its rounding depends on the build.
    fn mul_add(a: f32, b: f32, c: f32) -> f32;
    /// `x.floor()`, the same bits in every build.
    fn floor(x: f32) -> f32;
    /// `x.ceil()`, the same bits in every build.
    fn ceil(x: f32) -> f32;
}

/// The AVX builds: `a · b + c` rounded once (an FMA instruction), `floor` and `ceil` one
/// rounding instruction each.
pub(crate) struct Fused;

/// The baseline build: `a · b + c` rounded twice (the multiply, then the add), since
/// `f32::mul_add` would be a libm call per lane. On x86-64 without SSE4.1 `f32::floor` and
/// `f32::ceil` are libm calls too, which keep the loops around them from vectorising; there
/// they are computed with adds and compares instead.
pub(crate) struct Separate;

impl Arith for Fused {
    #[inline(always)]
    fn mul_add(a: f32, b: f32, c: f32) -> f32 {
        a.mul_add(b, c)
    }
    #[inline(always)]
    fn floor(x: f32) -> f32 {
        x.floor()
    }
    #[inline(always)]
    fn ceil(x: f32) -> f32 {
        x.ceil()
    }
}

/// Whether this target's baseline lacks a rounding instruction (`roundps`, SSE4.1).
const NO_ROUND_INSTRUCTION: bool =
    cfg!(all(target_arch = "x86_64", not(target_feature = "sse4.1")));

impl Arith for Separate {
    #[inline(always)]
    fn mul_add(a: f32, b: f32, c: f32) -> f32 {
        a * b + c
    }
    #[inline(always)]
    fn floor(x: f32) -> f32 {
        if NO_ROUND_INSTRUCTION {
            floor_by_adds(x)
        } else {
            x.floor()
        }
    }
    #[inline(always)]
    fn ceil(x: f32) -> f32 {
        if NO_ROUND_INSTRUCTION {
            -floor_by_adds(-x)
        } else {
            x.ceil()
        }
    }
}

/// `x.floor()` with the same bits (signed zeros, infinities and NaN included), from adds,
/// compares and selects that vectorise with SSE2.
#[inline(always)]
fn floor_by_adds(x: f32) -> f32 {
    // 2^23: every f32 of at least this magnitude is an integer, and adding then subtracting it
    // rounds a smaller magnitude to the nearest integer (ties to even).
    const TWO_POW_23: f32 = 8_388_608.0;
    let magnitude = x.abs();
    let nearest = ((magnitude + TWO_POW_23) - TWO_POW_23).copysign(x);
    // `<` is false for NaN and the infinities: they, and the large integers, stay as they are.
    let nearest = if magnitude < TWO_POW_23 { nearest } else { x };
    if nearest > x { nearest - 1.0 } else { nearest }
}

/// Defines `$name`, which runs the `#[inline(always)]` kernel `$kernel` compiled for AVX-512VL
/// or else AVX2 (both with FMA and POPCNT) as [`simd_level`] says (8-lane vectors instead of
/// baseline SSE2's 4), and the baseline build otherwise. Kernels that add in a fixed order and
/// use no FMA give the same bits on every path. A kernel written `$kernel::<Arith>` is generic over
/// [`Arith`]: it gets [`Fused`] in the AVX builds and [`Separate`] in the baseline one, so its
/// bits depend on the CPU (still the same for any thread count on one machine).
/// Attributes and doc comments before `$name` are kept.
macro_rules! simd_dispatch {
    (
        $(#[$meta:meta])*
        $name:ident => $kernel:ident ( $($arg:ident : $ty:ty),* $(,)? ) $(-> $ret:ty)?
    ) => {
        $crate::simd::simd_dispatch!(@build [$(#[$meta])*] $name
            [$kernel] [$kernel] ($($arg : $ty),*) $(-> $ret)?);
    };
    (
        $(#[$meta:meta])*
        $name:ident => $kernel:ident :: <Arith> ( $($arg:ident : $ty:ty),* $(,)? ) $(-> $ret:ty)?
    ) => {
        $crate::simd::simd_dispatch!(@build [$(#[$meta])*] $name
            [$kernel::<$crate::simd::Fused>] [$kernel::<$crate::simd::Separate>]
            ($($arg : $ty),*) $(-> $ret)?);
    };
    (
        @build [$(#[$meta:meta])*] $name:ident [$($fast:tt)*] [$($base:tt)*]
        ( $($arg:ident : $ty:ty),* ) $(-> $ret:ty)?
    ) => {
        $(#[$meta])*
        #[allow(clippy::too_many_arguments)]
        fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2,fma,popcnt")]
                #[allow(clippy::too_many_arguments)]
                fn avx2($($arg: $ty),*) $(-> $ret)? {
                    $($fast)*($($arg),*)
                }
                // The same 8-lane code with AVX-512VL's encodings: 32 vector registers instead
                // of 16 (the blend loops keep their polynomial constants in registers instead
                // of reloading them) and mask registers for the compares. Rust never contracts
                // `a * b + c` into an FMA: only explicit `Arith::mul_add` calls become one.
                #[target_feature(enable = "avx2,fma,popcnt,avx512f,avx512vl")]
                #[allow(clippy::too_many_arguments)]
                fn avx512($($arg: $ty),*) $(-> $ret)? {
                    $($fast)*($($arg),*)
                }
                match $crate::simd::simd_level() {
                    // SAFETY: `simd_level` returns `Avx512` only when the CPU supports AVX2,
                    // FMA, POPCNT, AVX-512F and AVX-512VL, every feature this build enables.
                    $crate::simd::SimdLevel::Avx512 => return unsafe { avx512($($arg),*) },
                    // SAFETY: `simd_level` returns `Avx2` only when the CPU supports AVX2, FMA
                    // and POPCNT.
                    $crate::simd::SimdLevel::Avx2 => return unsafe { avx2($($arg),*) },
                    $crate::simd::SimdLevel::Baseline => {}
                }
            }
            $($base)*($($arg),*)
        }
    };
}

pub(crate) use simd_dispatch;

/// For tests: runs the named tests of the current test binary (full names, as `--exact` takes
/// them) once per SIMD build below [`SimdLevel::detected`], with `DAMAGE_TWIN_SIMD` set to
/// that build, and panics with the child's output unless every named test ran and passed. A
/// test suite checked this way covers the kernels that machines without AVX-512 or AVX2 run.
#[doc(hidden)]
pub fn rerun_tests_on_lower_builds(tests: &[&str]) {
    let exe = std::env::current_exe().expect("the test binary's path");
    let lower = [SimdLevel::Avx2, SimdLevel::Baseline]
        .into_iter()
        .filter(|&level| level < SimdLevel::detected());
    for level in lower {
        let output = std::process::Command::new(&exe)
            .args(tests)
            .arg("--exact")
            .env(SIMD_ENV, level.name())
            .output()
            .expect("the test binary runs");
        let stdout = String::from_utf8_lossy(&output.stdout);
        let all_passed = format!("test result: ok. {} passed", tests.len());
        assert!(
            output.status.success() && stdout.contains(&all_passed),
            "with {SIMD_ENV}={}, expected {all_passed}; got:\n{stdout}\n{}",
            level.name(),
            String::from_utf8_lossy(&output.stderr)
        );
    }
}

/// For tests: asserts that [`simd_level`] is the build `DAMAGE_TWIN_SIMD` asks for, capped at
/// the CPU's, so that a rerun with the variable set really ran the lower build.
#[doc(hidden)]
pub fn assert_level_follows_the_environment() {
    let requested = std::env::var(SIMD_ENV).ok();
    let expected = level_for(SimdLevel::detected(), requested.as_deref());
    assert_eq!(simd_level(), expected, "{SIMD_ENV}={requested:?}");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_variable_caps_the_build_and_never_raises_it() {
        use SimdLevel::*;
        assert_eq!(level_for(Avx512, None), Avx512);
        assert_eq!(level_for(Avx512, Some("")), Avx512);
        assert_eq!(level_for(Avx512, Some("avx2")), Avx2);
        assert_eq!(level_for(Avx512, Some(" Baseline ")), Baseline);
        assert_eq!(level_for(Avx2, Some("avx512")), Avx2);
        assert_eq!(level_for(Baseline, Some("avx2")), Baseline);
        assert_eq!(level_for(Avx2, Some("sse9")), Avx2);
    }

    #[test]
    fn a_value_that_names_no_build_or_too_high_a_build_is_reported() {
        use SimdLevel::*;
        assert_eq!(warning_for(Avx512, None), None);
        assert_eq!(warning_for(Avx512, Some(" ")), None);
        assert_eq!(warning_for(Avx512, Some("avx2")), None);
        assert_eq!(warning_for(Avx2, Some("avx2")), None);
        let unknown = warning_for(Avx2, Some("sse9")).expect("a warning");
        assert!(
            unknown.contains("\"sse9\"") && unknown.ends_with("running avx2"),
            "{unknown}"
        );
        let too_high = warning_for(Avx2, Some("avx512")).expect("a warning");
        assert!(too_high.contains("at most avx2"), "{too_high}");
    }

    #[test]
    fn floor_and_ceil_by_adds_give_the_standard_bits() {
        let mut values = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            0.49999997,
            -0.49999997,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            16_777_217.0,
            1e30,
            -1e30,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            1e-45,
            -1e-45,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
        ];
        let mut rng = fastrand::Rng::with_seed(7);
        for _ in 0..100_000 {
            values.push((rng.f32() - 0.5) * 64.0);
            values.push(f32::from_bits(rng.u32(..)));
        }
        for x in values {
            let ceil = -floor_by_adds(-x);
            if x.is_nan() {
                assert!(floor_by_adds(x).is_nan() && ceil.is_nan());
                continue;
            }
            assert_eq!(
                floor_by_adds(x).to_bits(),
                x.floor().to_bits(),
                "floor({x:e})"
            );
            assert_eq!(ceil.to_bits(), x.ceil().to_bits(), "ceil({x:e})");
            for build in [<Fused as Arith>::floor(x), <Separate as Arith>::floor(x)] {
                assert_eq!(build.to_bits(), x.floor().to_bits(), "floor({x:e})");
            }
        }
    }

    #[test]
    fn names_round_trip() {
        for level in [SimdLevel::Baseline, SimdLevel::Avx2, SimdLevel::Avx512] {
            assert_eq!(SimdLevel::parse(level.name()), Some(level));
        }
        assert_eq!(SimdLevel::parse("avx"), None);
    }

    #[test]
    fn the_build_follows_the_environment() {
        assert_level_follows_the_environment();
    }

    /// The training kernels' own checks (SSIM, losses, Adam) and the rasterizer's unit tests,
    /// on the builds below this CPU's.
    #[test]
    fn kernel_checks_pass_on_the_lower_builds() {
        rerun_tests_on_lower_builds(&[
            "simd::tests::the_build_follows_the_environment",
            "train::ssim::tests::every_band_height_gives_the_same_bits",
            "train::loss::tests::fast_ssim_matches_the_metric",
            "train::loss::tests::photometric_gradient_matches_finite_differences",
            "train::loss::tests::region_gradient_matches_finite_differences_and_is_zero_outside",
            "train::adam::tests::steps_match_torch_adam",
            "train::adam::tests::both_sh_groups_in_one_pass_match_one_group_at_a_time",
            "raster::tests::blend_backward_matches_finite_differences_in_screen_space",
            "raster::tests::forward_matches_a_per_pixel_loop_on_edge_tiles",
            "raster::tests::blend_backward_matches_the_reference_in_screen_space",
            "raster::bin::tests::bins_are_sorted_by_tile_then_depth",
        ]);
    }
}
