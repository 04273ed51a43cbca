//! A link that changes nothing changes no number of any built-in, and the all-data Kalman
//! filter under Bernoulli losses has, on average, the error the data-free variance recursion
//! predicts (Sinopoli et al. 2004): the expectation over arrival sequences drawn independently
//! of the engine, within the Monte Carlo standard errors of both.
use hushfuse::engine::runner;
use hushfuse::metrics::results;
use hushfuse::network::channel::stability;
use hushfuse::scenario::{build, builtin};
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

fn summary_of(text: &str, source: &str, trials: usize) -> results::Summary {
    let opts = build::LoadOptions {
        trials: Some(trials),
        ..Default::default()
    };
    let exp = build::load_with(text, source, &opts).unwrap_or_else(|e| panic!("{source}: {e}"));
    let sums = runner::run(&exp, runner::RunOptions { threads: 2 }, &|_| {})
        .unwrap_or_else(|e| panic!("{source}: {e}"));
    results::summarize(&exp, &sums)
}

/// `text` with its `[channel]` (and every sensor's own) replaced by `channel`.
fn with_channel(text: &str, channel: toml::Table) -> String {
    let mut t: toml::Table = toml::from_str(text).unwrap();
    if let Some(toml::Value::Array(sensors)) = t.get_mut("sensors") {
        for s in sensors.iter_mut().filter_map(toml::Value::as_table_mut) {
            s.remove("channel");
        }
    }
    t.insert("channel".into(), toml::Value::Table(channel));
    toml::to_string(&t).unwrap()
}

/// Whether a `[[schemes]]` entry of `text` has a link of its own.
fn entries_with_own_link(text: &str) -> bool {
    let t: toml::Table = toml::from_str(text).unwrap();
    t.get("schemes")
        .and_then(toml::Value::as_array)
        .is_some_and(|a| {
            a.iter().any(|e| {
                e.get("channel").is_some()
                    || e.get("sweep")
                        .and_then(toml::Value::as_table)
                        .is_some_and(|sw| sw.keys().any(|k| k.starts_with("channel.")))
            })
        })
}

/// The schemes' results as JSON without the link section (which only a run with a link has).
fn without_link(s: &results::Summary) -> serde_json::Value {
    let mut v = serde_json::to_value(&s.schemes).unwrap();
    for scheme in v.as_array_mut().unwrap() {
        scheme.as_object_mut().unwrap().remove("link");
    }
    v
}

#[test]
fn an_ideal_link_and_a_lossless_one_reproduce_every_built_in() {
    for (name, _, text) in builtin::BUILTIN {
        if build::file_kind(text, name).unwrap() != build::FileKind::Scenario
            || entries_with_own_link(text)
            || text.contains("\n[network]")
        {
            // Table reports run no trials; the stability reproductions are about their own
            // (per-entry) links, which a scenario-level channel does not replace; a multi-hop
            // network's channel is on every hop (its own links are tests/network_graph.rs's).
            continue;
        }
        // Two trials: every scheme, every step, the generic loop against the fast paths.
        let plain = summary_of(text, name, 2);
        let ideal: toml::Table = toml::from_str("kind = \"ideal\"").unwrap();
        let ideal = summary_of(&with_channel(text, ideal), name, 2);
        assert_eq!(
            serde_json::to_value(&ideal.schemes).unwrap(),
            serde_json::to_value(&plain.schemes).unwrap(),
            "{name}: kind = \"ideal\" moved a number"
        );
        let lossless: toml::Table = toml::from_str("kind = \"bernoulli\"\nloss = 0.0").unwrap();
        let lossless = summary_of(&with_channel(text, lossless), name, 2);
        assert_eq!(
            without_link(&lossless),
            without_link(&plain),
            "{name}: loss = 0 moved a number"
        );
        for s in &lossless.schemes {
            let link = s.link.as_ref().expect("a lossless link still counts");
            assert_eq!(link.lost, 0.0, "{name}");
        }
    }
}

/// Mean and standard error of the steady-state posterior variance of the scalar Kalman filter
/// (a = 1.2, q = r = 1, prior variance 1) when each measurement arrives with probability
/// `gamma`, over `sequences` arrival sequences drawn from a generator of this test's own, and
/// over steps `from..=steps`: the average of each sequence's time average.
fn recursion_expectation(gamma: f64, steps: usize, from: usize, sequences: usize) -> (f64, f64) {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(0x5150_2004);
    let (mut sum, mut sum2) = (0.0, 0.0);
    for _ in 0..sequences {
        let arrivals: Vec<bool> = (0..steps).map(|_| rng.random::<f64>() < gamma).collect();
        // The prior of step 1 is a² P0 + q.
        let priors = stability::prior_variance_path(1.2, 1.0, 1.0, 1.44 + 1.0, &arrivals);
        let mut avg = 0.0;
        for k in from..=steps {
            let p = priors[k - 1];
            avg += if arrivals[k - 1] {
                p - p * p / (p + 1.0)
            } else {
                p
            };
        }
        avg /= (steps - from + 1) as f64;
        sum += avg;
        sum2 += avg * avg;
    }
    let n = sequences as f64;
    let mean = sum / n;
    let var = (sum2 - n * mean * mean) / (n - 1.0);
    (mean, (var / n).sqrt())
}

#[test]
fn the_kalman_filter_at_loss_0_2_has_the_recursions_expected_error() {
    let (trials, steps, from) = (400, 60, 21);
    let text = format!(
        r#"
name = "scalar"
trials = {trials}
steps = {steps}
seed = 2004
steady_state_from = {from}
[model]
kind = "matrix"
F = [[1.2]]
Q = [[1.0]]
[prior]
mean = [0.0]
cov_diag = [1.0]
[[sensors]]
H = [[1.0]]
R = [[1.0]]
[channel]
kind = "bernoulli"
loss = 0.2
[[schemes]]
kind = "centralized-kf"
"#
    );
    let s = summary_of(&text, "scalar.toml", trials);
    let ss = &s.schemes[0].steady_state;
    let (want, want_se) = recursion_expectation(0.8, steps, from, 20_000);
    // The filter's own variance (trace) and its real squared error (mse) both estimate the
    // recursion's expectation: the trace because it is the recursion on the run's arrivals,
    // the mse because the filter is consistent given the arrivals. Each against the
    // independent expectation within 3 combined standard errors.
    for (what, got, se) in [("trace", ss.trace, ss.trace_se), ("mse", ss.mse, ss.mse_se)] {
        let z = (got - want) / (se * se + want_se * want_se).sqrt();
        assert!(
            z.abs() < 3.0,
            "{what}: run {got} ± {se}, recursion {want} ± {want_se}, z = {z:.2}"
        );
    }
    // And the test can tell: the ideal link's error is far below (at least 10 SE).
    let (ideal, _) = recursion_expectation(1.0, steps, from, 10);
    assert!(want - ideal > 10.0 * want_se, "{want} vs ideal {ideal}");
    // The bounds of Sinopoli et al. hold for the prior variance; the posterior of a step is
    // smaller, so its expectation lies below the upper bound of the prior.
    let upper = stability::upper_bound(1.2, 1.0, 1.0, 0.8).expect("0.8 is above critical");
    assert!(
        ss.trace < upper,
        "{} vs the prior's upper bound {upper}",
        ss.trace
    );
}
