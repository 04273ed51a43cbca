use super::*;

/// `ln(1e-300)`: below it the band probability is not required to be accurate.
const LN_1E300: f64 = -690.775_527_898_213_7;
/// The accuracy required where the band probability is at least 1e-300.
const TOL: f64 = 1e-12;

fn kernel(mu: &[f64], c: f64, s: f64) -> Vec<f64> {
    let mut out = vec![0.0; mu.len()];
    add_log_band_probability(mu, c, s, &mut out);
    out
}

fn reference(mu: &[f64], c: f64, s: f64) -> Vec<f64> {
    let mut out = vec![0.0; mu.len()];
    add_log_band_probability_scalar(mu, 0.0, c, s, &mut out);
    out
}

/// Largest `|got - want|` where `want >= ln 1e-300`; also checks that every value is
/// finite and not above 0 by more than rounding.
fn worst_error(mu: &[f64], got: &[f64], want: &[f64], what: &str) -> f64 {
    let mut worst: f64 = 0.0;
    for ((&m, &g), &w) in mu.iter().zip(got).zip(want) {
        assert!(g.is_finite() && g <= 1e-15, "{what}, mu = {m}: {g}");
        if w >= LN_1E300 {
            worst = worst.max((g - w).abs());
        }
    }
    worst
}

#[test]
fn matches_log_q_band_on_a_dense_grid_of_exact_inputs() {
    // mu on a grid of multiples of 2^-7 out to +-60, half-widths multiples of 2^-10 from
    // 2^-10 to ~16 (steps of 2^(1/4)), s a power of two: the reference's inputs
    // (-c - mu) s and (c - mu) s are then exact, so it is accurate even for narrow bands
    // far out (where a rounded band width would cost it ulp(mu) / 2c relative).
    let mu: Vec<f64> = (-60 * 128..=60 * 128).map(|i| i as f64 / 128.0).collect();
    let mut worst: f64 = 0.0;
    for i in 0..=56 {
        let c = (2f64.powf(-10.0 + 0.25 * i as f64) * 1024.0).round() / 1024.0;
        for s in [0.5, 1.0, 2.0] {
            let what = format!("c = {c}, s = {s}");
            let e = worst_error(&mu, &kernel(&mu, c, s), &reference(&mu, c, s), &what);
            assert!(e <= TOL, "{what}: error {e:e}");
            worst = worst.max(e);
        }
    }
    // What is achieved (2.3e-13 when written), with margin.
    assert!(worst < 4e-13, "worst error {worst:e}");
}

#[test]
fn matches_the_exact_band_for_rounded_inputs() {
    // Generic s and c: the reference's own inputs are rounded, which moves its log by up to
    // ~|a| ulp(mu); the kernel (which sees |mu| and c s) is compared against band_h at
    // x = |mu| s, c s instead, and against log_q_band with the input rounding allowed.
    let mu: Vec<f64> = (0..20_000)
        .map(|i| -50.0 + i as f64 * 0.005_000_37)
        .collect();
    for (c, s) in [
        (0.1, 1.0),
        (0.7, 1.0 / 3f64.sqrt()),
        (1.3, 0.83),
        (2.9, 1.71),
        (4.99, 0.5),
        (0.003, 1.9),
        (0.013, 0.77),
    ] {
        let got = kernel(&mu, c, s);
        let want = reference(&mu, c, s);
        let cs = c * s;
        for ((&m, &g), &w) in mu.iter().zip(&got).zip(&want) {
            assert!(g.is_finite(), "c = {c}, s = {s}, mu = {m}: {g}");
            let x = (m * s).abs();
            let a = x - cs;
            let exact = band_h(x, cs) - 0.5 * a * a;
            if exact >= LN_1E300 {
                assert!(
                    (g - exact).abs() <= TOL,
                    "c {c} s {s} mu {m}: {g} vs {exact}"
                );
                let input_rounding = 4.0 * (a.abs() + 1.0) * f64::EPSILON * (m.abs() + c) * s;
                assert!(
                    (g - w).abs() <= TOL + input_rounding,
                    "c {c} s {s} mu {m}: {g} vs log_q_band {w}"
                );
            }
        }
    }
}

