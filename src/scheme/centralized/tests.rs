use super::*;
use crate::linalg::{matrix_from_rows, relative_difference, Matrix};
use crate::model::{presets, LinearSensor, MeasurementModel};

use crate::model::Opaque;

/// The EKF on a linear model equals the KF (information-form fusion).
#[test]
fn ekf_on_a_linear_model_equals_the_kf() {
    let transition = presets::constant_velocity_2d(0.5, 1.0).unwrap();
    let a = LinearSensor::new(
        matrix_from_rows(&[vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]]),
        Matrix::identity(2, 2) * 2.0,
    )
    .unwrap();
    let b = LinearSensor::new(
        matrix_from_rows(&[vec![0.3, 1.0, 0.0, 0.2]]),
        Matrix::from_element(1, 1, 0.5),
    )
    .unwrap();
    let prior = Gaussian::new(
        Vector::from_vec(vec![1.0, 0.0, -1.0, 0.5]),
        Matrix::identity(4, 4) * 3.0,
    );
    let linear = Arc::new(System {
        transition: transition.clone(),
        sensors: vec![Arc::new(a.clone()), Arc::new(b.clone())],
        prior: prior.clone(),
    });
    let opaque = Arc::new(System {
        transition,
        sensors: vec![Arc::new(Opaque(a)), Arc::new(Opaque(b))],
        prior,
    });
    let mut kf = CentralizedKf::new(linear);
    let mut ekf = CentralizedKf::new(opaque);
    for k in 1..=30 {
        let t = k as f64;
        let inbox = vec![
            Received::Measurement(Vector::from_vec(vec![t.sin(), 0.5 * t])),
            if k % 3 == 0 {
                Received::Silent
            } else {
                Received::Measurement(Vector::from_element(1, 0.1 * t))
            },
        ];
        kf.step(k, &inbox).unwrap();
        ekf.step(k, &inbox).unwrap();
        assert!(relative_difference(&kf.estimate().cov, &ekf.estimate().cov) < 1e-10);
        assert!((&kf.estimate().mean - &ekf.estimate().mean).amax() < 1e-9);
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig {
        cases: 48,
        // A fixed seed: the same cases on every run and machine (CI included).
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed0003),
        ..proptest::prelude::ProptestConfig::default()
    })]
    /// The all-data schedule and the buffered direct step give the textbook
    /// information-form step's numbers bit for bit,
    /// on random systems of dimension 1 to 6 with 1 to 4 sensors, for two trials sharing
    /// the schedule; a missing measurement at step `drop_at` takes the center off the
    /// schedule for good, onto the direct form from the same estimate.
    #[test]
    fn schedule_is_bit_identical_to_direct(
        n in 1usize..=6,
        n_sensors in 1usize..=4,
        v in proptest::collection::vec(-1.0f64..1.0, 64),
        drop_at in 0usize..30,
    ) {
        use crate::model::LinearTransition;
        let mut it = v.iter().copied().cycle();
        let mut next = || it.next().unwrap();
        let f = Matrix::from_fn(n, n, |i, j| f64::from(u8::from(i == j)) + 0.3 * next());
        let g = Matrix::from_fn(n, n, |_, _| 0.5 * next());
        let q = &g * g.transpose() + Matrix::identity(n, n) * 0.1;
        let q = (&q + q.transpose()) * 0.5;
        let sensors = (0..n_sensors)
            .map(|i| {
                let m = 1 + i % 2;
                let h = Matrix::from_fn(m, n, |_, _| next());
                let r = Matrix::from_diagonal(&Vector::from_fn(m, |_, _| 0.5 + next().abs()));
                Arc::new(LinearSensor::new(h, r).unwrap()) as Arc<dyn MeasurementModel>
            })
            .collect();
        let prior = Gaussian::new(
            Vector::from_fn(n, |_, _| next()),
            Matrix::from_diagonal(&Vector::from_fn(n, |_, _| 1.0 + next().abs())),
        );
        let sys = Arc::new(System {
            transition: LinearTransition::new(f, q).unwrap(),
            sensors,
            prior,
        });
        let scheme = CentralizedScheme::new(sys.clone(), 1.0).unwrap();
        for trial in 0..2 {
            let mut fast = scheme.build().unwrap().center;
            let mut direct = CentralizedKf::new(sys.clone());
            // The textbook form, allocating (the code before the buffers): the oracle.
            let mut oracle = sys.prior.clone();
            for k in 1..=20usize {
                let inbox: Vec<Received> = sys
                    .sensors
                    .iter()
                    .enumerate()
                    .map(|(i, s)| {
                        if trial == 1 && k == drop_at && i == 0 {
                            Received::Silent
                        } else {
                            let t = (k * (i + 1) + trial) as f64;
                            Received::Measurement(Vector::from_fn(s.meas_dim(), |r, _| {
                                (t + r as f64).sin() * 3.0
                            }))
                        }
                    })
                    .collect();
                let a = fast.step(k, &inbox);
                let b = direct.step(k, &inbox);
                proptest::prop_assert_eq!(&a, &b);
                let c = (|| -> Result<Gaussian, SchemeError> {
                    use crate::filter::information::Information;
                    let pred = kf::predict(&sys.transition, &oracle);
                    let mut info = Information::from_gaussian(&pred)?;
                    for (i, msg) in inbox.iter().enumerate() {
                        if let Received::Measurement(z) = msg {
                            info.add_measurement(sys.sensors[i].as_linear().unwrap(), z)?;
                        }
                    }
                    Ok(info.to_gaussian()?)
                })();
                proptest::prop_assert_eq!(a.is_ok(), c.is_ok());
                let Ok(c) = c else { break };
                oracle = c;
                let (ea, eb) = (fast.estimate(), direct.estimate());
                let bits = |m: &Matrix| m.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                let vbits = |m: &Vector| m.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                proptest::prop_assert_eq!(vbits(&ea.mean), vbits(&eb.mean), "mean, step {}", k);
                proptest::prop_assert_eq!(bits(&ea.cov), bits(&eb.cov), "cov, step {}", k);
                proptest::prop_assert_eq!(vbits(&ea.mean), vbits(&oracle.mean), "oracle mean, step {}", k);
                proptest::prop_assert_eq!(bits(&ea.cov), bits(&oracle.cov), "oracle cov, step {}", k);
            }
        }
    }
}
