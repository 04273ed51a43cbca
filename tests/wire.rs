//! What crosses the network is what the bits priced carry: a measurement or an estimate
//! arrives as IEEE 754 singles (`link::as_sent`), feedback reaches the sensors as singles,
//! frames as their octets; a value beyond the single range arrives non-finite and the centers
//! reject it.
use hushfuse::linalg::{Matrix, Vector};
use hushfuse::link::{as_sent, Message, Received, Transmission};
use hushfuse::scenario::{build, builtin};
use hushfuse::scheme::{Feedback, InnovationReference};

fn arrives(m: Message) -> Received {
    Received::from(Transmission::Send(m))
}

#[test]
fn measurements_and_estimates_arrive_as_singles() {
    let z = Vector::from_vec(vec![0.1, 1.5, -2.0 / 3.0, 1e-50, f64::NAN]);
    let want = [0.1f32 as f64, 1.5, (-2.0f32 / 3.0) as f64, 0.0];
    for got in [
        arrives(Message::Measurement(z.clone())),
        arrives(Message::Estimate(z.clone())),
    ] {
        let (Received::Measurement(v) | Received::Estimate(v)) = got else {
            panic!("{got:?}")
        };
        assert_eq!(&v.as_slice()[..4], &want);
        assert_ne!(v[0], 0.1, "an f64 was delivered");
        assert!(v[4].is_nan());
        // Rounding twice is rounding once: a single is exact as an f64.
        assert!(v.iter().take(4).all(|&x| as_sent(x) == x));
    }
    let octets = vec![1, 2, 3];
    let frame = Message::Frame {
        octets: octets.clone(),
        payload_bits: 20,
    };
    assert_eq!(arrives(frame), Received::Frame(octets));
    assert_eq!(
        Received::from(Transmission::Silent),
        Received::Silent,
        "silence is not a message"
    );
}

#[test]
fn a_finite_value_beyond_the_single_range_arrives_infinite() {
    let big = Vector::from_vec(vec![1e39, -1e39, f64::MAX, f32::MAX as f64]);
    let Received::Measurement(v) = arrives(Message::Measurement(big)) else {
        unreachable!()
    };
    assert_eq!(
        v.as_slice(),
        &[
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f32::MAX as f64
        ]
    );
}

/// Every sensor of the first variant of `scenario` whose kind starts with `kind` sends `x` (per
/// component) at step 1: the center's answer.
fn center_takes(scenario: &str, text: &str, kind: &str, x: f64) -> Result<(), String> {
    let exp = build::load(text, scenario).unwrap();
    let v = exp
        .variants
        .iter()
        .find(|v| v.kind.to_string().starts_with(kind));
    let mut inst = v.unwrap().scheme.build().unwrap();
    let estimate = kind == "dkf";
    let inbox: Vec<Received> = exp
        .system
        .sensors
        .iter()
        .map(|s| {
            let dim = if estimate {
                exp.system.state_dim()
            } else {
                s.meas_dim()
            };
            let v = Vector::from_element(dim, x);
            arrives(if estimate {
                Message::Estimate(v)
            } else {
                Message::Measurement(v)
            })
        })
        .collect();
    inst.center.step(1, &inbox).map_err(|e| e.to_string())
}

#[test]
fn the_centers_reject_a_value_that_overflowed_the_single() {
    let kfmc = include_str!("../benches/data/kfmc.toml");
    assert!(center_takes("kfmc", kfmc, "centralized-kf", 1.0).is_ok());
    let err = center_takes("kfmc", kfmc, "centralized-kf", 1e39).unwrap_err();
    assert!(err.contains("finite"), "{err}");
    let dormann = builtin::get("dormann-fig1").unwrap();
    assert!(center_takes("dormann-fig1", dormann, "dkf", 1.0).is_ok());
    let err = center_takes("dormann-fig1", dormann, "dkf", -1e39).unwrap_err();
    assert!(err.contains("corrupt estimate"), "{err}");
}

