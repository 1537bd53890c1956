//! Runtime CPU-feature dispatch shared by the CPU hot loops (rasterizer, SSIM, Adam).

/// How a kernel computes `a · b + c`: kernels generic over it are built with [`Fused`] (one
/// rounding, one instruction) in the AVX builds and with [`Separate`] (two roundings) in the
/// baseline one, where `f32::mul_add` would be a libm call per lane. Both directions of a
/// computation that must agree bit for bit run in the same build. Call it from
/// `#[inline(always)]` functions, not from large closures: a closure LLVM keeps out of line is
/// compiled for the baseline CPU, where each `mul_add` becomes that libm call (10× slower).
pub(crate) trait MulAdd {
    fn mul_add(a: f32, b: f32, c: f32) -> f32;
}

/// `a · b + c` rounded once (an FMA instruction where the build enables `fma`).
pub(crate) struct Fused;

/// `a · b + c` rounded twice: the multiply, then the add.
pub(crate) struct Separate;

impl MulAdd for Fused {
    #[inline(always)]
    fn mul_add(a: f32, b: f32, c: f32) -> f32 {
        a.mul_add(b, c)
    }
}

impl MulAdd for Separate {
    #[inline(always)]
    fn mul_add(a: f32, b: f32, c: f32) -> f32 {
        a * b + c
    }
}

/// Defines `$name`, which runs the `#[inline(always)]` kernel `$kernel` compiled for AVX-512VL
/// or else AVX2 (both with FMA and POPCNT) when the CPU has it (8-lane vectors instead of baseline SSE2's
/// 4), and the baseline build otherwise. Kernels that add in a fixed order and use no FMA give
/// the same bits on every path. A kernel written `$kernel::<MulAdd>` is generic over
/// [`MulAdd`]: it gets [`Fused`] in the AVX builds and [`Separate`] in the baseline one, so its
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
        $name:ident => $kernel:ident :: <MulAdd> ( $($arg:ident : $ty:ty),* $(,)? ) $(-> $ret:ty)?
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
                // `a * b + c` into an FMA: only explicit `MulAdd::mul_add` calls become one.
                #[target_feature(enable = "avx2,fma,popcnt,avx512f,avx512vl")]
                #[allow(clippy::too_many_arguments)]
                fn avx512($($arg: $ty),*) $(-> $ret)? {
                    $($fast)*($($arg),*)
                }
                let avx2_fma = std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                    && std::arch::is_x86_feature_detected!("popcnt");
                if avx2_fma
                    && std::arch::is_x86_feature_detected!("avx512f")
                    && std::arch::is_x86_feature_detected!("avx512vl")
                {
                    // SAFETY: the CPU supports AVX2, FMA, POPCNT, AVX-512F and AVX-512VL
                    // (checked just above), every feature this build enables.
                    return unsafe { avx512($($arg),*) };
                }
                if avx2_fma {
                    // SAFETY: the CPU supports AVX2, FMA and POPCNT (checked just above).
                    return unsafe { avx2($($arg),*) };
                }
            }
            $($base)*($($arg),*)
        }
    };
}

pub(crate) use simd_dispatch;
