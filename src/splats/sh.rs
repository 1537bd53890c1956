//! Real spherical harmonics up to degree 3 with the 3DGS basis, sign convention and constants:
//! the raw colour sum of one Gaussian seen from a direction, and its vector-Jacobian products.
//! Pure maths on one Gaussian's coefficients (`[k * 3 + c]`, DC first): no rendering, no clamping.

use glam::Vec3;

pub use super::model::SH_C0;

/// Degree-1 constant `sqrt(3 / (4 pi))`.
pub const SH_C1: f32 = 0.488_602_52;
/// Degree-2 constants (3DGS order).
pub const SH_C2: [f32; 5] = [
    1.092_548_4,
    -1.092_548_4,
    0.315_391_57,
    -1.092_548_4,
    0.546_274_2,
];
/// Degree-3 constants (3DGS order).
pub const SH_C3: [f32; 7] = [
    -0.590_043_6,
    2.890_611_4,
    -0.457_045_8,
    0.373_176_33,
    -0.457_045_8,
    1.445_305_7,
    -0.590_043_6,
];

/// Basis values `Y_k(dir)` for `k < (degree + 1)^2`; `dir` must be unit length. Entries past
/// the degree are left untouched.
#[inline(always)]
pub fn sh_basis(degree: u32, dir: Vec3, out: &mut [f32; 16]) {
    out[0] = SH_C0;
    if degree == 0 {
        return;
    }
    let (x, y, z) = (dir.x, dir.y, dir.z);
    out[1] = -SH_C1 * y;
    out[2] = SH_C1 * z;
    out[3] = -SH_C1 * x;
    if degree == 1 {
        return;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, xz) = (x * y, y * z, x * z);
    out[4] = SH_C2[0] * xy;
    out[5] = SH_C2[1] * yz;
    out[6] = SH_C2[2] * (2.0 * zz - xx - yy);
    out[7] = SH_C2[3] * xz;
    out[8] = SH_C2[4] * (xx - yy);
    if degree == 2 {
        return;
    }
    out[9] = SH_C3[0] * y * (3.0 * xx - yy);
    out[10] = SH_C3[1] * xy * z;
    out[11] = SH_C3[2] * y * (4.0 * zz - xx - yy);
    out[12] = SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
    out[13] = SH_C3[4] * x * (4.0 * zz - xx - yy);
    out[14] = SH_C3[5] * z * (xx - yy);
    out[15] = SH_C3[6] * x * (xx - 3.0 * yy);
}

