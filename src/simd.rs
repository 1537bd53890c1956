//! Runtime CPU-feature dispatch shared by the CPU hot loops (rasterizer, SSIM, Adam).

/// Defines `$name`, which runs the `#[inline(always)]` kernel `$kernel` compiled for AVX-512VL
/// or else AVX2 when the CPU has it (8-lane vectors instead of baseline SSE2's 4), and the
/// baseline build otherwise. Kernels that add in a fixed order and use no FMA give the same bits
/// on every path.
/// Attributes and doc comments before `$name` are kept.
macro_rules! simd_dispatch {
    (
        $(#[$meta:meta])*
        $name:ident => $kernel:ident ( $($arg:ident : $ty:ty),* $(,)? ) $(-> $ret:ty)?
    ) => {
        $(#[$meta])*
        #[allow(clippy::too_many_arguments)]
        fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                #[allow(clippy::too_many_arguments)]
                fn avx2($($arg: $ty),*) $(-> $ret)? {
                    $kernel($($arg),*)
                }
                // The same 8-lane code with AVX-512VL's encodings: 32 vector registers instead
                // of 16 (the blend loops keep their polynomial constants in registers instead
                // of reloading them) and mask registers for the compares. Still no FMA
                // contraction (Rust never fuses), so the bits match the other paths.
                #[target_feature(enable = "avx2,avx512f,avx512vl")]
                #[allow(clippy::too_many_arguments)]
                fn avx512($($arg: $ty),*) $(-> $ret)? {
                    $kernel($($arg),*)
                }
                if std::arch::is_x86_feature_detected!("avx512f")
                    && std::arch::is_x86_feature_detected!("avx512vl")
                    && std::arch::is_x86_feature_detected!("avx2")
                {
                    // SAFETY: the CPU supports AVX2, AVX-512F and AVX-512VL (checked just
                    // above), every feature this build enables.
                    return unsafe { avx512($($arg),*) };
                }
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU supports AVX2 (checked just above).
                    return unsafe { avx2($($arg),*) };
                }
            }
            $kernel($($arg),*)
        }
    };
}

pub(crate) use simd_dispatch;