#[test]
fn bin_boundaries_and_the_band_centre() {
    // Particles exactly on bin and piece boundaries, at mu = 0, and half-widths on the bin
    // grid (so that x = 0 falls on a boundary): rounding may pick either neighbouring row.
    for c in [0.375, 0.75, 1.5, 3.0, 9.0, 9.375, 12.0, 0.1, 1.0] {
        let mut mu: Vec<f64> = (0..=140)
            .map(|k| c + A_LO + k as f64 * BIN)
            .filter(|&x| x >= 0.0)
            .flat_map(|x| [x, -x, x * (1.0 + 1e-15), x * (1.0 - 1e-15)])
            .collect();
        mu.extend([0.0, -0.0, 1e-300, c, -c]);
        mu.resize(mu.len().max(KERNEL_MIN_LEN), 0.5);
        let e = worst_error(&mu, &kernel(&mu, c, 1.0), &reference(&mu, c, 1.0), "");
        assert!(e <= TOL, "c = {c}: {e:e}");
    }
}

#[test]
fn far_tails_are_finite_decreasing_and_close() {
    for (c, s) in [
        (0.05, 1.0),
        (1.0, 1.0),
        (3.0, 2.0),
        (20.0, 1.0),
        (0.004, 1.0),
    ] {
        let mu: Vec<f64> = (0..4000).map(|i| i as f64 * 0.25).collect();
        let got = kernel(&mu, c, s);
        let want = reference(&mu, c, s);
        for i in 1..mu.len() {
            // Non-increasing (strictly, where P is not within rounding of 1).
            let d = got[i] - got[i - 1];
            assert!(
                d < 0.0 || (d <= 1e-15 && got[i] > -1e-12),
                "c {c}: not decreasing"
            );
            if want[i] < LN_1E300 {
                let rel = ((got[i] - want[i]) / want[i]).abs();
                assert!(rel < 0.01, "c {c}, mu {}: {} vs {}", mu[i], got[i], want[i]);
            }
        }
    }
    // Astronomically far particles: large, negative, finite; NaN stays NaN.
    let mut mu = vec![0.0; KERNEL_MIN_LEN];
    let far = [
        1e100,
        -1e149,
        1e150,
        1e200,
        f64::MAX,
        -f64::MAX,
        f64::INFINITY,
    ];
    mu[..far.len()].copy_from_slice(&far);
    mu[10] = f64::NAN;
    for s in [1.0, 1e-90, 1e90] {
        let got = kernel(&mu, 1.0 / s, s);
        for (m, g) in far.iter().zip(&got) {
            assert!(
                g.is_finite() && *g < -1e100 * s.min(1.0),
                "mu {m}, s {s}: {g}"
            );
        }
        assert!(got[10].is_nan());
    }
    let got = kernel(&mu, 1.0, 1.0);
    assert!(got[0] > got[2] && got[2] < -4e299);
    assert!(got[2] == got[3] && got[3] == got[4] && got[4] == got[6]);
}

#[test]
fn symmetric_additive_and_thread_safe() {
    let mu: Vec<f64> = (0..1000).map(|i| (i as f64 - 500.0) * 0.0731).collect();
    let neg: Vec<f64> = mu.iter().map(|m| -m).collect();
    assert_eq!(kernel(&mu, 1.7, 0.9), kernel(&neg, 1.7, 0.9));
    let mut out: Vec<f64> = (0..1000).map(|i| i as f64).collect();
    add_log_band_probability(&mu, 1.7, 0.9, &mut out);
    let plain = kernel(&mu, 1.7, 0.9);
    for (i, (o, p)) in out.iter().zip(&plain).enumerate() {
        assert_eq!(*o, i as f64 + p);
    }
    // Each thread has its own table.
    let handles: Vec<_> = (0..4)
        .map(|t| {
            let mu = mu.clone();
            std::thread::spawn(move || {
                let c = 0.3 + t as f64;
                for _ in 0..50 {
                    let got = kernel(&mu, c, 1.0);
                    let e = worst_error(&mu, &got, &reference(&mu, c, 1.0), "");
                    assert!(e <= TOL);
                }
            })
        })
        .collect();
    for h in handles {
        h.join().unwrap();
    }
}

