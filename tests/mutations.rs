//! Random mutations of valid scenario files (drop a key, change a type, a length, a sign, a
//! huge or non-finite number) never panic, and a run that is accepted never ends as a success
//! with a non-finite number in its summary. Everything runs in-process, so a panic anywhere in
//! loading, building or running is caught and reported with the mutated file.
use hushfuse::engine::runner;
use hushfuse::metrics::results;
use hushfuse::scenario::build;
use proptest::prelude::*;
use std::panic::{catch_unwind, AssertUnwindSafe};

const LINEAR: &str = r#"
name = "m-linear"
trials = 2
steps = 12
seed = 3
[model]
kind = "constant-velocity-1d"
dt = 1.0
sigma2 = 0.1
[prior]
mean = [0.0, 1.0]
cov_diag = [1.0, 1.0]
[groups]
position = [0]
[[sensors]]
observe = [0]
R_diag = [1.0]
[[sensors]]
H = [[1.0, 0.0]]
R = [[2.0]]
[[schemes]]
kind = "centralized-kf-random"
sweep.rate = [0.5, 1.0]
[[schemes]]
kind = "dkf-alg2-event"
alpha = 0.5
b = 4.0
[[schemes]]
kind = "censored-pf"
l = 1.0
particles = 50
[[schemes]]
kind = "federated-tobit"
tau = 3.0
[paper]
citation = "x"
[[paper.claims]]
kind = "better"
text = "t"
a = "Centralized KF (random)"
a_params = { rate = 1.0 }
b = "Censored PF"
metric = "mse:position"
"#;

const PLACED: &str = r#"
name = "m-placed"
trials = 2
steps = 10
seed = 4
[model]
kind = "constant-velocity-2d"
dt = 1.0
sigma2 = 0.01
[prior]
mean = [0.0, 1.0, 0.0, 1.0]
cov_diag = [1.0, 0.1, 1.0, 0.1]
[[sensor_fields]]
kind = "range"
layout = "grid"
area = [-10.0, 10.0, -10.0, 10.0]
grid = [2, 2]
position_indices = [0, 2]
r = 0.5
[[sensors]]
kind = "rss"
position = [1.0, 1.0]
position_indices = [0, 2]
R_diag = [0.1]
p0 = 100.0
path_loss_alpha = 0.2
path_loss_exponent = 2.0
[[schemes]]
kind = "quantized-innovation"
quantizer = "zhang"
bits = 2
activate = 3
[[schemes]]
kind = "send-on-delta"
delta = 1.0
[[schemes]]
kind = "censored-pf"
l = 2.0
particles = 40
feedback = "prediction-covariance"
"#;

/// Every path to a value in a TOML tree, with its parent table or array.
fn paths(v: &toml::Value, prefix: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
    match v {
        toml::Value::Table(t) => {
            for (k, x) in t {
                prefix.push(k.clone());
                out.push(prefix.clone());
                paths(x, prefix, out);
                prefix.pop();
            }
        }
        toml::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                prefix.push(format!("#{i}"));
                out.push(prefix.clone());
                paths(x, prefix, out);
                prefix.pop();
            }
        }
        _ => {}
    }
}

/// The parent container of `path` and the last key.
fn parent<'a>(root: &'a mut toml::Value, path: &[String]) -> Option<&'a mut toml::Value> {
    let mut v = root;
    for key in &path[..path.len() - 1] {
        v = match (v, key.strip_prefix('#')) {
            (toml::Value::Array(a), Some(i)) => a.get_mut(i.parse::<usize>().ok()?)?,
            (toml::Value::Table(t), None) => t.get_mut(key)?,
            _ => return None,
        };
    }
    Some(v)
}

#[derive(Debug, Clone, Copy)]
enum Mutation {
    Drop,
    ToString,
    ToBool,
    Lengthen,
    Shorten,
    Negate,
    Huge,
    HugeInt,
    Nan,
    Infinite,
    Zero,
}

