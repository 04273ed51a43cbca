//! Tests of the sums: the NEES histogram, the row layout, recording and merging.
use super::*;
use crate::linalg::Matrix;

#[test]
fn histograms_merge_and_clear_only_what_they_touched_with_the_counts_of_a_full_pass() {
    let fill = |values: &[f64]| {
        let mut h = NeesHistogram::new();
        values.iter().for_each(|&v| h.add(v));
        h
    };
    let a = fill(&[1e-3, 0.5, 0.5, 2.0]);
    let b = fill(&[1e6, 3.0, f64::NAN, 1e-9]);
    // Values added divided, all at once: the counts and the touched range of one by one.
    let mut d = NeesHistogram::new();
    d.add_divided(&[2e-3, 1.0, 1.0, 4.0], 2.0);
    assert_eq!((&d.counts, d.touched), (&a.counts, a.touched));
    d.add_divided(&[], 2.0);
    assert_eq!(d.touched, a.touched);
    let mut m = NeesHistogram::new();
    m.merge(&a);
    m.merge(&b);
    let full: Vec<u64> = a.counts.iter().zip(&b.counts).map(|(x, y)| x + y).collect();
    assert_eq!(m.counts, full);
    assert_eq!(m.total(), 8);
    // One read back from a file touches every bin.
    let back: NeesHistogram = serde_json::from_str(&serde_json::to_string(&m).unwrap()).unwrap();
    assert_eq!(back.touched, NeesHistogram::every_bin());
    let mut twice = back.clone();
    twice.merge(&back);
    assert_eq!(twice.total(), 16);
    twice.clear();
    assert_eq!(twice, NeesHistogram::new());
    m.clear();
    assert_eq!(m.counts, NeesHistogram::new().counts);
}

#[test]
fn the_fast_histogram_bin_is_the_bin_of_the_library_log10() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
    let mut worst: f64 = 0.0;
    let mut check = |v: f64| {
        assert_eq!(
            NeesHistogram::bin(v),
            NeesHistogram::exact_bin(v),
            "value {v:e}"
        );
        if let Some(t) = approx_t(v) {
            let exact = (v.log10() - NeesHistogram::LO) * NeesHistogram::PER_DECADE;
            worst = worst.max((t - exact).abs());
        }
    };
    // Log-uniform over 1e-8 .. 1e16 (beyond both ends of the histogram).
    for _ in 0..400_000 {
        let v = 10f64.powf(rng.random_range(-8.0..16.0));
        check(v);
    }
    // Every bin edge and its floating-point neighbours, where the cheap value cannot
    // decide and the library's log10 must.
    for b in 0..=NeesHistogram::BINS + 1 {
        let edge = 10f64.powf(NeesHistogram::LO + b as f64 / NeesHistogram::PER_DECADE);
        let mut v = edge;
        for _ in 0..4 {
            v = v.next_down();
        }
        for _ in 0..9 {
            check(v);
            v = v.next_up();
        }
    }
    // Around the margin: t a few APPROX_T_ERROR from every edge, where the fast path
    // starts or stops deciding.
    for b in 0..=NeesHistogram::BINS + 1 {
        for d in [-3.0, -1.0, -0.5, 0.5, 1.0, 3.0] {
            let t = b as f64 + d * APPROX_T_ERROR;
            check(10f64.powf(NeesHistogram::LO + t / NeesHistogram::PER_DECADE));
        }
    }
    for v in [
        0.0,
        -0.0,
        -1.0,
        f64::MIN_POSITIVE,
        f64::MIN_POSITIVE / 4.0,
        f64::MAX,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
        1.0,
        1e-4,
        1e12,
    ] {
        check(v);
    }
    assert!(worst < 1e-8, "approximation error {worst:e}");
    assert!(worst < APPROX_T_ERROR / 100.0);
}

