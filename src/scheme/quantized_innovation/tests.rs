use super::*;
use crate::linalg::matrix_from_rows;
use crate::model::{presets, LinearSensor, LinearTransition};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

fn system(q_scale: f64) -> Arc<System> {
    let base = presets::constant_velocity_2d(1.0, 0.1).unwrap();
    let transition = LinearTransition::new(base.f().clone(), base.q() * q_scale).unwrap();
    let sensors: Vec<Arc<dyn MeasurementModel>> = vec![
        Arc::new(
            LinearSensor::new(
                matrix_from_rows(&[vec![1.0, 0.0, 0.0, 0.0]]),
                Matrix::from_element(1, 1, 4.0),
            )
            .unwrap(),
        ),
        Arc::new(
            LinearSensor::new(
                matrix_from_rows(&[vec![0.0, 0.0, 1.0, 0.0]]),
                Matrix::from_element(1, 1, 4.0),
            )
            .unwrap(),
        ),
        Arc::new(
            LinearSensor::new(
                matrix_from_rows(&[vec![0.6, 0.0, 0.8, 0.0]]),
                Matrix::from_element(1, 1, 2.0),
            )
            .unwrap(),
        ),
    ];
    let prior = Gaussian::new(
        Vector::from_vec(vec![0.0, 1.0, 0.0, 1.0]),
        Matrix::from_diagonal(&Vector::from_vec(vec![10.0, 1.0, 10.0, 1.0])),
    );
    Arc::new(System {
        transition,
        sensors,
        prior,
    })
}

/// Runs `steps` steps of a scheme on data drawn from the system; returns the squared
/// position errors summed over steps 21..=steps.
fn run(scheme: &QuantizedInnovationScheme, sys: &System, seed: u64, steps: usize) -> f64 {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut inst = scheme.build().unwrap();
    let mut x = sys.prior.mean.clone();
    let mut feedback = inst.center.feedback();
    let mut total = 0.0;
    for k in 1..=steps {
        x = sys.transition.sample_next(&x, &mut rng);
        let inbox: Vec<Received> = inst
            .sensors
            .iter_mut()
            .zip(&sys.sensors)
            .map(|(node, s)| {
                let z = s.sample(&x, &mut rng);
                node.step(k, &z, feedback.as_ref(), &mut rng)
                    .unwrap()
                    .into()
            })
            .collect();
        inst.center.step(k, &inbox).unwrap();
        feedback = inst.center.feedback();
        if k > 20 {
            let e = &inst.center.estimate().mean - &x;
            total += e[0] * e[0] + e[2] * e[2];
        }
    }
    total
}

/// With many levels (L = 101) the quantized filter approaches the analog KF: on the same
/// data its position MSE is within 1% of the analog one, while 2-bit Msechu (L = 4,
/// rho = 0.88) is clearly worse — so the comparison can fail.
#[test]
fn many_levels_approach_the_analog_kf() {
    let sys = system(1.0);
    let make = |q: QuantizerChoice| {
        QuantizedInnovationScheme::new(sys.clone(), &q, Activation::All).unwrap()
    };
    let fine = make(QuantizerChoice::LloydMax { levels: 101 });
    let coarse = make(QuantizerChoice::Msechu { bits: 2 });
    let analog = make(QuantizerChoice::Analog);
    let (mut f, mut c, mut a) = (0.0, 0.0, 0.0);
    for seed in 0..300 {
        f += run(&fine, &sys, seed, 60);
        c += run(&coarse, &sys, seed, 60);
        a += run(&analog, &sys, seed, 60);
    }
    assert!((f / a - 1.0).abs() < 0.01, "L = 101: {f} vs analog {a}");
    assert!(c / a > 1.05, "L = 4 should be clearly worse: {c} vs {a}");
}

