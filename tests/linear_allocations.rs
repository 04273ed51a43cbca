//! The linear-Gaussian schemes allocate nothing per step once their shared, data-independent
//! matrices are computed: a fusion center step allocates nothing at all, a sensor step only
//! the message it sends (the `Message` owns its vector). On the default scenario: the
//! centralized KF, the globalized DKF, Algorithms 1 and 2. On arena-1d: Zhang et al.'s (2016)
//! quantized-innovation KF, the event-triggered filters, Geng et al.'s federated Tobit filter and
//! round-robin KF, and the estimate fusions (covariance intersection, naive). The centralized KF with random
//! losses, whose covariance depends on the data and is computed per step in buffers,
//! allocates nothing either where the fixed-size kernels reproduce matrixmultiply's 6 x 6
//! products (x86-64 with FMA), and otherwise only matrixmultiply's packing buffers of its two
//! products: a constant per step. Counted by a global allocator that counts the calls made on
//! the current thread.
use hushfuse::engine::runner;
use hushfuse::link::{Received, Transmission};
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
use rand::SeedableRng;
#[path = "common/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations;

/// Per step of one trial of `variant`: (sensor allocations, messages sent, center allocations).
/// The trial is run three times on the same data and coins; the third run is reported, so
/// every memoized matrix it needs has been seen twice and kept (see `CovarianceMemo`).
fn per_step(exp: &build::Experiment, variant: &build::Variant) -> Vec<(usize, usize, usize)> {
    let data = runner::draw_trial(exp, 3);
    let mut out = Vec::new();
    for _ in 0..3 {
        out.clear();
        let mut inst = variant.scheme.build().unwrap();
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(11);
        let mut inbox: Vec<Received> = Vec::with_capacity(exp.system.n_sensors());
        for k in 1..=exp.steps {
            inbox.clear();
            let before = allocations();
            let mut sent = 0;
            for (i, node) in inst.sensors.iter_mut().enumerate() {
                let t = node
                    .step(k, &data.measurements[k - 1][i], None, &mut rng)
                    .unwrap();
                sent += usize::from(matches!(t, Transmission::Send(_)));
                inbox.push(Received::from(t));
            }
            let sensors = allocations() - before;
            let before = allocations();
            inst.center.step(k, &inbox).unwrap();
            let center = allocations() - before;
            out.push((sensors, sent, center));
        }
    }
    out
}

/// Whether `linalg::fixed::gemm` reproduces matrixmultiply's 6 x 6 products itself (its FMA
/// kernels), rather than calling it.
fn fma_kernel() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("fma") && std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[test]
fn linear_schemes_allocate_nothing_per_step() {
    let mut exp = build::load(builtin::get("default").unwrap(), "default").unwrap();
    exp.steps = 40;
    let mut checked = 0;
    for variant in &exp.variants {
        let label = &exp.curves[variant.curve].label;
        let kind = exp.curves[variant.curve].kind.as_str();
        let steps = per_step(&exp, variant);
        for (k, &(sensors, sent, center)) in steps.iter().enumerate() {
            // One allocation per message: the vector the message owns.
            assert_eq!(
                sensors,
                sent,
                "{label} ({kind}) step {}: sensor side",
                k + 1
            );
            if kind == "centralized-kf-random" && k == 0 {
                // The first step off the all-data schedule makes the center's buffers.
            } else if kind == "centralized-kf-random" && !fma_kernel() {
                // F P F^T for the 6-D state: nalgebra hands 6 x 6 products to matrixmultiply,
                // which allocates its two packing buffers per product. Those products fix the
                // summation order of the published numbers; with FMA the fixed-size kernel
                // reproduces them (and allocates nothing), without it they stay: a constant two
                // per step, never growing (everything else is in the center's buffers).
                assert_eq!(center, 2, "{label} step {}: fusion center", k + 1);
            } else {
                assert_eq!(center, 0, "{label} ({kind}) step {}: fusion center", k + 1);
            }
        }
        checked += 1;
    }
    assert!(checked >= 5, "the default scenario has the linear schemes");
    // The counter sees this thread's allocations at all (the test can fail).
    let before = allocations();
    let v = hushfuse::linalg::Vector::zeros(3);
    assert!(allocations() > before);
    drop(v);
}

