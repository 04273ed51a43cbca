//! A variant whose trial fails becomes a row marked failed (its first failure by trial: trial,
//! step, message), while the other variants finish; the same failure for any thread count and
//! any order of merging blocks; its numbers null in summary.json.
use hushfuse::engine::runner;
use hushfuse::filter::Gaussian;
use hushfuse::link::Received;
use hushfuse::metrics::{results, Sums};
use hushfuse::output::durable;
use hushfuse::scenario::build;
use hushfuse::scheme::{FusionCenter, Scheme, SchemeError, SchemeInstance};

const TEXT: &str = r#"
name = "failing"
trials = 24
steps = 30
seed = 31
[model]
kind = "matrix"
F = [[0.9]]
Q = [[1.0]]
[prior]
mean = [0.0]
cov_diag = [1.0]
[[sensors]]
H = [[1.0]]
R = [[1.0]]
[[schemes]]
kind = "centralized-kf"
[[schemes]]
kind = "centralized-kf"
label = "failing"
"#;

/// A scheme whose center fails at step 7 in the trials whose center seed is divisible by 3
/// (which trials those are depends on the seeding only: deterministic).
#[derive(Debug)]
struct Failing(Box<dyn Scheme>);

struct FailingCenter {
    inner: Box<dyn FusionCenter>,
    fails: bool,
}

impl FusionCenter for FailingCenter {
    fn step(&mut self, k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        if self.fails && k == 7 {
            return Err(SchemeError::Unsupported(
                "the test's center fails here".into(),
            ));
        }
        self.inner.step(k, inbox)
    }
    fn estimate(&self) -> &Gaussian {
        self.inner.estimate()
    }
}

impl Scheme for Failing {
    fn build(&self) -> Result<SchemeInstance, SchemeError> {
        self.build_with_seed(0)
    }
    fn build_with_seed(&self, seed: u64) -> Result<SchemeInstance, SchemeError> {
        let inst = self.0.build_with_seed(seed)?;
        Ok(SchemeInstance {
            sensors: inst.sensors,
            center: Box::new(FailingCenter {
                inner: inst.center,
                fails: seed.is_multiple_of(3),
            }),
        })
    }
}

fn experiment() -> build::Experiment {
    let mut exp = build::load(TEXT, "failing.toml").unwrap();
    let inner = build::load(TEXT, "failing.toml")
        .unwrap()
        .variants
        .remove(1)
        .scheme;
    exp.variants[1].scheme = Box::new(Failing(inner));
    exp
}

#[test]
fn a_failed_variant_is_a_failed_row_and_the_others_finish() {
    let exp = experiment();
    let one = runner::run(&exp, runner::RunOptions { threads: 1 }, &|_| {}).unwrap();
    let three = runner::run(&exp, runner::RunOptions { threads: 3 }, &|_| {}).unwrap();
    assert_eq!(one, three, "the sums depend on the thread count");
    let failure = one[1].failure.clone().expect("the failing variant failed");
    assert_eq!(failure.step, 7);
    assert!(
        failure.message.contains("the test's center fails here"),
        "{failure:?}"
    );
    assert!(one[0].failure.is_none());
    // The first failing trial, found trial by trial.
    let first = (0..exp.trials)
        .find(|&t| {
            let mut sums = runner::empty_sums(&exp);
            runner::run_trial_on(&exp, t, &runner::draw_trial(&exp, t), &mut sums).unwrap();
            sums[1].failure.is_some()
        })
        .expect("some trial fails");
    assert_eq!(failure.trial, first);
    // The blocks merged in any order report the same failure.
    let blocks: Vec<Vec<Sums>> = (0..runner::n_blocks(exp.trials))
        .map(|b| {
            let mut sums = runner::empty_sums(&exp);
            for t in runner::block_trials(b, exp.trials) {
                runner::run_trial_on(&exp, t, &runner::draw_trial(&exp, t), &mut sums).unwrap();
            }
            sums
        })
        .collect();
    // A checkpoint or shard holding them is accepted (a failed variant's counts are those of
    // its trials up to their failures).
    for (b, sums) in blocks.iter().enumerate() {
        let trials = runner::block_trials(b, exp.trials).len();
        durable::validate_sums(&exp, sums, trials, "block").unwrap();
    }
    let mut backwards = runner::empty_sums(&exp);
    for b in blocks.iter().rev() {
        runner::fold_block(&mut backwards, b);
    }
    assert_eq!(backwards[1].failure, Some(failure.clone()));
    // The other variant is the run without the failing one, number for number.
    let mut alone = experiment();
    alone.variants.truncate(1);
    let alone = runner::run(&alone, runner::RunOptions { threads: 2 }, &|_| {}).unwrap();
    assert_eq!(alone[0], one[0]);

    let summary = results::summarize(&exp, &one);
    let table = results::table(&summary);
    assert!(table.contains("FAILED"), "{table}");
    assert!(
        table.contains(&format!("failed: failing: trial {}, step 7", failure.trial)),
        "{table}"
    );
    assert_eq!(results::failed(&summary).len(), 1);
    assert!(hushfuse::metrics::finite::non_finite(&summary).is_empty());
    let json = hushfuse::metrics::summary_json(&summary).unwrap();
    let row = &json["schemes"][1];
    assert_eq!(row["failed"]["trial"], failure.trial);
    assert_eq!(row["failed"]["step"], 7);
    assert!(row["steady_state"]["mse"].is_null());
    assert!(row["mse"][0].is_null());
    // Its energy too (issue 24), like its other numbers.
    assert!(row["energy_per_step_uj"].is_null());
    assert!(row["energy_parts_per_step_uj"]["tx"].is_null());
    assert!(json["schemes"][0]["energy_per_step_uj"].is_number());
    assert_eq!(row["name"], "failing");
    assert!(json["schemes"][0]["steady_state"]["mse"].is_number());
    assert!(json["schemes"][0].get("failed").is_none());
}