#[test]
fn feedback_reaches_the_sensors_as_singles() {
    let mean = Vector::from_vec(vec![0.1, 2.0]);
    let cov = Matrix::from_row_slice(2, 2, &[1.0 / 3.0, 0.1, 0.1, 1.0 / 3.0]);
    let f = Feedback::Prediction {
        mean,
        cov: Some(cov),
    };
    let Feedback::Prediction { mean, cov: Some(c) } = f.as_sent() else {
        unreachable!()
    };
    assert_eq!(mean.as_slice(), &[0.1f32 as f64, 2.0]);
    let third = (1.0f32 / 3.0) as f64;
    assert_eq!(c.as_slice(), &[third, 0.1f32 as f64, 0.1f32 as f64, third]);
    let refs = Feedback::InnovationReference(vec![
        None,
        Some(InnovationReference {
            y_hat: 0.1,
            delta: 1e39,
        }),
    ]);
    let Feedback::InnovationReference(r) = refs.as_sent() else {
        unreachable!()
    };
    assert_eq!(r[0], None);
    let r1 = r[1].unwrap();
    assert_eq!((r1.y_hat, r1.delta), (0.1f32 as f64, f64::INFINITY));
    // The bits priced are the bits sent: rounding changes no count.
    assert_eq!(refs.as_sent().bits(2), refs.bits(2));
}

/// A scalar random walk, one sensor, the all-data KF; `extra` appended to the file.
fn doubles_scenario(reals: &str, extra: &str) -> build::Experiment {
    let text = format!(
        r#"
name = "reals"
trials = 3
steps = 30
seed = 5
{reals}
[model]
kind = "matrix"
F = [[1.2]]
Q = [[1.0]]
[prior]
mean = [0.0]
cov_diag = [1.0]
[[sensors]]
observe = [0]
R_diag = [1.0]
[[schemes]]
kind = "centralized-kf"
{extra}
"#
    );
    build::load_with(&text, "reals.toml", &Default::default()).unwrap()
}

/// `reals = "f64"`: the center fuses the readings as they were (the estimate of a KF on the
/// exact readings, which differs from the singles' one), and every real costs 64 bits, its
/// frame 4 octets more.
#[test]
fn with_doubles_the_readings_arrive_exact_and_cost_64_bits() {
    use hushfuse::engine::trace::{run_variant_with, LoopOptions};
    let run = |exp: &build::Experiment| {
        let data = hushfuse::engine::runner::draw_trial(exp, 0);
        let mut out = Vec::new();
        let opts = LoopOptions {
            trial: 0,
            alone: false,
            available: None,
        };
        run_variant_with(exp, &data.measurements, 0, opts, &mut |s| {
            out.push((
                s.estimate.mean[0],
                s.traffic.bits,
                s.traffic.frame_bits,
                s.bits.to_vec(),
            ));
            Ok(())
        })
        .unwrap();
        (out, data)
    };
    let (doubles, data) = run(&doubles_scenario("reals = \"f64\"", ""));
    let (singles, _) = run(&doubles_scenario("", ""));
    for (k, (d, s)) in doubles.iter().zip(&singles).enumerate() {
        assert_eq!((d.1, d.2), (64, 88 + 64), "step {}", k + 1);
        assert_eq!((s.1, s.2), (32, 88 + 32));
        assert_eq!(d.3, vec![64]);
    }
    // The first update from the prior N(0, 1) with r = 1 fuses z_1 exactly: x = P z / (P + r).
    let z1 = data.measurements[0][0][0];
    let p = 1.2 * 1.2 * 1.0 + 1.0;
    assert_eq!(doubles[0].0, p * z1 / (p + 1.0));
    assert_ne!(doubles[0].0, singles[0].0, "singles round z_1");
    assert_eq!(singles[0].0, p * as_sent(z1) / (p + 1.0));
}

#[test]
fn doubles_are_refused_where_the_loop_cannot_carry_them() {
    let text = |extra: &str| {
        format!(
            "name = \"r\"\ntrials = 1\nsteps = 3\nseed = 1\nreals = \"f64\"\n[model]\nkind = \"matrix\"\nF = [[1.0]]\nQ = [[1.0]]\n[prior]\nmean = [0.0]\ncov_diag = [1.0]\n[[sensors]]\nobserve = [0]\nR_diag = [1.0]\n[[schemes]]\nkind = \"centralized-kf\"\n{extra}\n"
        )
    };
    let e = build::load_with(&text("sequence_bits = 4"), "r.toml", &Default::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("reals") && e.contains("sequence numbers"), "{e}");
    let e = build::load_with(
        &text("reals2 = 1").replace("reals = \"f64\"", "reals = \"f16\""),
        "r.toml",
        &Default::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("f16") || e.contains("reals"), "{e}");
}