/// Eq. (15): averaged over the data, one quantized update reduces the covariance by rho
/// times the analog reduction. Each draw gives the reduction factor eta of its level; its
/// mean must match rho within 4 standard errors (sample standard deviation / sqrt(n)).
#[test]
fn mean_covariance_reduction_is_rho_times_analog() {
    for choice in [
        QuantizerChoice::Zhang {
            bits: 1,
            flag_zone: true,
        },
        QuantizerChoice::You { bits: 2 },
        QuantizerChoice::Msechu { bits: 1 },
    ] {
        // One sensor, a prediction that is exactly the prior (F = I, Q = 0).
        let mut sys = (*system(0.0)).clone();
        sys.transition =
            LinearTransition::new(Matrix::identity(4, 4), Matrix::zeros(4, 4)).unwrap();
        sys.sensors.truncate(1);
        let sys = Arc::new(sys);
        let scheme = QuantizedInnovationScheme::new(sys.clone(), &choice, Activation::All).unwrap();
        let rho = scheme.link.as_ref().unwrap().quantizer.rho();
        let p = &sys.prior.cov;
        let h = sys.sensors[0].jacobian(&sys.prior.mean);
        let analog =
            (p * h.transpose() * &h * p).trace() / ((&h * p * h.transpose())[(0, 0)] + 4.0);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(17);
        let chol = p.clone().cholesky().unwrap().l();
        let n = 20_000;
        let (mut s1, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let w = Vector::from_fn(4, |_, _| StandardNormal.sample(&mut rng));
            let x = &sys.prior.mean + &chol * w;
            let z = sys.sensors[0].sample(&x, &mut rng);
            let mut inst = scheme.build().unwrap();
            let fb = inst.center.feedback();
            let t = inst.sensors[0].step(1, &z, fb.as_ref(), &mut rng).unwrap();
            inst.center.step(1, &[t.into()]).unwrap();
            let ratio = (p - &inst.center.estimate().cov).trace() / analog;
            s1 += ratio;
            s2 += ratio * ratio;
        }
        let mean = s1 / n as f64;
        let se = ((s2 / n as f64 - mean * mean) / n as f64).sqrt();
        assert!(
            (mean - rho).abs() < 4.0 * se + 1e-12,
            "{choice:?}: {mean} vs rho {rho} (se {se})"
        );
    }
}

/// A corrupt frame is an error at the fusion center, never a panic or a wrong level.
#[test]
fn corrupt_frames_are_rejected() {
    let sys = system(1.0);
    let scheme = QuantizedInnovationScheme::new(
        sys.clone(),
        &QuantizerChoice::Zhang {
            bits: 2,
            flag_zone: true,
        },
        Activation::All,
    )
    .unwrap();
    let mut inst = scheme.build().unwrap();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
    let fb = inst.center.feedback();
    // A large innovation is sure to be sent.
    let t = inst.sensors[0]
        .step(1, &Vector::from_element(1, 40.0), fb.as_ref(), &mut rng)
        .unwrap();
    let Transmission::Send(Message::Frame { mut octets, .. }) = t else {
        panic!("expected a frame")
    };
    octets[9] ^= 0x10; // flip a payload bit
    let inbox = vec![Received::Frame(octets), Received::Silent, Received::Silent];
    let err = inst.center.step(1, &inbox).unwrap_err();
    assert!(err.to_string().contains("corrupt frame"), "{err}");
    let err = inst
        .center
        .step(
            1,
            &[
                Received::Frame(vec![1, 2, 3]),
                Received::Silent,
                Received::Silent,
            ],
        )
        .unwrap_err();
    assert!(err.to_string().contains("corrupt frame"), "{err}");
}

/// The silent centre level still updates: the covariance shrinks by eta of the centre
/// cell although nothing arrived.
#[test]
fn silence_is_an_update() {
    let sys = system(1.0);
    let scheme = QuantizedInnovationScheme::new(
        sys.clone(),
        &QuantizerChoice::You { bits: 1 },
        Activation::All,
    )
    .unwrap();
    let mut inst = scheme.build().unwrap();
    let before = (sys.transition.f() * &sys.prior.cov * sys.transition.f().transpose()
        + sys.transition.q())
    .trace();
    inst.center
        .step(1, &[Received::Silent, Received::Silent, Received::Silent])
        .unwrap();
    assert!(inst.center.estimate().cov.trace() < before * 0.9);
}