/// Partial derivatives `dY_k / d(x, y, z)`, treating the components as independent (the caller
/// chains through the normalisation).
#[inline(always)]
fn sh_basis_derivatives(degree: u32, dir: Vec3, out: &mut [Vec3; 16]) {
    out[0] = Vec3::ZERO;
    if degree == 0 {
        return;
    }
    let (x, y, z) = (dir.x, dir.y, dir.z);
    out[1] = Vec3::new(0.0, -SH_C1, 0.0);
    out[2] = Vec3::new(0.0, 0.0, SH_C1);
    out[3] = Vec3::new(-SH_C1, 0.0, 0.0);
    if degree == 1 {
        return;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    out[4] = SH_C2[0] * Vec3::new(y, x, 0.0);
    out[5] = SH_C2[1] * Vec3::new(0.0, z, y);
    out[6] = SH_C2[2] * Vec3::new(-2.0 * x, -2.0 * y, 4.0 * z);
    out[7] = SH_C2[3] * Vec3::new(z, 0.0, x);
    out[8] = SH_C2[4] * Vec3::new(2.0 * x, -2.0 * y, 0.0);
    if degree == 2 {
        return;
    }
    out[9] = SH_C3[0] * Vec3::new(6.0 * x * y, 3.0 * xx - 3.0 * yy, 0.0);
    out[10] = SH_C3[1] * Vec3::new(y * z, x * z, x * y);
    out[11] = SH_C3[2] * Vec3::new(-2.0 * x * y, 4.0 * zz - xx - 3.0 * yy, 8.0 * y * z);
    out[12] = SH_C3[3] * Vec3::new(-6.0 * x * z, -6.0 * y * z, 6.0 * zz - 3.0 * xx - 3.0 * yy);
    out[13] = SH_C3[4] * Vec3::new(4.0 * zz - 3.0 * xx - yy, -2.0 * x * y, 8.0 * x * z);
    out[14] = SH_C3[5] * Vec3::new(2.0 * x * z, -2.0 * y * z, xx - yy);
    out[15] = SH_C3[6] * Vec3::new(3.0 * xx - 3.0 * yy, -6.0 * x * y, 0.0);
}

/// The raw SH sum `sum_k Y_k(dir) c_k` per RGB channel (colour = `max(sum + 0.5, 0)`).
/// `coeffs` holds at least `(degree + 1)^2 * 3` values; `dir` must be unit length.
#[inline(always)]
pub fn eval_sh(degree: u32, coeffs: &[f32], dir: Vec3) -> Vec3 {
    let mut basis = [0.0f32; 16];
    sh_basis(degree, dir, &mut basis);
    eval_sh_from_basis(degree, &basis, coeffs)
}

/// [`eval_sh`] from basis values `sh_basis` already wrote.
// `inline(always)` here and below: the projection calls these from its AVX-compiled kernels,
// and an out-of-line copy would be compiled for the baseline CPU.
#[inline(always)]
pub fn eval_sh_from_basis(degree: u32, basis: &[f32; 16], coeffs: &[f32]) -> Vec3 {
    // A constant count per degree, so that the four partial sums below unroll into registers.
    match degree {
        0 => sum_basis::<1>(basis, coeffs),
        1 => sum_basis::<4>(basis, coeffs),
        2 => sum_basis::<9>(basis, coeffs),
        _ => sum_basis::<16>(basis, coeffs),
    }
}

/// `sum_{k < N} basis[k] c_k` in four interleaved partial sums: one running sum per channel
/// made a chain of N dependent adds, which set the projection's speed. (Locals, not an array
/// indexed by `k % 4`: LLVM kept such an array on the stack, with a store per add.)
#[inline(always)]
fn sum_basis<const N: usize>(basis: &[f32; 16], coeffs: &[f32]) -> Vec3 {
    let coeffs = &coeffs[..N * 3];
    let term = |k: usize| basis[k] * Vec3::new(coeffs[k * 3], coeffs[k * 3 + 1], coeffs[k * 3 + 2]);
    let [mut s0, mut s1, mut s2, mut s3] = [Vec3::ZERO; 4];
    let mut k = 0;
    while k + 4 <= N {
        s0 += term(k);
        s1 += term(k + 1);
        s2 += term(k + 2);
        s3 += term(k + 3);
        k += 4;
    }
    while k < N {
        s0 += term(k);
        k += 1;
    }
    (s0 + s1) + (s2 + s3)
}

/// Backward of [`eval_sh`]: adds `Y_k * v_sum` into `v_coeffs` and returns the gradient with
/// respect to the (unit) direction's components.
#[inline]
pub fn eval_sh_backward(
    degree: u32,
    coeffs: &[f32],
    dir: Vec3,
    v_sum: Vec3,
    v_coeffs: &mut [f32],
) -> Vec3 {
    let mut basis = [0.0f32; 16];
    sh_basis(degree, dir, &mut basis);
    eval_sh_backward_from_basis(degree, &basis, coeffs, dir, v_sum, v_coeffs)
}

/// [`eval_sh_backward`] from the basis values of `dir` (`sh_basis`).
#[inline(always)]
pub fn eval_sh_backward_from_basis(
    degree: u32,
    basis: &[f32; 16],
    coeffs: &[f32],
    dir: Vec3,
    v_sum: Vec3,
    v_coeffs: &mut [f32],
) -> Vec3 {
    // A constant count per degree, as in `eval_sh_from_basis`.
    match degree {
        0 => sh_backward::<1>(0, basis, coeffs, dir, v_sum, v_coeffs),
        1 => sh_backward::<4>(1, basis, coeffs, dir, v_sum, v_coeffs),
        2 => sh_backward::<9>(2, basis, coeffs, dir, v_sum, v_coeffs),
        _ => sh_backward::<16>(3, basis, coeffs, dir, v_sum, v_coeffs),
    }
}

/// [`eval_sh_backward_from_basis`] for `N = (degree + 1)^2` coefficients per channel.
#[inline(always)]
fn sh_backward<const N: usize>(
    degree: u32,
    basis: &[f32; 16],
    coeffs: &[f32],
    dir: Vec3,
    v_sum: Vec3,
    v_coeffs: &mut [f32],
) -> Vec3 {
    let coeffs = &coeffs[..N * 3];
    let v_coeffs = &mut v_coeffs[..N * 3];
    for (k, b) in basis[..N].iter().enumerate() {
        v_coeffs[k * 3] += b * v_sum.x;
        v_coeffs[k * 3 + 1] += b * v_sum.y;
        v_coeffs[k * 3 + 2] += b * v_sum.z;
    }
    if N == 1 {
        return Vec3::ZERO;
    }
    let mut d_basis = [Vec3::ZERO; 16];
    sh_basis_derivatives(degree, dir, &mut d_basis);
    // Two interleaved partial sums (locals, as in `sum_basis`) halve the chain of dependent
    // adds.
    let term = |k: usize| {
        let c = Vec3::new(coeffs[k * 3], coeffs[k * 3 + 1], coeffs[k * 3 + 2]);
        d_basis[k] * c.dot(v_sum)
    };
    let (mut odd, mut even) = (Vec3::ZERO, Vec3::ZERO);
    let mut k = 1;
    while k + 2 <= N {
        odd += term(k);
        even += term(k + 1);
        k += 2;
    }
    if k < N {
        odd += term(k);
    }
    odd + even
}

#[cfg(test)]
mod tests {
    use super::*;

    fn coeffs() -> Vec<f32> {
        (0..48)
            .map(|i| ((i * 37 % 17) as f32 - 8.0) * 0.05)
            .collect()
    }

    #[test]
    fn dc_only_is_constant_over_directions() {
        let c = coeffs();
        let a = eval_sh(0, &c, Vec3::X);
        let b = eval_sh(0, &c, Vec3::new(0.0, 0.6, 0.8));
        assert_eq!(a, b);
        assert!((a.x - SH_C0 * c[0]).abs() < 1e-7);
    }

    #[test]
    fn degree_one_band_matches_3dgs_sign_convention() {
        let mut c = vec![0.0; 12];
        c[3] = 1.0; // k = 1 (-C1 * y), red channel
        let s = eval_sh(1, &c, Vec3::Y);
        assert!((s.x + SH_C1).abs() < 1e-7);
    }

    #[test]
    fn direction_gradient_matches_finite_differences_for_every_degree() {
        let c = coeffs();
        let v = Vec3::new(0.3, -0.7, 1.1);
        for degree in 0..=3 {
            let dir = Vec3::new(0.2, -0.5, 0.84);
            let mut v_coeffs = vec![0.0; 48];
            let v_dir = eval_sh_backward(degree, &c, dir, v, &mut v_coeffs);
            let f = |d: Vec3| eval_sh(degree, &c, d).dot(v) as f64;
            for axis in 0..3 {
                let eps = 1e-3;
                let mut e = Vec3::ZERO;
                e[axis] = eps;
                let fd = (f(dir + e) - f(dir - e)) / (2.0 * eps as f64);
                assert!(
                    (fd - v_dir[axis] as f64).abs() < 2e-3 * (1.0 + fd.abs()),
                    "degree {degree} axis {axis}: fd {fd} analytic {}",
                    v_dir[axis]
                );
            }
            // Coefficient gradient is the basis itself.
            let mut basis = [0.0; 16];
            sh_basis(degree, dir, &mut basis);
            for k in 0..crate::splats::model::sh_coeffs_for_degree(degree) {
                assert!((v_coeffs[k * 3 + 1] - basis[k] * v.y).abs() < 1e-7);
            }
        }
    }
}
