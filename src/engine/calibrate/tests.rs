//! Unit tests of the calibrator.
use super::*;

#[test]
fn short_drops_trailing_zeros_and_writes_huge_values_with_an_exponent() {
    assert_eq!(short(24.0), "24");
    assert_eq!(short(12.5), "12.5");
    assert_eq!(short(0.123456), "0.1235");
    assert_eq!(short(999_999_999.0), "999999999");
    assert_eq!(short(1e9), "1e9");
    assert_eq!(short(1e300), "1e300");
    assert_eq!(short(1.23456789e12), "1.2346e12");
    assert_eq!(bits_cell(384.0), "384.0");
    assert_eq!(bits_cell(1e300), "1e300");
}

#[test]
fn directory_labels_read_back_as_their_budget() {
    for v in [
        24.0,
        12.5,
        24.00001,
        24.00004,
        1e9,
        5e9,
        1.23456789e12,
        1e300,
        2e-300,
    ] {
        let label = dir_label(v);
        assert_eq!(label.parse::<f64>(), Ok(v), "{v}: {label}");
    }
}

const ARENAS: [&str; 5] = [
    "arena-1d",
    "arena-nca",
    "arena-rss",
    "arena-wsn",
    "arena-tobit",
];

fn small(threads: usize) -> Options {
    Options {
        threads,
        load: LoadOptions {
            trials: Some(4),
            ..LoadOptions::default()
        },
        ..Options::default()
    }
}

/// Everything an outcome says, as JSON (the summaries carry every scheme's full result).
fn fingerprint(out: &Outcome) -> String {
    serde_json::to_string(&(
        &out.budgets,
        &out.rows,
        &out.summaries,
        &out.texts,
        out.evaluations,
        out.axis,
        out.tolerance,
    ))
    .expect("an outcome serializes")
}

/// Calibration with pilot runs built from the parsed scenario equals calibration with pilot
/// runs built from the scenario text (the path before typed knobs), bit for bit, on every
/// arena scenario: knobs, achieved bits, statuses, summaries, texts and the number of runs.
#[test]
fn typed_pilot_runs_equal_text_pilot_runs_on_every_arena_scenario() {
    let budgets = [12.0, 48.0];
    let opts = small(1);
    for id in ARENAS {
        let text = crate::scenario::builtin::get(id).expect("a built-in");
        let typed = calibrate(text, id, &budgets, &opts).expect("calibrates");
        let (mut ev, setup) = prepare(text, id, &budgets, &opts).expect("prepares");
        ev.via_text = true;
        let old = calibrate_all(&mut ev, &setup).expect("calibrates through text");
        assert!(typed.evaluations > 0, "{id}");
        assert_eq!(fingerprint(&typed), fingerprint(&old), "{id}");
    }
}

/// The way the bits move as each knob grows, declared in the registry, is the way the
/// calibrator measures it off the ends of the range (integer knobs: the first two values that
/// build) on every arena scenario.
#[test]
fn declared_knob_directions_agree_with_the_measured_ones() {
    use crate::scheme::registry::Direction;
    let budgets = [12.0, 48.0];
    let opts = small(1);
    let mut checked = 0;
    for id in ARENAS {
        let text = crate::scenario::builtin::get(id).expect("a built-in");
        let (mut ev, s) = prepare(text, id, &budgets, &opts).expect("prepares");
        for (ci, entry) in s.list.iter().enumerate() {
            let kind = s.full.curves[ci].kind.clone();
            let Some(k) = registry::find(&kind).and_then(|e| e.knob) else {
                continue;
            };
            let range = knob_range(&kind, s.n_sensors).expect("a declared range");
            let mut p = Pilot {
                ci,
                entry,
                knob: k.name,
                range,
                trials: s.pilot,
            };
            let (a, b) = if range.integer {
                let lo = p.eval(&mut ev, range.lo).expect("the lower end builds");
                let next = p
                    .eval(&mut ev, range.lo + 1.0)
                    .expect("the next integer builds");
                (s.axis.of(&lo), s.axis.of(&next))
            } else {
                let ((_, lo), (_, hi)) = ends(&mut ev, &s, &mut p, &kind).expect("the ends build");
                (s.axis.of(&lo), s.axis.of(&hi))
            };
            assert_ne!(a, b, "{id}: {kind}: the knob does not move the bits");
            let measured = if b > a {
                Direction::MoreBits
            } else {
                Direction::FewerBits
            };
            assert_eq!(measured, k.grows, "{id}: {kind}: {a} -> {b} bits per step");
            checked += 1;
        }
    }
    assert!(checked >= 40, "only {checked} knobs checked");
}

#[test]
fn a_log_scale_knob_bisects_at_the_geometric_midpoint() {
    assert_eq!(midpoint(1.0, 100.0, true), 10.0);
    assert_eq!(midpoint(1.0, 100.0, false), 50.5);
    // An end at 0 has no geometric midpoint: the arithmetic one.
    assert_eq!(midpoint(0.0, 4.0, true), 2.0);
    // Every built-in knob is linear (a change of scale would move calibrated numbers).
    for e in crate::scheme::SCHEMES {
        if let Some(k) = e.knob {
            assert_eq!(k.scale, registry::Scale::Linear, "{}", e.kind);
            assert!(!knob_range(e.kind, 4).unwrap().log);
        }
    }
}

/// Calibrating several axes from one set of pilot runs (the quick arena) gives, per axis, the
/// outcome of calibrating that axis alone — knobs, spends, statuses, summaries, texts — with
/// fewer pilot runs in all (a pilot run gives every axis's spend).
#[test]
fn axes_calibrated_together_equal_each_alone_with_fewer_pilot_runs() {
    let opts = small(1);
    let plans: [(Axis, &[f64]); 3] = [
        (Axis::Payload, &[12.0, 48.0]),
        (Axis::Frame, &[96.0, 192.0]),
        (Axis::Energy, &[300.0, 390.0]),
    ];
    let text = crate::scenario::builtin::get("arena-1d").expect("a built-in");
    let together = calibrate_axes(text, "arena-1d", &plans, &opts).expect("calibrates");
    assert_eq!(together.len(), plans.len());
    let (mut alone_runs, mut together_runs) = (0, 0);
    for ((axis, budgets), shared) in plans.iter().zip(&together) {
        let alone = calibrate(
            text,
            "arena-1d",
            budgets,
            &Options {
                axis: *axis,
                ..opts
            },
        )
        .expect("calibrates");
        let without_runs = |o: &Outcome| {
            let mut o = o.clone();
            o.evaluations = 0;
            fingerprint(&o)
        };
        assert_eq!(without_runs(shared), without_runs(&alone), "{axis:?}");
        alone_runs += alone.evaluations;
        together_runs += shared.evaluations;
    }
    assert!(
        together_runs * 3 < alone_runs * 2,
        "{together_runs} pilot runs together, {alone_runs} alone"
    );
    assert!(calibrate_axes(text, "arena-1d", &[(Axis::Payload, &[-1.0])], &opts).is_err());
}
