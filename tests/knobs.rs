//! The registry's typed knobs and applicability against the built-in arena scenarios: each
//! kind's `applies` says exactly where its example builds, and every knob builds at both ends
//! of its declared range.
use hushfuse::scenario::build;
use hushfuse::scenario::builtin;
use hushfuse::scheme::registry::{self, Bound, BuildContext, SchemeEntry, SCHEMES};
use hushfuse::scheme::System;
use std::sync::Arc;

const ARENAS: [&str; 5] = [
    "arena-1d",
    "arena-nca",
    "arena-rss",
    "arena-wsn",
    "arena-tobit",
];

/// Builds a scheme from `table` and makes one instance of it.
fn builds(
    e: &SchemeEntry,
    table: toml::Table,
    system: &Arc<System>,
    steps: usize,
) -> Result<(), String> {
    let cx = BuildContext {
        system,
        steps,
        link_loss: None,
    };
    let scheme = (e.build)(table, &cx).map_err(|err| err.to_string())?;
    scheme
        .build_with_seed(1)
        .map(|_| ())
        .map_err(|err| err.to_string())
}

/// On every arena scenario's system, `applies` holds exactly where the kind's example builds.
#[test]
fn applies_agrees_with_where_each_example_builds() {
    for id in ARENAS {
        let exp = build::load(builtin::get(id).unwrap(), id).unwrap();
        for e in SCHEMES {
            let table: toml::Table = toml::from_str(e.example).unwrap();
            let result = builds(e, table, &exp.system, exp.steps);
            assert_eq!(
                result.is_ok(),
                e.applies.holds(&exp.system),
                "{id}: {} declares {:?}, its example: {result:?}",
                e.kind,
                e.applies
            );
        }
    }
}

/// Every arena entry of a kind with a knob builds at both ends of the knob's range (an open
/// upper end at 4^12), and every kind with a knob is walked on some arena scenario.
#[test]
fn every_knob_builds_at_both_ends_of_its_range() {
    let mut walked = std::collections::BTreeSet::new();
    for id in ARENAS {
        let text = builtin::get(id).unwrap();
        let exp = build::load(text, id).unwrap();
        let mut spec = build::parse(text, id).unwrap();
        // The arenas ask the registry for their schemes (`every_scheme`): the list as run.
        build::expand_every_scheme(&mut spec, id).unwrap();
        let n = exp.system.n_sensors();
        for raw in &spec.schemes {
            let kind = raw["kind"].as_str().unwrap();
            let e = registry::find(kind).unwrap();
            let Some(k) = e.knob else { continue };
            let mut table = raw.clone();
            for key in ["kind", "label", "note", "sweep", "frontier"] {
                table.remove(key);
            }
            let lo = k.lo.at(n).expect("a closed lower end");
            let hi = k.hi.at(n).unwrap_or(4f64.powi(12));
            assert!(lo < hi, "{id}: {kind}: empty range");
            if k.hi == Bound::Open {
                assert_eq!(k.lo, Bound::Fixed(0.0), "{kind}: a threshold starts at 0");
            }
            for x in [lo, hi] {
                let mut t = table.clone();
                t.insert(
                    k.name.into(),
                    if k.integer {
                        toml::Value::Integer(x.round() as i64)
                    } else {
                        toml::Value::Float(x)
                    },
                );
                if let Err(err) = builds(e, t, &exp.system, exp.steps) {
                    panic!("{id}: {kind} with {} = {x} does not build: {err}", k.name);
                }
            }
            walked.insert(kind.to_string());
        }
    }
    for e in SCHEMES.iter().filter(|e| e.knob.is_some()) {
        assert!(walked.contains(e.kind), "{}: on no arena scenario", e.kind);
    }
}
