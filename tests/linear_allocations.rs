//! The linear-Gaussian schemes (centralized KF, globalized DKF, Algorithms 1 and 2) allocate
//! nothing per step once their shared, data-independent matrices are computed: a fusion center
//! step allocates nothing at all, a sensor step only the message it sends (the `Message`
//! owns its vector). The centralized KF with random losses, whose covariance depends on the
//! data and is computed per step in buffers, allocates nothing either where the fixed-size
//! kernels reproduce matrixmultiply's 6 x 6 products (x86-64 with FMA), and otherwise only
//! matrixmultiply's packing buffers of its two products: a constant per step. Counted by a global allocator that counts the
//! calls made on the current thread.
use hushfuse::link::{Received, Transmission};
use hushfuse::sim::{build, builtin, runner};
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

/// Whether `filter::fixed::gemm` reproduces matrixmultiply's 6 x 6 products itself (its FMA
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
