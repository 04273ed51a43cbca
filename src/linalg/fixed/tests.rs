use super::*;
use proptest::prelude::*;

fn bits(v: &Vector) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

proptest! {
    /// The fixed-size kernel equals the dynamic gemv (and `&a * &x`) bit for bit, for
    /// every shape up to 7 x 7 (7 takes the dynamic fallback), with values spanning many
    /// magnitudes, signed zeros and infinities.
    #[test]
    fn fixed_gemv_is_bit_identical(
        r in 1usize..=7,
        c in 1usize..=7,
        vals in proptest::collection::vec(
            prop_oneof![
                8 => -1e3f64..1e3,
                1 => (-300i32..300).prop_map(|e| 10f64.powi(e)),
                1 => Just(-0.0f64),
                1 => Just(0.0f64),
                1 => Just(f64::INFINITY),
            ],
            56,
        ),
    ) {
        let a = Matrix::from_fn(r, c, |i, j| vals[(i * 7 + j) % 56]);
        let x = Vector::from_fn(c, |i, _| vals[(49 + i) % 56]);
        let mut fast = Vector::zeros(r);
        gemv(&mut fast, &a, &x);
        let mut dynamic = Vector::zeros(r);
        dynamic.gemv(1.0, &a, &x, 0.0);
        let expr = &a * &x;
        prop_assert_eq!(bits(&fast), bits(&dynamic));
        prop_assert_eq!(bits(&fast), bits(&expr));
    }
}

fn spd(n: usize, vals: &[f64]) -> Matrix {
    let g = Matrix::from_fn(n, n, |i, j| vals[(i * 7 + j) % vals.len()]);
    &g * g.transpose() + Matrix::identity(n, n) * vals[0].abs().max(1e-3)
}

proptest! {
    /// The fixed-size Cholesky solve, Mahalanobis distance and LU solve equal nalgebra's
    /// dynamic ones bit for bit (dimension 7 takes the dynamic fallback).
    #[test]
    fn fixed_solves_are_bit_identical(
        n in 1usize..=7,
        vals in proptest::collection::vec(-10.0f64..10.0, 56),
        scale in -30i32..30,
    ) {
        let p = spd(n, &vals) * 10f64.powi(scale);
        let b = Vector::from_fn(n, |i, _| vals[(3 * i + 5) % 56] * 10f64.powi(-scale / 2));
        let chol = nalgebra::Cholesky::new(p.clone()).unwrap();
        let mut fast = b.clone();
        chol_solve(&chol, &mut fast);
        let mut dynamic = b.clone();
        chol.solve_mut(&mut dynamic);
        prop_assert_eq!(bits(&fast), bits(&dynamic));

        let m = crate::linalg::mahalanobis_sq(&b, &p).unwrap();
        match mahalanobis_sq_small(&b, &p) {
            Some(v) => prop_assert_eq!(v.unwrap().to_bits(), m.to_bits()),
            None => prop_assert_eq!(n, 7),
        }
        // Indefinite: refused by both.
        let bad = &p - Matrix::identity(n, n) * (2.0 * p.amax());
        if let Some(v) = mahalanobis_sq_small(&b, &bad) {
            prop_assert!(v.is_none());
            prop_assert!(crate::linalg::mahalanobis_sq(&b, &bad).is_err());
        }

        let a = Matrix::from_fn(n, n, |i, j| vals[(5 * i + 3 * j + 1) % 56]);
        let lu = a.clone().lu();
        let packed = PackedLu::new(lu.clone());
        let mut fast = b.clone();
        let ok_fast = packed.solve(&mut fast);
        let mut dynamic = b.clone();
        let ok_dyn = lu.solve_mut(&mut dynamic);
        prop_assert_eq!(ok_fast, ok_dyn);
        if ok_dyn {
            prop_assert_eq!(bits(&fast), bits(&dynamic));
        }
    }
}