#[test]
fn records_hand_computed_errors_and_merges() {
    let groups = vec![("a".to_string(), vec![0]), ("b".to_string(), vec![1])];
    let mut s = Sums::new(2, 2, 2);
    let truth = Vector::from_vec(vec![1.0, 2.0]);
    let est = Gaussian::new(
        Vector::from_vec(vec![2.0, 4.0]),
        Matrix::from_diagonal(&Vector::from_vec(vec![1.0, 4.0])),
    );
    let mut t = s.trial(&groups, 2);
    let traffic = Traffic {
        messages: 3,
        bits: 96,
        frame_bits: 400,
        downlink_bits: 64,
        ..Traffic::default()
    };
    t.record(1, &truth, &est, traffic).unwrap();
    t.record(2, &truth, &est, traffic).unwrap();
    t.finish();
    let l = s.layout();
    assert_eq!(s.at(0, l.group(0)), 1.0);
    assert_eq!(s.at(0, l.group(1)), 4.0);
    assert_eq!(s.at(1, Layout::TOTAL_SE), 5.0);
    assert_eq!(s.at(1, Layout::NEES), 2.0); // 1/1 + 4/4
    assert_eq!(s.at(1, Layout::TRACE), 5.0);
    assert_eq!(s.at(1, Layout::BITS), 96.0);
    assert_eq!(s.at(1, Layout::FRAME_BITS), 400.0);
    assert_eq!(s.at(1, Layout::DOWNLINK_BITS), 64.0);
    assert_eq!(s.steady_mse.sum, 5.0);
    assert_eq!(s.per_trial, vec![5.0, 1.0, 4.0]);
    assert_eq!(
        s.per_trial_rows().collect::<Vec<_>>(),
        vec![&[5.0, 1.0, 4.0][..]]
    );
    let mut m = s.clone();
    m.merge(&s);
    assert_eq!(m.trials, 2);
    // Cleared sums are new sums.
    let mut cleared = m.clone();
    cleared.clear();
    assert_eq!(cleared, Sums::new(2, 2, 2));
    assert_eq!(m.at(1, Layout::TOTAL_SE), 10.0);
    let (mean, se) = m.steady_mse.mean_se(2);
    assert_eq!((mean, se), (5.0, 0.0));
}

#[test]
fn second_moments_and_whole_run_averages_give_hand_computed_standard_errors() {
    // One 1-D state, 3 trials x 2 steps; the estimate is off by e(t, k), covariance 1.
    let groups = vec![("x".to_string(), vec![0])];
    let errors = [[1.0, 2.0], [2.0, 0.0], [3.0, 1.0]];
    let mut s = Sums::new(1, 2, 1);
    let truth = Vector::from_vec(vec![0.0]);
    for (t, e) in errors.iter().enumerate() {
        let mut obs = s.trial(&groups, 1);
        for (k, &e) in e.iter().enumerate() {
            let est = Gaussian::new(Vector::from_vec(vec![e]), Matrix::identity(1, 1));
            let traffic = Traffic {
                messages: t as _,
                bits: 8 * k as u64,
                ..Traffic::default()
            };
            obs.record(k + 1, &truth, &est, traffic).unwrap();
        }
        obs.finish();
    }
    // Step 1 squared errors 1, 4, 9: mean 14/3, sample variance (98 - 196/3) / 2 = 49/3,
    // se sqrt(49/9) = 7/3.
    let (m, se) = s.mean_se_at(0, Layout::TOTAL_SE);
    assert!((m - 14.0 / 3.0).abs() < 1e-12);
    assert!((se - 7.0 / 3.0).abs() < 1e-12, "{se}");
    // Per-trial time averages of the squared error: 2.5, 2, 5 -> mean 19/6; sample
    // variance (35.25 - 361/12) / 2 = 31/12, se sqrt(31/36).
    let (m, se) = s.whole_run[Layout::TOTAL_SE].mean_se(3);
    assert!((m - 19.0 / 6.0).abs() < 1e-12);
    assert!((se - (31.0f64 / 36.0).sqrt()).abs() < 1e-12, "{se}");
    // Messages: trial t sends t per step; whole-run averages 0, 1, 2 -> se 1 / sqrt(3).
    let (m, se) = s.whole_run[Layout::MESSAGES].mean_se(3);
    assert_eq!(m, 1.0);
    assert!((se - 1.0 / 3f64.sqrt()).abs() < 1e-12);
    // Bits are 0 at step 1 and 8 at step 2 in every trial: no spread at either step.
    assert_eq!(s.mean_se_at(1, Layout::BITS), (8.0, 0.0));
    // Merging two halves gives the same second moments as one pass.
    let mut m2 = Sums::new(1, 2, 1);
    m2.merge(&s);
    assert_eq!(m2.per_step_sq, s.per_step_sq);
    assert_eq!(m2.whole_run, s.whole_run);
}

