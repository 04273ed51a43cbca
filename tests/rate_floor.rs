//! The rate–distortion floor in the arena (issue 24): every scheme's entropy-coded rate
//! `r_eff_per_step` is counted as documented, and no scheme of any arena lies below the floor at
//! its rate by more than 3 standard errors of its steady-state MSE, at its default knob or at
//! any budget.
use hushfuse::engine::calibrate::{self, Axis};
use hushfuse::engine::runner;
use hushfuse::metrics::floor::binary_entropy;
use hushfuse::metrics::results::{self, SchemeSummary, Summary};
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;

fn run(name: &str, trials: usize) -> Summary {
    let text = builtin::get(name).unwrap();
    let opts = build::LoadOptions {
        trials: Some(trials),
        ..Default::default()
    };
    let exp = build::load_with(text, &format!("built-in:{name}"), &opts).unwrap();
    let sums = runner::run(&exp, runner::RunOptions::default(), &|_| {}).unwrap();
    results::summarize(&exp, &sums)
}

/// Whether a vector floor can be solved in this build (OpenBLAS found at build time).
fn sdp_available(s: &Summary) -> bool {
    s.rate_distortion_floor_note
        .as_deref()
        .is_none_or(|n| !n.contains("BLAS"))
}

/// Every scheme with a floor: steady-state MSE + 3 s.e. >= floor; returns how many were checked.
fn assert_above_floor(context: &str, schemes: &[&SchemeSummary]) -> usize {
    let mut checked = 0;
    for s in schemes {
        let Some(floor) = s.floor_mse else { continue };
        let (mse, se) = (s.steady_state.mse, s.steady_state.mse_se);
        assert!(
            mse + 3.0 * se >= floor,
            "{context}: {} at R_eff {:.3} bits/step: MSE {mse} ± {se} below the floor {floor}",
            s.name,
            s.r_eff_per_step
        );
        checked += 1;
    }
    checked
}

#[test]
fn r_eff_is_counted_per_sensor_as_documented() {
    let s = run("arena-1d", 20);
    let by = |kind: &str| s.schemes.iter().find(|x| x.kind == kind).unwrap();
    // Every sensor at every step: no decision to code, R_eff is the payload.
    let all = by("centralized-kf");
    assert_eq!(all.r_eff_per_step, all.bits_per_step);
    assert_eq!(all.r_eff_per_step, 128.0);
    // Round robin: a sensor always sends in its slot and is not scheduled outside it.
    let rr = by("round-robin-kf");
    assert_eq!(rr.r_eff_per_step, rr.bits_per_step);
    // Random forwarding at rate p: each of the 4 sensors' decisions carries about h(p); the
    // sample rate stands in for p (the counts are per sensor, so they differ slightly).
    let random = by("centralized-kf-random");
    let h = 4.0 * binary_entropy(random.rate);
    let decisions = random.r_eff_per_step - random.bits_per_step;
    assert!(
        (decisions - h).abs() < 0.01 * h,
        "decisions {decisions} vs 4 h(p) {h}"
    );
    // Every scheme: payload <= R_eff <= payload + one bit per sensor.
    for x in &s.schemes {
        assert!(
            x.r_eff_per_step >= x.bits_per_step - 1e-9
                && x.r_eff_per_step <= x.bits_per_step + 4.0 + 1e-9,
            "{}: R_eff {} payload {}",
            x.name,
            x.r_eff_per_step,
            x.bits_per_step
        );
    }
}

#[test]
fn the_floor_curve_falls_to_the_all_data_error() {
    let s = run("arena-1d", 4);
    if !sdp_available(&s) {
        eprintln!("skipped: {:?}", s.rate_distortion_floor_note);
        return;
    }
    let c = s
        .rate_distortion_floor
        .as_ref()
        .expect("arena-1d has a floor");
    assert!(c.rate.windows(2).all(|w| w[0] < w[1]));
    assert!(c.mse.windows(2).all(|w| w[0] >= w[1]), "{:?}", c.mse);
    assert!(c.mse.iter().all(|&d| d >= c.all_data_mse));
    // The floor at the top of the curve is the all-data KF's steady-state error, which is the
    // steady state of the posterior Cramér–Rao bound on linear sensors.
    let pcrb = s.pcrb.as_ref().unwrap().steady_mse;
    assert!(
        (c.all_data_mse - pcrb).abs() < 1e-6 * pcrb,
        "{} vs {pcrb}",
        c.all_data_mse
    );
    // Nonlinear sensors: no floor, and the reason.
    let rss = run("arena-rss", 2);
    assert!(rss.rate_distortion_floor.is_none());
    assert!(rss
        .rate_distortion_floor_note
        .as_deref()
        .is_some_and(|n| n.contains("not linear")));
}

#[test]
fn no_scheme_of_an_arena_lies_below_the_floor_at_its_default_knobs() {
    // arena-tobit has no floor: its three states are driven through two scalar sensors, so the
    // Kalman estimate's driving covariance is singular, which the program cannot take (the
    // note says so); arena-rss and arena-wsn have nonlinear sensors.
    let tobit = run("arena-tobit", 2);
    assert!(tobit
        .rate_distortion_floor_note
        .as_deref()
        .is_some_and(|n| n.contains("singular")));
    for (name, trials) in [("arena-1d", 100), ("arena-nca", 40)] {
        let s = run(name, trials);
        if !sdp_available(&s) {
            eprintln!("{name}: skipped: {:?}", s.rate_distortion_floor_note);
            continue;
        }
        let schemes: Vec<&SchemeSummary> = s.schemes.iter().collect();
        let n = assert_above_floor(name, &schemes);
        assert!(n >= 5, "{name}: only {n} schemes had a floor");
    }
}

#[test]
fn no_scheme_lies_below_the_floor_at_any_budget() {
    let text = builtin::get("arena-1d").unwrap();
    // Low payload budgets, where the floor lies well above the all-data error, and energy.
    for (axis, budgets) in [
        (Axis::Payload, &[3.0, 6.0, 12.0][..]),
        (Axis::Energy, &[270.0][..]),
    ] {
        let opts = calibrate::Options {
            axis,
            load: build::LoadOptions {
                trials: Some(60),
                ..Default::default()
            },
            ..Default::default()
        };
        let out = calibrate::calibrate(text, "built-in:arena-1d", budgets, &opts).unwrap();
        if !sdp_available(&out.summaries[0]) {
            eprintln!("skipped: no BLAS");
            return;
        }
        for (b, row) in out.rows.iter().enumerate() {
            let schemes: Vec<&SchemeSummary> = row.iter().map(|c| &c.result).collect();
            let context = format!("arena-1d at {} {}", budgets[b], axis.unit());
            let n = assert_above_floor(&context, &schemes);
            assert!(n >= 10, "{context}: only {n} schemes had a floor");
            // The table's floor is the summary's.
            for (c, s) in row.iter().zip(&out.summaries[b].schemes) {
                assert_eq!(c.result.floor_mse, s.floor_mse);
            }
        }
    }
}