fn mutate(root: &mut toml::Value, path: &[String], m: Mutation) {
    let Some(p) = parent(root, path) else { return };
    let last = path.last().unwrap();
    let slot: Option<&mut toml::Value> = match (&mut *p, last.strip_prefix('#')) {
        (toml::Value::Array(a), Some(i)) => {
            let i: usize = i.parse().unwrap();
            if let Mutation::Drop = m {
                if i < a.len() {
                    a.remove(i);
                }
                return;
            }
            a.get_mut(i)
        }
        (toml::Value::Table(t), None) => {
            if let Mutation::Drop = m {
                t.remove(last);
                return;
            }
            t.get_mut(last)
        }
        _ => None,
    };
    let Some(v) = slot else { return };
    let number = |v: &toml::Value| match v {
        toml::Value::Integer(i) => Some(*i as f64),
        toml::Value::Float(x) => Some(*x),
        _ => None,
    };
    let new = match m {
        Mutation::Drop => return,
        Mutation::ToString => toml::Value::String("x".into()),
        Mutation::ToBool => toml::Value::Boolean(true),
        Mutation::Lengthen => match &*v {
            toml::Value::Array(a) => {
                let mut a = a.clone();
                if let Some(first) = a.first().cloned() {
                    a.push(first);
                }
                toml::Value::Array(a)
            }
            other => toml::Value::Array(vec![other.clone(), other.clone()]),
        },
        Mutation::Shorten => match &*v {
            toml::Value::Array(a) => {
                let mut a = a.clone();
                a.pop();
                toml::Value::Array(a)
            }
            _ => return,
        },
        Mutation::Negate => match &*v {
            toml::Value::Integer(i) => toml::Value::Integer(-*i),
            toml::Value::Float(x) => toml::Value::Float(-*x),
            _ => return,
        },
        Mutation::Huge => match number(v) {
            Some(x) => toml::Value::Float(if x < 0.0 { -1e300 } else { 1e300 }),
            None => return,
        },
        Mutation::HugeInt => toml::Value::Integer(i64::MAX),
        Mutation::Nan => toml::Value::Float(f64::NAN),
        Mutation::Infinite => toml::Value::Float(f64::INFINITY),
        Mutation::Zero => match &*v {
            toml::Value::Integer(_) => toml::Value::Integer(0),
            toml::Value::Float(_) => toml::Value::Float(0.0),
            _ => return,
        },
    };
    *v = new;
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        Just(Mutation::Drop),
        Just(Mutation::ToString),
        Just(Mutation::ToBool),
        Just(Mutation::Lengthen),
        Just(Mutation::Shorten),
        Just(Mutation::Negate),
        Just(Mutation::Huge),
        Just(Mutation::HugeInt),
        Just(Mutation::Nan),
        Just(Mutation::Infinite),
        Just(Mutation::Zero),
    ]
}

/// Loads and (if accepted and small) runs `text`; Err describes a violation.
fn check(text: &str) -> Result<(), String> {
    let outcome = catch_unwind(AssertUnwindSafe(|| -> Result<(), String> {
        let opts = build::LoadOptions {
            threads: 1,
            ..Default::default()
        };
        let Ok(exp) = build::load_with(text, "mutated.toml", &opts) else {
            return Ok(()); // refused with an error: fine
        };
        // Accepted files that are still small are run to the end.
        if exp.trials * exp.steps > 200 {
            return Ok(());
        }
        let Ok(sums) = runner::run(&exp, runner::RunOptions { threads: 1 }, &|_| {}) else {
            return Ok(()); // a run error exits 1 with a message: fine
        };
        let summary = results::summarize(&exp, &sums);
        let bad = hushfuse::metrics::finite::non_finite(&summary);
        // A failed variant's numbers are null in summary.json by design (its row is marked
        // failed and the run exits 1), so the check reads the variants that did not fail.
        let failed = results::failed(&summary);
        let mut finished = summary.clone();
        finished.schemes.retain(|s| s.failed.is_none());
        // No floor at a scheme's rate (none for the scenario, or a rate too low for a finite
        // one) is a null by design, not a non-finite number.
        for s in &mut finished.schemes {
            s.floor_mse.get_or_insert(0.0);
        }
        // The CLI turns these into exit code 1; here the function must find them.
        let json = serde_json::to_string(&finished).unwrap();
        if bad.is_empty() && json.contains("null") {
            return Err("a non-finite number that non_finite() missed".into());
        }
        if failed.is_empty() && summary.schemes.iter().any(|s| s.failed.is_some()) {
            return Err("a failed variant that failed() missed".into());
        }
        Ok(())
    }));
    match outcome {
        Ok(r) => r,
        Err(p) => Err(format!(
            "panicked: {}",
            p.downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default()
        )),
    }
}

proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig {
        cases: 300,
        // A fixed seed: the same cases on every run and machine (CI included).
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed0000),
        ..proptest::prelude::ProptestConfig::default()
    })]
    #[test]
    fn mutated_scenarios_never_panic_nor_pass_non_finite(
        base in 0usize..2,
        picks in proptest::collection::vec((any::<prop::sample::Index>(), mutation()), 1..3),
    ) {
        let text = [LINEAR, PLACED][base];
        let mut root: toml::Value = toml::from_str(text).unwrap();
        for (index, m) in picks {
            let mut all = Vec::new();
            paths(&root, &mut Vec::new(), &mut all);
            if all.is_empty() {
                break;
            }
            let path = all[index.index(all.len())].clone();
            mutate(&mut root, &path, m);
        }
        let Ok(mutated) = toml::to_string(&root) else {
            return Ok(()); // not representable as TOML (e.g. an array of mixed tables)
        };
        prop_assert!(check(&mutated).is_ok(), "{}\n--- file ---\n{mutated}", check(&mutated).unwrap_err());
    }
}

/// The unmutated bases are valid and run.
#[test]
fn the_bases_are_valid() {
    for text in [LINEAR, PLACED] {
        let exp = build::load(text, "base.toml").unwrap();
        let sums = runner::run(&exp, runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
        assert!(hushfuse::metrics::finite::non_finite(&results::summarize(&exp, &sums)).is_empty());
    }
}