#[test]
fn link_counters_are_summed_per_step_and_merge() {
    let groups = vec![("x".to_string(), vec![0])];
    let truth = Vector::from_vec(vec![0.0]);
    let est = Gaussian::new(Vector::from_vec(vec![0.5]), Matrix::identity(1, 1));
    let mut s = Sums::new(1, 2, 1);
    let mut t = s.trial(&groups, 1);
    // Step 1: nothing for the link to count. Step 2: an ARQ step.
    t.record(1, &truth, &est, Traffic::default()).unwrap();
    let arq = Traffic {
        messages: 2,
        lost: 1,
        retransmissions: 3,
        duplicates: 1,
        ack_frames: 2,
        ack_bits: 176,
        ..Traffic::default()
    };
    t.record(2, &truth, &est, arq).unwrap();
    t.finish();
    assert_eq!(LINK_COUNTERS[4], "retransmissions");
    assert_eq!(s.link, vec![[0; LINK_FIELDS], [1, 0, 0, 0, 3, 1, 2, 176]]);
    let mut m = s.clone();
    m.merge(&s);
    assert_eq!(m.link[1], [2, 0, 0, 0, 6, 2, 4, 352]);
    // Sums that never saw the link merge into ones that did, and the other way round.
    let mut empty = Sums::new(1, 2, 1);
    empty.merge(&s);
    assert_eq!(empty.link, s.link);
    let mut m2 = s.clone();
    m2.merge(&Sums::new(1, 2, 1));
    assert_eq!(m2.link, s.link);
}