/// Per step of one trial of `variant` with the center's feedback passed to the sensors:
/// (sensor allocations, messages sent, center-step allocations, feedback allocations),
/// the third of three runs on the same data and coins (as [`per_step`]).
fn per_step_with_feedback(
    exp: &build::Experiment,
    variant: &build::Variant,
) -> Vec<(usize, usize, usize, usize)> {
    let data = runner::draw_trial(exp, 3);
    let mut out = Vec::new();
    for _ in 0..3 {
        out.clear();
        let mut inst = variant.scheme.build_with_seed(5).unwrap();
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(11);
        let mut inbox: Vec<Received> = Vec::with_capacity(exp.system.n_sensors());
        let mut feedback = inst.center.feedback();
        for k in 1..=exp.steps {
            inbox.clear();
            let before = allocations();
            let mut sent = 0;
            for (i, node) in inst.sensors.iter_mut().enumerate() {
                let t = node
                    .step(k, &data.measurements[k - 1][i], feedback.as_ref(), &mut rng)
                    .unwrap();
                sent += usize::from(matches!(t, Transmission::Send(_)));
                inbox.push(Received::from(t));
            }
            let sensors = allocations() - before;
            let before = allocations();
            inst.center.step(k, &inbox).unwrap();
            let center = allocations() - before;
            let before = allocations();
            feedback = inst.center.feedback();
            let fed = allocations() - before;
            out.push((sensors, sent, center, fed));
        }
    }
    out
}

/// The other linear-Gaussian schemes of issue 12 on `arena-1d`, each at the allowance: a
/// sensor step allocates one vector per message sent, a fusion-center step nothing. The
/// feedback (`FusionCenter::feedback`) returns an owned `Feedback` and allocates only what it
/// holds, counted apart: Zhang et al.'s (2016) y_hat and Delta per sensor (one vector), the innovation
/// trigger's fused prediction with its covariance (a vector and a matrix), the closed-loop
/// stochastic trigger's prediction without it (a vector), nothing for the open loop and
/// send-on-delta (no feedback), nothing for the federated Tobit filter and the estimate
/// fusions (no feedback). Every step is checked, the first too, where the centers make their
/// buffers when they are built (the round-robin KF makes them on its first step).
#[test]
fn other_linear_schemes_at_the_allowance() {
    let mut exp = build::load(builtin::get("arena-1d").unwrap(), "arena-1d").unwrap();
    exp.steps = 30;
    // (kind, the allocations of its feedback, the steps its center makes its buffers in).
    let fixed = [
        ("quantized-innovation", 1, 0),
        ("innovation-trigger-kf", 2, 0),
        ("stochastic-trigger-open", 0, 0),
        ("stochastic-trigger-closed", 1, 0),
        ("send-on-delta", 0, 0),
        ("federated-tobit", 0, 0),
        // Its KF's buffers are made on the first step.
        ("round-robin-kf", 0, 1),
        ("ci-fusion", 0, 0),
        ("naive-fusion", 0, 0),
    ];
    let mut checked = 0;
    for variant in &exp.variants {
        let label = &exp.curves[variant.curve].label;
        let kind = exp.curves[variant.curve].kind.as_str();
        let steps = per_step_with_feedback(&exp, variant);
        // The counts of every scheme, asserted or not: `cargo test --release --test
        // linear_allocations -- --nocapture` prints them (steps 11..=30).
        let mean = |f: fn(&(usize, usize, usize, usize)) -> usize| {
            steps[10..].iter().map(f).sum::<usize>() as f64 / steps[10..].len() as f64
        };
        println!(
            "{kind}: per step, sensor allocations {:.1} (messages {:.1}), center {:.1}, feedback {:.1}",
            mean(|s| s.0),
            mean(|s| s.1),
            mean(|s| s.2),
            mean(|s| s.3)
        );
        let Some(&(_, feedback, warm_up)) = fixed.iter().find(|f| f.0 == kind) else {
            continue;
        };
        for (k, &(sensors, sent, center, fed)) in steps.iter().enumerate() {
            let step = k + 1;
            assert_eq!(sensors, sent, "{label} ({kind}) step {step}: sensor side");
            if step > warm_up {
                assert_eq!(center, 0, "{label} ({kind}) step {step}: fusion center");
            }
            assert_eq!(
                fed, feedback,
                "{label} ({kind}) step {step}: feedback allocations"
            );
        }
        checked += 1;
    }
    assert_eq!(
        checked,
        fixed.len(),
        "arena-1d has each of these schemes once"
    );
}
