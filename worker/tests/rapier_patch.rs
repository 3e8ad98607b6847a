//! The vendored rapier3d's slice kernels (vendor/rapier3d/NAOFARM.md), which
//! do nalgebra's arithmetic faster, give its bits.

/// A well-conditioned `n × n` matrix with every entry set, whose LU
/// factorisation pivots.
fn pivoting_matrix(n: usize) -> nalgebra::DMatrix<f32> {
    nalgebra::DMatrix::from_fn(n, n, |i, j| {
        let x = ((i * 7 + j * 13) % 17) as f32 / 17.0 - 0.5;
        if i == (j + 3) % n {
            x + n as f32
        } else {
            x
        }
    })
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Solves `b` with nalgebra's LU and with the slice kernel; asserts the
/// same bits, naming `what`.
fn solves_alike(
    lu: &nalgebra::LU<f32, nalgebra::Dyn, nalgebra::Dyn>,
    b: nalgebra::DVector<f32>,
    what: &str,
) {
    let (mut theirs, mut ours) = (b.clone(), b);
    assert!(lu.solve_mut(&mut theirs));
    rapier3d::utils::slice_blas::lu_solve(lu, ours.as_mut_slice());
    assert_eq!(bits(ours.as_slice()), bits(theirs.as_slice()), "{what}");
}

#[test]
fn the_slice_kernels_give_nalgebras_bits() {
    use rapier3d::utils::slice_blas::{axpy, solve_upper};
    for n in [1, 2, 7, 24, 32] {
        let lu = nalgebra::LU::new(pivoting_matrix(n));
        // Every column of M⁻¹, as the motor and stop rows ask for it.
        let mut moved = 0;
        for k in 0..n {
            let mut unit = nalgebra::DVector::<f32>::zeros(n);
            unit[k] = 1.0;
            solves_alike(&lu, unit, &format!("n {n}, column {k}"));
            let mut permuted = nalgebra::DVector::<f32>::zeros(n);
            permuted[k] = 1.0;
            lu.p().permute_rows(&mut permuted);
            moved += usize::from(permuted[k] != 1.0);
        }
        // The matrices pivot, so the forward substitution starts elsewhere
        // than at k for some columns.
        assert!(n < 7 || moved > 0, "n {n}: no column was moved");
        // A contact's row: zeros where it moves no degree of freedom (from
        // none to all but the last), with and without a −0 among them.
        for first in 0..n {
            for negative_zero in [None, Some(n - 1 - first / 2)] {
                let mut b = nalgebra::DVector::<f32>::from_fn(n, |i, _| {
                    if i < first || i % 3 == 1 {
                        0.0
                    } else {
                        (i as f32 * 0.53).sin() - 0.2
                    }
                });
                if let Some(z) = negative_zero {
                    b[z] = -0.0;
                }
                let what = format!("n {n}, zeros before {first}, -0 at {negative_zero:?}");
                solves_alike(&lu, b, &what);
            }
        }
        // A dense right-hand side through the upper triangle.
        let u = lu.u();
        let b = nalgebra::DVector::<f32>::from_fn(n, |i, _| (i as f32 * 0.37).sin() + 0.1);
        let mut theirs = b.clone();
        let mut ours = b.clone();
        assert!(u.solve_upper_triangular_mut(&mut theirs));
        assert!(solve_upper(&u, ours.as_mut_slice()));
        assert_eq!(bits(ours.as_slice()), bits(theirs.as_slice()), "n {n}");
        // And y ← a·x + y.
        let x = nalgebra::DVector::<f32>::from_fn(n, |i, _| (i as f32 * 0.11).cos() * 1e3);
        theirs.axpy(-0.3, &x, 1.0);
        axpy(ours.as_mut_slice(), -0.3, x.as_slice());
        assert_eq!(bits(ours.as_slice()), bits(theirs.as_slice()), "n {n}");
    }
    // A zero on the diagonal stops both solves alike.
    let mut singular = pivoting_matrix(4).upper_triangle();
    singular[(2, 2)] = 0.0;
    let b = nalgebra::DVector::<f32>::from_element(4, 1.0);
    let (mut theirs, mut ours) = (b.clone(), b);
    assert!(!singular.solve_upper_triangular_mut(&mut theirs));
    assert!(!solve_upper(&singular, ours.as_mut_slice()));
    assert_eq!(bits(ours.as_slice()), bits(theirs.as_slice()));
}
