//! The particle-filter fusion center allocates nothing per particle: the allocations of a step
//! (a few small vectors and matrices of the reference point and the fed-back prediction) are
//! the same with 200 particles as with 5,000. Counted by a global allocator that counts the
//! calls made on the current thread.
use hushfuse::linalg::Vector;
use hushfuse::link::Received;
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
#[path = "common/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations;

const STEPS: usize = 15;
const COUNTED_FROM: usize = 6;

/// Allocations of the fusion center of `scheme` in `scenario` (particles replaced by
/// `particles`) over steps COUNTED_FROM..=STEPS, fed a fixed inbox sequence: sensor i sends the
/// noise-free measurement of the prior mean's path at steps k with k + i even, and is silent
/// otherwise. A first uncounted run warms the per-thread band-table cache.
fn center_allocations(scenario: &str, from: &str, scheme: &str, particles: usize) -> usize {
    let text = builtin::get(scenario).unwrap().replace(
        &format!("particles = {from}"),
        &format!("particles = {particles}"),
    );
    let exp = build::load(&text, scenario).unwrap();
    let variant = exp
        .variants
        .iter()
        .find(|v| exp.curves[v.curve].label == scheme)
        .unwrap();
    let sys = &exp.system;
    let mut count = 0;
    for counted in [false, true] {
        let mut inst = variant.scheme.build_with_seed(7).unwrap();
        let mut x = sys.prior.mean.clone();
        let mut inbox: Vec<Received> = Vec::with_capacity(sys.n_sensors());
        for k in 1..=STEPS {
            x = sys.transition.f() * &x;
            inbox.clear();
            for (i, s) in sys.sensors.iter().enumerate() {
                inbox.push(if (k + i) % 2 == 0 {
                    Received::Measurement(s.predict(&x))
                } else {
                    Received::Silent
                });
            }
            let before = allocations();
            inst.center.step(k, &inbox).unwrap();
            let fb = inst.center.feedback();
            if counted && k >= COUNTED_FROM {
                count += allocations() - before;
            }
            drop(fb);
        }
    }
    count
}

#[test]
fn fusion_center_allocations_do_not_grow_with_particles() {
    for (scenario, from, scheme) in [
        ("zheng-fig1", "1000", "CFwMD"),
        ("zheng-fig1", "1000", "CFoMD"),
        ("zheng-fig2-table1", "1000", "CFwMD2"),
        ("zheng-fig8", "10000", "CFwMD"),
    ] {
        let small = center_allocations(scenario, from, scheme, 200);
        let large = center_allocations(scenario, from, scheme, 5000);
        assert_eq!(small, large, "{scenario} {scheme}: allocations per run");
        // A handful of small vectors and matrices per step and sensor, whatever the cloud.
        let sensors = build::load(builtin::get(scenario).unwrap(), scenario)
            .unwrap()
            .system
            .n_sensors();
        let per_step_sensor = small as f64 / ((STEPS - COUNTED_FROM + 1) * sensors) as f64;
        println!("{scenario} {scheme}: {per_step_sensor} allocations per step and sensor");
        assert!(
            per_step_sensor <= 30.0,
            "{scenario} {scheme}: {per_step_sensor} per step and sensor"
        );
    }
    // The counter sees this thread's allocations at all (the test can fail).
    let before = allocations();
    let v = Vector::zeros(3);
    assert!(allocations() > before);
    drop(v);
}
