use super::*;
use proptest::prelude::*;

fn mbits(m: &[f64]) -> Vec<u64> {
    m.iter().map(|x| x.to_bits()).collect()
}

fn check<const N: usize>(vals: &[f64], scale: i32, spoil: Option<(usize, f64)>) {
    let n = N;
    let a = Matrix::from_fn(n, n, |i, j| vals[(i * 7 + j) % 56] * 10f64.powi(scale));
    let b = Matrix::from_fn(n, n, |i, j| vals[(3 * i + 5 * j + 11) % 56]);
    if gemm_square_covers(n) {
        let mut want = Matrix::zeros(n, n);
        gemm(&mut want, &a, &b);
        let mut got = [f64::NAN; 36];
        gemm_square::<N>(&mut got, a.as_slice(), b.as_slice());
        assert_eq!(mbits(&got[..n * n]), mbits(want.as_slice()), "gemm n={n}");
    }
    let g = Matrix::from_fn(n, n, |i, j| vals[(i * 7 + j + 3) % 56]);
    let mut p =
        (&g * g.transpose() + Matrix::identity(n, n) * vals[0].abs().max(1e-3)) * 10f64.powi(scale);
    if let Some((at, v)) = spoil {
        // A non-finite or extreme entry (the factor may then hold infinities or NaN).
        let (r, c) = (at % n, (at / n) % n);
        p[(r.max(c), r.min(c))] = v;
    }
    let want = cholesky(p.clone());
    let mut got = [0.0; 36];
    got[..n * n].copy_from_slice(p.as_slice());
    let ok = cholesky_square::<N>(&mut got);
    assert_eq!(ok, want.is_some(), "cholesky n={n}");
    let Some(chol) = want else { return };
    assert_eq!(mbits(&got[..n * n]), mbits(chol.l_dirty().as_slice()));
    let mut inv = Matrix::identity(n, n);
    chol_solve_matrix(&chol, &mut inv);
    let mut sym = [f64::NAN; 36];
    sym[..n * n].copy_from_slice(inv.as_slice());
    crate::linalg::symmetrize(&mut inv);
    symmetrize_square::<N>(&mut sym);
    assert_eq!(
        mbits(&sym[..n * n]),
        mbits(inv.as_slice()),
        "symmetrize n={n}"
    );
    let mut fast = [f64::NAN; 36];
    chol_inverse_sym_square::<N>(&got, &mut fast);
    assert_eq!(
        mbits(&fast[..n * n]),
        mbits(inv.as_slice()),
        "inverse n={n}"
    );
}

proptest! {
    /// [`all_finite`] answers as `iter().all(is_finite)` for every length up to 40, with
    /// infinities, NaN, signed zeros and extreme values anywhere.
    #[test]
    fn all_finite_is_all_is_finite(
        vals in proptest::collection::vec(prop_oneof![
            8 => -1e300f64..1e300,
            1 => Just(f64::INFINITY),
            1 => Just(f64::NEG_INFINITY),
            1 => Just(f64::NAN),
            1 => Just(-0.0f64),
            1 => Just(f64::MAX),
            1 => Just(f64::MIN_POSITIVE),
        ], 0..40),
    ) {
        prop_assert_eq!(all_finite(&vals), vals.iter().all(|v| v.is_finite()));
    }
}

proptest! {
    /// The square slice kernels equal [`gemm`], [`cholesky`], `linalg::symmetrize` and
    /// identity + [`chol_solve_matrix`] + `linalg::symmetrize` bit for bit, on well-scaled and
    /// extreme positive definite matrices and on ones with an overflowing, tiny, infinite
    /// or NaN entry (whose factor, when Cholesky accepts it, need not be finite).
    #[test]
    fn square_kernels_are_bit_identical(
        n in 1usize..=6,
        vals in proptest::collection::vec(-10.0f64..10.0, 56),
        scale in prop_oneof![4 => -30i32..30, 1 => -300i32..300],
        spoil in proptest::option::of((0usize..36, prop_oneof![
            Just(f64::INFINITY),
            Just(f64::NAN),
            Just(1e300),
            Just(-1e300),
            Just(1e-300),
            Just(0.0),
        ])),
    ) {
        match n {
            1 => check::<1>(&vals, scale, spoil),
            2 => check::<2>(&vals, scale, spoil),
            3 => check::<3>(&vals, scale, spoil),
            4 => check::<4>(&vals, scale, spoil),
            5 => check::<5>(&vals, scale, spoil),
            _ => check::<6>(&vals, scale, spoil),
        }
    }
}