/// Two estimators of a 2-state target, one step, every value by hand: node 0 at (1, 0) with
/// P = I, node 1 at (0, 2) with P = 2I, the truth at 0.
#[test]
fn many_estimators_record_their_mean_and_each_node_by_hand() {
    let groups = vec![("position".to_string(), vec![0])];
    let mut sums = Sums::new(1, 1, 2);
    let truth = Vector::zeros(2);
    let a = Gaussian::new(Vector::from_vec(vec![1.0, 0.0]), Matrix::identity(2, 2));
    let b = Gaussian::new(
        Vector::from_vec(vec![0.0, 2.0]),
        Matrix::identity(2, 2) * 2.0,
    );
    let mut state = sums.trial_state(&groups, 1);
    state
        .record_estimators(&mut sums, 1, &truth, (&[&a, &b], None), Traffic::default())
        .unwrap();
    state.finish(&mut sums);
    // Squared errors (1, 0) and (0, 4): their mean per component (0.5, 2), total 2.5; NEES 1
    // and 4 / 2 = 2, mean 1.5; traces 2 and 4, mean 3; both NEES under the chi-square(2)
    // quantiles (5.99, 9.21).
    assert_eq!(sums.at(0, Layout::TOTAL_SE), 2.5);
    // (The NEES goes through a Cholesky factor: √2 rounds.)
    let near = |a: f64, b: f64| (a - b).abs() < 1e-12;
    assert!(near(sums.at(0, Layout::NEES), 1.5));
    assert_eq!(sums.at(0, Layout::TRACE), 3.0);
    assert_eq!(sums.at(0, Layout::NEES_COVERED), 1.0);
    assert_eq!(sums.at(0, Layout::NEES_COVERED_95), 1.0);
    assert_eq!(sums.at(0, Layout { groups: 1 }.group(0)), 0.5);
    assert_eq!(sums.steady_mse.sum, 2.5);
    assert!(near(sums.steady_nees.sum, 1.5));
    // Each node on its own; the mean estimate (0.5, 1), each node 1.25 away squared.
    assert_eq!(sums.estimators.len(), 2);
    assert_eq!(
        (sums.estimators[0].mse.sum, sums.estimators[0].nees.sum),
        (1.0, 1.0)
    );
    assert_eq!(sums.estimators[1].mse.sum, 4.0);
    assert!(near(sums.estimators[1].nees.sum, 2.0));
    assert_eq!(sums.disagreement.sum, 1.25);
    // A node far out of its bound counts as a fraction of the nodes.
    let mut far = Sums::new(1, 1, 2);
    let c = Gaussian::new(Vector::from_vec(vec![10.0, 0.0]), Matrix::identity(2, 2));
    let mut state = far.trial_state(&groups, 1);
    state
        .record_estimators(&mut far, 1, &truth, (&[&a, &c], None), Traffic::default())
        .unwrap();
    state.finish(&mut far);
    assert_eq!(far.at(0, Layout::NEES_COVERED), 0.5);
}

/// Per-node sums merge as the other sums do: two trials added into one, or each into its own
/// and merged, give the same numbers.
#[test]
fn many_estimator_sums_merge_like_one_run() {
    let groups = vec![("position".to_string(), vec![0])];
    let truth = Vector::zeros(2);
    let g = |x: f64, y: f64| Gaussian::new(Vector::from_vec(vec![x, y]), Matrix::identity(2, 2));
    let trials = [[g(1.0, 0.5), g(-0.5, 2.0)], [g(0.2, 0.1), g(3.0, -1.0)]];
    let run = |sums: &mut Sums, t: &[Gaussian; 2]| {
        let mut state = sums.trial_state(&groups, 1);
        state
            .record_estimators(sums, 1, &truth, (&[&t[0], &t[1]], None), Traffic::default())
            .unwrap();
        state.finish(sums);
    };
    let mut one = Sums::new(1, 1, 2);
    trials.iter().for_each(|t| run(&mut one, t));
    let mut merged = Sums::new(1, 1, 2);
    for t in &trials {
        let mut part = Sums::new(1, 1, 2);
        run(&mut part, t);
        merged.merge(&part);
    }
    assert_eq!(one, merged);
    assert_eq!(one.estimators[1].mse.sum, 0.25 + 4.0 + 9.0 + 1.0);
}

/// The estimates' NEES factors, where the caller has them (`fixed::nees_factor` of each
/// covariance, as the lock-step consensus loop keeps them), give the sums of factoring in the
/// recorder bit for bit; a wrong factor would show (checked: a factor of 2P moves the NEES).
#[test]
fn estimators_recorded_with_their_nees_factors_are_the_same_sums() {
    let groups = vec![("position".to_string(), vec![0])];
    let truth = Vector::from_vec(vec![0.3, -0.2]);
    let p = |a: f64, b: f64, c: f64| Matrix::from_row_slice(2, 2, &[a, b, b, c]);
    let est = [
        Gaussian::new(Vector::from_vec(vec![1.0, 0.1]), p(1.3, 0.4, 0.9)),
        Gaussian::new(Vector::from_vec(vec![-0.7, 2.0]), p(2.1, -0.3, 0.5)),
    ];
    let factors: Vec<f64> = est
        .iter()
        .flat_map(|g| crate::linalg::fixed::nees_factor(&g.cov).unwrap())
        .collect();
    let run = |factors: Option<&[f64]>| {
        let mut sums = Sums::new(1, 1, 2);
        let mut state = sums.trial_state(&groups, 1);
        let refs = [&est[0], &est[1]];
        state
            .record_estimators(&mut sums, 1, &truth, (&refs, factors), Traffic::default())
            .unwrap();
        state.finish(&mut sums);
        sums
    };
    assert_eq!(run(Some(&factors)), run(None));
    let doubled: Vec<f64> = est
        .iter()
        .flat_map(|g| crate::linalg::fixed::nees_factor(&(&g.cov * 2.0)).unwrap())
        .collect();
    assert_ne!(run(Some(&doubled)).steady_nees, run(None).steady_nees);
}