#[test]
fn short_slices_and_degenerate_bands_take_the_scalar_path() {
    let mu: Vec<f64> = (0..KERNEL_MIN_LEN - 1)
        .map(|i| i as f64 * 0.37 - 9.0)
        .collect();
    assert_eq!(kernel(&mu, 1.0, 1.0), reference(&mu, 1.0, 1.0));
    let mu: Vec<f64> = (0..200).map(|i| i as f64 * 0.37 - 30.0).collect();
    for (c, s) in [
        (0.0, 1.0),
        (-1.0, 1.0),
        (1.0, -1.0),
        (1.0, 0.0),
        (f64::NAN, 1.0),
        (1.0, f64::INFINITY),
        (1e7, 1.0),
        (1.0, 1e-101),
    ] {
        let (got, want) = (kernel(&mu, c, s), reference(&mu, c, s));
        for (g, w) in got.iter().zip(&want) {
            assert!(
                g == w || (g.is_nan() && w.is_nan()),
                "c {c} s {s}: {g} vs {w}"
            );
        }
    }
    assert!(kernel(&mu, 0.0, 1.0)
        .iter()
        .all(|&v| v == f64::NEG_INFINITY));
}

#[test]
fn centering_inside_the_kernel_changes_no_bit() {
    // Both the table path (>= 64 particles) and the scalar fallback (fewer).
    for len in [40usize, 3000] {
        let h: Vec<f64> = (0..len)
            .map(|i| 7.3 + (i as f64 * 0.731).sin() * 9.0)
            .collect();
        let center = 7.9;
        let mu: Vec<f64> = h.iter().map(|v| v - center).collect();
        for (c, s) in [(0.8, 1.0), (2.5, 0.6), (0.004, 3.0)] {
            let mut a = vec![0.5; len];
            let mut b = vec![0.5; len];
            add_log_band_probability(&mu, c, s, &mut a);
            add_log_band_probability_about(&h, center, c, s, &mut b);
            assert_eq!(a, b, "len {len}, c {c}, s {s}");
        }
    }
}

#[test]
fn cached_tables_equal_fresh_ones_through_evictions() {
    // More bands than the cache holds, visited twice in an order that evicts every one:
    // the second visit (rebuilt or cached) must give the first visit's values bit for bit,
    // and each must equal a table built from scratch.
    let mu: Vec<f64> = (0..2000).map(|i| -20.0 + i as f64 * 0.02).collect();
    let bands: Vec<(f64, f64)> = (0..CACHED_TABLES + 7)
        .map(|i| (0.05 + 0.37 * i as f64, 1.0 / (1.0 + 0.1 * i as f64)))
        .collect();
    let first: Vec<Vec<f64>> = bands.iter().map(|&(c, s)| kernel(&mu, c, s)).collect();
    for round in 0..2 {
        for (b, &(c, s)) in bands.iter().enumerate().rev() {
            assert_eq!(kernel(&mu, c, s), first[b], "round {round}, band {b}");
        }
    }
    let k = Kernel::get();
    let mut scratch = Workspace::new();
    for (b, &(c, s)) in bands.iter().enumerate() {
        let mut rows = Box::new([ZERO_ROW; TABLE_ROWS]);
        let c_sd = c * s;
        k.build(c_sd, s, &mut scratch.scratch, &mut rows);
        let mut fresh = vec![0.0; mu.len()];
        add_from_table(&rows, &mu, 0.0, s, c_sd, &mut fresh);
        assert_eq!(fresh, first[b], "band {b}");
    }
}

#[test]
#[should_panic]
fn rejects_length_mismatch() {
    add_log_band_probability(&[0.0; 100], 1.0, 1.0, &mut [0.0; 99]);
}

#[test]
fn process_wide_tables_are_accurate() {
    let k = Kernel::get();
    for i in 0..=50_000 {
        let y = i as f64 * (42.0 / 50_000.0);
        let (got, want) = (k.t_lookup(y), ln_scaled_q_any(y));
        assert!((got - want).abs() <= 1e-15 * want.abs().max(1.0), "T({y})");
    }
    for i in 0..=50_000 {
        let g = 2f64.powf(-6.9 + i as f64 * 13.8 / 50_000.0);
        let l = eval_block(&k.l_tab, &[g], Kernel::l_index)[0];
        let want = log1mexp(-g);
        assert!(
            (l - want).abs() <= 5e-16 * want.abs().max(1.0),
            "L({g}): {l} vs {want}"
        );
    }
}
