//! naofarm: nalgebra's elementwise vector kernels on contiguous slices.
//!
//! nalgebra's `axpy` walks a vector by a stride it reads at run time, which
//! keeps the compiler from vectorising the loop, and its LU solve runs the
//! forward substitution over the leading zeros of a unit right-hand side.
//! A multibody's motor and stop rows each solve for such a column of `M⁻¹`.
//! Each routine here does, element by element, the same IEEE operations in
//! the same order as the nalgebra routine it names, so its results are the
//! same bits.
//! Must not: reorder a sum (a reduction such as `dot` keeps nalgebra's).

use crate::math::Real;
use na::{DMatrix, Dyn, LU};

/// `y ← a·x + y`: nalgebra's `y.axpy(a, x, 1.0)`, which computes
/// `a·x·1 + 1·y` per element (both products by one are exact).
#[inline]
pub fn axpy(y: &mut [Real], a: Real, x: &[Real]) {
    assert_eq!(y.len(), x.len(), "axpy: mismatched lengths");
    for (y, x) in y.iter_mut().zip(x) {
        *y = a * *x + *y;
    }
}

/// Solves `U x = b` in place with the upper triangle of the column-major
/// square `m` (its diagonal included): nalgebra's
/// `solve_upper_triangular_mut` on one column. Returns `false` on a zero on
/// the diagonal, leaving `b` as far as it got, as nalgebra does.
pub fn solve_upper(m: &DMatrix<Real>, b: &mut [Real]) -> bool {
    let n = m.nrows();
    assert_eq!(n, b.len(), "solve_upper: dimension mismatch");
    let data = m.as_slice();
    for i in (0..n).rev() {
        let diag = data[i * n + i];
        if diag == 0.0 {
            return false;
        }
        let coeff = b[i] / diag;
        b[i] = coeff;
        axpy(&mut b[..i], -coeff, &data[i * n..i * n + i]);
    }
    true
}

/// Solves `L x = b` in place with the strict lower triangle of the
/// column-major square `m` and a unit diagonal, from row `first` on:
/// nalgebra's `solve_lower_triangular_with_diag_mut(b, 1.0)` when every entry
/// of `b` before `first` is `+0` (each of its steps there adds `-0·l` to
/// `+0` entries and leaves them `+0`).
pub fn solve_unit_lower_from(m: &DMatrix<Real>, b: &mut [Real], first: usize) {
    let n = m.nrows();
    assert_eq!(n, b.len(), "solve_unit_lower_from: dimension mismatch");
    let data = m.as_slice();
    for i in first..n.saturating_sub(1) {
        let coeff = b[i] / 1.0;
        axpy(&mut b[i + 1..], -coeff, &data[i * n + i + 1..(i + 1) * n]);
    }
}

/// Solves `M x = b` in place through `lu`: the bits of `lu.solve_mut(b)`.
/// The forward substitution starts at the first entry of the permuted `b`
/// that is not zero when `b` holds no −0 (then each step it skips adds ±0
/// to entries that are `+0` or not zero, which leaves them as they are; the
/// factors are finite). A unit vector `eₖ`, a motor or stop row's column of
/// `M⁻¹`, starts where the permutation moved its 1; a contact's row starts
/// past the degrees of freedom it does not move.
pub fn lu_solve(lu: &LU<Real, Dyn, Dyn>, b: &mut [Real]) {
    let m = lu.lu_internal();
    assert_eq!(m.nrows(), b.len(), "LU solve matrix dimension mismatch.");
    if b.is_empty() {
        return;
    }
    lu.p()
        .permute_rows(&mut na::DVectorViewMut::from_slice(b, m.nrows()));
    let negative_zero = b
        .iter()
        .any(|x| x.to_bits() == (-0.0 as Real).to_bits());
    let first = if negative_zero {
        0
    } else {
        b.iter().position(|x| *x != 0.0).unwrap_or(b.len())
    };
    solve_unit_lower_from(m, b, first);
    let _ = solve_upper(m, b);
}