/// `record_shared` (a lockstep batch sharing one covariance; its trials as lanes, its step sums
/// added field by field) gives the sums of recording each trial alone with the factor, bit for
/// bit: every state dimension it takes in lanes (and 7, which it does not), 1 to 9 trials
/// (groups of four and a partial group), enough steady steps to flush the pending NEES, and a
/// trial whose NEES stays beyond the divergence bound.
#[test]
fn a_shared_covariance_batch_records_what_its_trials_record_alone() {
    use crate::linalg::fixed::nees_factor;
    use rand::{Rng, SeedableRng};
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
    let steps = 45;
    let traffic = Traffic {
        messages: 2,
        bits: 64,
        frame_bits: 300,
        ..Traffic::default()
    };
    for n in [1usize, 2, 3, 6, 7] {
        let groups = vec![
            ("first".to_string(), vec![0]),
            ("all".to_string(), (0..n).collect()),
        ];
        for trials in [1usize, 3, 4, 5, 9] {
            // Per step: a covariance A A^T + I, and every trial's truth and mean.
            let covs: Vec<Matrix> = (0..steps)
                .map(|_| {
                    let a = Matrix::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
                    &a * a.transpose() + Matrix::identity(n, n)
                })
                .collect();
            let truths: Vec<Vec<Vector>> = (0..trials)
                .map(|_| {
                    (0..steps)
                        .map(|_| Vector::from_fn(n, |_, _| rng.random_range(-5.0..5.0)))
                        .collect()
                })
                .collect();
            // Trial 1 is far off for 12 steps in a row: it diverges.
            let means: Vec<Vec<Vector>> = (0..trials)
                .map(|j| {
                    (0..steps)
                        .map(|k| {
                            let off = if j == 1 && (10..22).contains(&k) {
                                1e3
                            } else {
                                1.0
                            };
                            let noise =
                                Vector::from_fn(n, |_, _| off * rng.random_range(-1.0..1.0));
                            &truths[j][k] + noise
                        })
                        .collect()
                })
                .collect();
            let mut batch = Sums::new(groups.len(), steps, n);
            let mut states: Vec<_> = (0..trials).map(|_| batch.trial_state(&groups, 3)).collect();
            let truth_refs: Vec<&[Vector]> = truths.iter().map(|t| t.as_slice()).collect();
            for k in 1..=steps {
                let factor = nees_factor(&covs[k - 1]);
                let flat: Vec<f64> = means
                    .iter()
                    .flat_map(|m| m[k - 1].iter().copied())
                    .collect();
                let mut shared = Gaussian::new(Vector::zeros(n), covs[k - 1].clone());
                let r = record_shared(
                    &mut states,
                    &mut batch,
                    k,
                    &truth_refs,
                    &flat,
                    &mut shared,
                    factor.as_deref(),
                    traffic,
                );
                r.unwrap();
            }
            states.iter_mut().for_each(|s| s.close(&mut batch));
            let mut alone = Sums::new(groups.len(), steps, n);
            for j in 0..trials {
                let mut state = alone.trial_state(&groups, 3);
                for k in 1..=steps {
                    let est = Gaussian::new(means[j][k - 1].clone(), covs[k - 1].clone());
                    match nees_factor(&covs[k - 1]) {
                        Some(f) => state.record_factored(
                            &mut alone,
                            k,
                            &truths[j][k - 1],
                            &est,
                            &f,
                            traffic,
                        ),
                        None => state.record(&mut alone, k, &truths[j][k - 1], &est, traffic),
                    }
                    .unwrap();
                }
                state.close(&mut alone);
            }
            assert!(
                alone.diverged == usize::from(trials > 1),
                "n {n}, {trials} trials: trial 1 diverges"
            );
            let bits = |s: &Sums| serde_json::to_string(s).unwrap();
            assert_eq!(bits(&batch), bits(&alone), "n {n}, {trials} trials");
        }
    }
}

