use super::*;
use proptest::prelude::*;

proptest! {
    /// [`lower_solve`] with a dirty Cholesky factor equals `chol.l().solve_lower_triangular`
    /// bit for bit (dimension 7 takes nalgebra's path), and refuses a zero diagonal as it.
    #[test]
    fn lower_solve_is_bit_identical(
        n in 1usize..=7,
        vals in proptest::collection::vec(-10.0f64..10.0, 56),
        scale in -30i32..30,
        zero_at in 0usize..10,
    ) {
        let g = Matrix::from_fn(n, n, |i, j| vals[(i * 7 + j) % 56]);
        let p = (&g * g.transpose() + Matrix::identity(n, n)) * 10f64.powi(scale);
        let b = Vector::from_fn(n, |i, _| vals[(3 * i + 5) % 56]);
        let chol = nalgebra::Cholesky::new(p).unwrap();
        let mut fast = b.clone();
        prop_assert!(lower_solve(chol.l_dirty(), &mut fast));
        let want = chol.l().solve_lower_triangular(&b).unwrap();
        let bits = |v: &Vector| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        prop_assert_eq!(bits(&fast), bits(&want));
        if zero_at < n {
            let mut l = chol.l_dirty().clone();
            l[(zero_at, zero_at)] = 0.0;
            let mut fast = b.clone();
            let mut slow = b.clone();
            prop_assert_eq!(lower_solve(&l, &mut fast), l.solve_lower_triangular_mut(&mut slow));
        }
    }
}