proptest! {
    /// The fixed-size gemm, Cholesky factorization and matrix solve equal nalgebra's.
    #[test]
    fn fixed_gemm_and_cholesky_are_bit_identical(
        n in 1usize..=7,
        vals in proptest::collection::vec(-10.0f64..10.0, 56),
        scale in -30i32..30,
    ) {
        let a = Matrix::from_fn(n, n, |i, j| vals[(i * 7 + j) % 56] * 10f64.powi(scale));
        let b = Matrix::from_fn(n, n, |i, j| vals[(3 * i + 5 * j + 11) % 56]);
        let mut fast = Matrix::zeros(n, n);
        gemm(&mut fast, &a, &b);
        let mut dynamic = Matrix::zeros(n, n);
        dynamic.gemm(1.0, &a, &b, 0.0);
        let mbits = |m: &Matrix| m.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        prop_assert_eq!(mbits(&fast), mbits(&dynamic));
        prop_assert_eq!(mbits(&fast), mbits(&(&a * &b)));

        let p = spd(n, &vals) * 10f64.powi(scale);
        let fast = cholesky(p.clone()).unwrap();
        let dynamic = nalgebra::Cholesky::new(p.clone()).unwrap();
        prop_assert_eq!(mbits(fast.l_dirty()), mbits(dynamic.l_dirty()));
        let mut x = b.clone();
        chol_solve_matrix(&fast, &mut x);
        let mut y = b.clone();
        dynamic.solve_mut(&mut y);
        prop_assert_eq!(mbits(&x), mbits(&y));
        let bad = &p - Matrix::identity(n, n) * (2.0 * p.amax());
        prop_assert!(cholesky(bad.clone()).is_none());
        prop_assert!(nalgebra::Cholesky::new(bad).is_none());
    }
}

proptest! {
    /// dot and norm equal nalgebra's on dynamic vectors of every length up to 20.
    #[test]
    fn dot_and_norm_are_bit_identical(
        n in 0usize..=20,
        vals in proptest::collection::vec(-1e3f64..1e3, 40),
    ) {
        let a = Vector::from_fn(n, |i, _| vals[i]);
        let b = Vector::from_fn(n, |i, _| vals[20 + i] * if i % 3 == 0 { -0.0 } else { 1.0 });
        prop_assert_eq!(dot(a.as_slice(), b.as_slice()).to_bits(), a.dot(&b).to_bits());
        prop_assert_eq!(norm(a.as_slice()).to_bits(), a.norm().to_bits());
    }
}

proptest! {
    /// The slice kernel for square matrices equals [`gemv`] (and hence nalgebra's) bit for
    /// bit, for every dimension up to 7 (7 takes nalgebra's gemv on views).
    #[test]
    fn gemv_square_is_bit_identical(
        n in 1usize..=7,
        vals in proptest::collection::vec(
            prop_oneof![
                8 => -1e3f64..1e3,
                1 => (-300i32..300).prop_map(|e| 10f64.powi(e)),
                1 => Just(-0.0f64),
                1 => Just(f64::INFINITY),
            ],
            56,
        ),
    ) {
        let a = Matrix::from_fn(n, n, |i, j| vals[(i * 7 + j) % 56]);
        let x = Vector::from_fn(n, |i, _| vals[(49 + i) % 56]);
        let mut want = Vector::zeros(n);
        gemv(&mut want, &a, &x);
        let mut got = vec![f64::NAN; n];
        gemv_square(&mut got, &a, x.as_slice());
        prop_assert_eq!(got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), bits(&want));
    }
}

proptest! {
    /// Packing nalgebra's internal LU matrix gives [`PackedLu::new`]'s factors and
    /// permutation bit for bit (dimension 7 keeps nalgebra's factorization).
    #[test]
    fn packed_lu_from_internal_matrix_is_bit_identical(
        n in 1usize..=7,
        vals in proptest::collection::vec(-10.0f64..10.0, 56),
        zero_col in proptest::option::of(0usize..7),
    ) {
        let mut a = Matrix::from_fn(n, n, |i, j| vals[(5 * i + 3 * j + 1) % 56]);
        if let Some(c) = zero_col.filter(|&c| c < n) {
            a.column_mut(c).fill(0.0);
        }
        match (PackedLu::new(a.clone().lu()), PackedLu::from_packed(a.clone().lu())) {
            (
                PackedLu::Fixed { n: n1, lu: lu1, perm: p1 },
                PackedLu::Fixed { n: n2, lu: lu2, perm: p2 },
            ) => {
                prop_assert_eq!(n1, n2);
                let b = |v: &[f64; 36]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                prop_assert_eq!(b(&lu1), b(&lu2));
                prop_assert_eq!(p1, p2);
            }
            (PackedLu::Dynamic(_), PackedLu::Dynamic(_)) => prop_assert_eq!(n, 7),
            _ => prop_assert!(false, "different representations"),
        }
    }
}