/// `add_divided` (bins decided four at a time, in chunks of 32, the undecided ones by the
/// library's log10) counts every `v / divisor` in the bin `exact_bin` gives, with the touched
/// range around them: values of every kind (bin edges and their neighbours, both ends,
/// zero, negative, subnormal, infinite, NaN), more than one chunk, a divisor that is not 1.
#[test]
fn counting_divided_values_puts_each_in_its_exact_bin() {
    let divisor = 3.0;
    let mut values: Vec<f64> = vec![0.0, -2.0, 1e-310, f64::INFINITY, f64::NAN, 1e20, 1e-9];
    for b in (0..=NeesHistogram::BINS + 1).step_by(7) {
        let edge = 10f64.powf(NeesHistogram::LO + b as f64 / NeesHistogram::PER_DECADE);
        values.extend([edge.next_down(), edge, edge.next_up(), edge * 1.01].map(|v| v * divisor));
    }
    assert!(values.len() > 100);
    let mut h = NeesHistogram::new();
    h.add_divided(&values, divisor);
    let mut want = NeesHistogram::new();
    for &v in &values {
        let b = NeesHistogram::exact_bin(v / divisor);
        want.counts[b] += 1;
        want.touch(b, b + 1);
    }
    assert_eq!(h.counts, want.counts);
    assert_eq!(h.touched, want.touched);
}

/// Four trials recorded side by side (`QuadTrials`, lane j: trial j) give the sums of
/// recording each trial alone, serialized bit for bit: state dimensions 1 to 6, two groups,
/// steady state from step 3, 45 steps (more steady NEES than one flush of a trial), one trial
/// that diverges and one with a NaN mean at one step. A factor with a zero diagonal, a
/// missing factor and a state of 7 are refused with nothing recorded.
#[test]
fn four_trials_side_by_side_record_what_each_records_alone() {
    use crate::linalg::fixed::nees_factor;
    use crate::linalg::quad::F64x4;
    use rand::{Rng, SeedableRng};
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(11);
    let steps = 45;
    let traffic = Traffic {
        messages: 3,
        bits: 96,
        frame_bits: 500,
        downlink_bits: 7,
        scheduled: 0b101,
        senders: 0b100,
        ..Traffic::default()
    };
    for n in 1..=6usize {
        let groups = vec![
            ("first".to_string(), vec![0]),
            ("all".to_string(), (0..n).collect()),
        ];
        let covs: Vec<Matrix> = (0..steps)
            .map(|_| {
                let a = Matrix::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
                &a * a.transpose() + Matrix::identity(n, n)
            })
            .collect();
        let truths: Vec<Vec<Vector>> = (0..4)
            .map(|_| {
                (0..steps)
                    .map(|_| Vector::from_fn(n, |_, _| rng.random_range(-5.0..5.0)))
                    .collect()
            })
            .collect();
        // Trial 2 is far off for 12 steps in a row (it diverges); trial 3 has a NaN at step 30.
        let means: Vec<Vec<Vector>> = (0..4)
            .map(|j| {
                (0..steps)
                    .map(|k| {
                        let off = if j == 2 && (10..22).contains(&k) {
                            1e3
                        } else {
                            1.0
                        };
                        let mut m = &truths[j][k]
                            + Vector::from_fn(n, |_, _| off * rng.random_range(-1.0..1.0));
                        if j == 3 && k == 29 {
                            m[0] = f64::NAN;
                        }
                        m
                    })
                    .collect()
            })
            .collect();
        let side = |v: &[Vector], c: usize| F64x4(std::array::from_fn(|j| v[j][c]));
        let mut quad = Sums::new(groups.len(), steps, n);
        let mut lanes = QuadTrials::new(&quad, 3).unwrap();
        for k in 1..=steps {
            let factor = nees_factor(&covs[k - 1]).unwrap();
            let t: Vec<Vector> = truths.iter().map(|t| t[k - 1].clone()).collect();
            let m: Vec<Vector> = means.iter().map(|m| m[k - 1].clone()).collect();
            let truth: Vec<F64x4> = (0..n).map(|c| side(&t, c)).collect();
            let mean: Vec<F64x4> = (0..n).map(|c| side(&m, c)).collect();
            let cov = &covs[k - 1];
            assert!(lanes.record(
                &mut quad,
                &groups,
                k,
                &truth,
                &mean,
                cov,
                Some(&factor),
                traffic
            ));
            if k == 7 {
                // Refused, nothing recorded: a zero diagonal, no factor, a factor too short.
                let mut zero = factor.clone();
                zero[(n - 1) * n + n - 1] = 0.0;
                let before = serde_json::to_string(&quad).unwrap();
                assert!(!lanes.record(
                    &mut quad,
                    &groups,
                    k,
                    &truth,
                    &mean,
                    cov,
                    Some(&zero),
                    traffic
                ));
                assert!(!lanes.record(&mut quad, &groups, k, &truth, &mean, cov, None, traffic));
                assert!(!lanes.record(
                    &mut quad,
                    &groups,
                    k,
                    &truth,
                    &mean,
                    cov,
                    Some(&factor[1..]),
                    traffic
                ));
                assert_eq!(serde_json::to_string(&quad).unwrap(), before);
            }
        }
        let mut states: Vec<_> = (0..4).map(|_| quad.trial_state(&groups, 3)).collect();
        lanes.close(&mut quad, &mut states);
        let mut alone = Sums::new(groups.len(), steps, n);
        for j in 0..4 {
            let mut state = alone.trial_state(&groups, 3);
            for k in 1..=steps {
                let est = Gaussian::new(means[j][k - 1].clone(), covs[k - 1].clone());
                let f = nees_factor(&covs[k - 1]).unwrap();
                state
                    .record_factored(&mut alone, k, &truths[j][k - 1], &est, &f, traffic)
                    .unwrap();
            }
            state.close(&mut alone);
        }
        assert_eq!(alone.diverged, 2, "n {n}: trials 2 and 3 diverge");
        assert_eq!(
            alone.sensors,
            [[4 * steps as u64, 0], [0, 0], [4 * steps as u64; 2]]
        );
        let bits = |s: &Sums| serde_json::to_string(s).unwrap();
        assert_eq!(bits(&quad), bits(&alone), "n {n}");
        assert_eq!(quad.nees_hist, alone.nees_hist, "n {n}");
    }
    let wide = Sums::new(1, 3, 7);
    let mut lanes = QuadTrials::new(&wide, 1).unwrap();
    let seven = vec![F64x4::splat(1.0); 7];
    let mut wide = wide;
    let eye = Matrix::identity(7, 7);
    let groups = vec![("all".to_string(), (0..7).collect())];
    let factor = vec![1.0; 49];
    assert!(!lanes.record(
        &mut wide,
        &groups,
        1,
        &seven,
        &seven,
        &eye,
        Some(&factor),
        traffic
    ));
    assert!(QuadTrials::new(&Sums::new(STACK_WIDTH, 3, 2), 1).is_none());
}
