//! Rate calibration: tune every scheme's bandwidth knob so that all schemes of
//! a scenario spend the same bits per step, then compare their accuracy at that budget.
//!
//! **Method.** Each `[[schemes]]` entry is run *alone* (so its coins always come from the same
//! stream, variant 0) on pilot runs of the scenario: same seed, same trials, hence the same
//! truths and measurements for every knob value (common random numbers). With common random
//! numbers the map knob -> bits per step is monotone (a threshold's rate falls as it grows; a
//! send probability's or `l`'s rises): the direction is read off the two ends of the range, and
//! the knob is bisected until the pilot's bits per step are within `tolerance` (relative, 2% by
//! default) of the target, or 40 halvings. Integer knobs (quantizer bits) are evaluated at every
//! integer of their range and the nearest is taken. A target outside what the range can reach
//! takes the nearer end and is marked. Schemes without a knob run as they are and are marked.
//!
//! By default the pilot runs use the scenario's own trials, so the point reported *is* the
//! pilot point: the achieved budget equals the pilot's, and the results are those of the scheme
//! alone with the calibrated knob (every scheme on the same truths). With fewer pilot trials
//! (`pilot_trials`) the calibrated knob is rerun at the full trial count and the achieved budget
//! is measured there (it then differs from the target by Monte Carlo error).
//!
//! **Knob ranges** ([`knob_range`]): declared by each kind's registry entry
//! ([`registry::Knob`]), from the parameters' documented values: `rate` of
//! `centralized-kf-random` in [0.001, 1]; `rate` of `dkf-alg1-random` in [0.5, 1]; `l` of
//! `censored-pf` in [0.001 N, N] (N sensors); `bits` of `quantized-innovation` the integers
//! 1..=8 (values that do not build, e.g. zhang above 3, end the range); every threshold
//! (`alpha`, `delta`, `tau`) in [0, hi], hi found by quadrupling from 1 until the rate is below
//! the smallest target (at most 4^12), or until it stops falling (a floor: hi is then the first
//! value on it).
//!
//! **Pilot runs** are built from the scenario parsed once ([`ScenarioFile`]) with the one
//! entry's table, the knob set in it: no scenario text is written or parsed per pilot run.
use crate::engine::runner;
use crate::metrics::results::{self, SchemeSummary, Summary};
use crate::scenario::build::{self, Experiment, LoadOptions};
use crate::scenario::ScenarioFile;
use crate::scheme::registry;
use serde::Serialize;
use std::collections::BTreeMap;

/// Which bits count against the budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// Uplink payload bits per step (the measurement or estimate bits).
    #[default]
    Payload,
    /// Whole 802.15.4 uplink frames per step (header, payload, footer).
    Frame,
    /// Frames plus the fusion center's downlink feedback bits.
    Total,
    /// What the sensors' radios spend per step, µJ (`[radio]`, [`crate::network::radio`]):
    /// frames sent, acknowledgements, listening for feedback and sleep. The axis a battery-powered
    /// deployment pays; its budget includes the radios' sleep, which no knob lowers.
    Energy,
}

impl Axis {
    /// Every axis, in the order the tables show their figures.
    pub const ALL: [Axis; 4] = [Axis::Payload, Axis::Frame, Axis::Total, Axis::Energy];

    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "payload" => Ok(Axis::Payload),
            "frame" => Ok(Axis::Frame),
            "total" => Ok(Axis::Total),
            "energy" => Ok(Axis::Energy),
            _ => Err(format!(
                "--budget-axis: expected payload, frame, total or energy, got {s:?}"
            )),
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Axis::Payload => "payload",
            Axis::Frame => "frame",
            Axis::Total => "total",
            Axis::Energy => "energy",
        }
    }
    /// What a budget on this axis counts, for the tables: "payload bits", …, "µJ".
    pub fn unit(self) -> &'static str {
        match self {
            Axis::Payload => "payload bits",
            Axis::Frame => "frame bits",
            Axis::Total => "total bits",
            Axis::Energy => "µJ",
        }
    }
    /// The bits (µJ) per step of a result on this axis.
    pub fn of(self, s: &SchemeSummary) -> f64 {
        match self {
            Axis::Payload => s.bits_per_step,
            Axis::Frame => s.frame_bits_per_step,
            Axis::Total => s.frame_bits_per_step + s.downlink_bits_per_step,
            Axis::Energy => s.energy.energy_per_step_uj,
        }
    }
}

/// Where a knob may range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnobRange {
    pub lo: f64,
    /// `None`: a threshold without an upper end (found by quadrupling).
    pub hi: Option<f64>,
    pub integer: bool,
    /// Bisect at the geometric midpoint ([`registry::Scale::Log`]).
    pub log: bool,
}

/// The range of `kind`'s knob on a system of `n_sensors` sensors: the registry's
/// [`registry::Knob`] of the kind with its per-sensor ends resolved.
pub fn knob_range(kind: &str, n_sensors: usize) -> Option<KnobRange> {
    let k = registry::find(kind)?.knob?;
    Some(KnobRange {
        lo: k.lo.at(n_sensors)?,
        hi: k.hi.at(n_sensors),
        integer: k.integer,
        log: k.scale == registry::Scale::Log,
    })
}

/// How a scheme met its budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Status {
    /// Within tolerance of the target.
    Calibrated,
    /// An integer knob whose reach contains the target, which falls between two integers: the
    /// nearer of them.
    NearestInteger,
    /// The target is outside the knob's reach: the nearer end of the range (which end:
    /// [`Calibrated::end`]). An integer knob at its end is this, never [`Status::NearestInteger`]:
    /// no integer of its range comes closer, however the rounding goes.
    OutOfRange,
    /// The scheme has no knob: run as it is.
    NoKnob,
    /// The knob could not be set (e.g. the entry uses another parameter instead): run as written.
    NotTunable,
}

impl Status {
    pub fn text(self) -> &'static str {
        match self {
            Status::Calibrated => "calibrated",
            Status::NearestInteger => "nearest integer",
            Status::OutOfRange => "out of range",
            Status::NoKnob => "no knob",
            Status::NotTunable => "not tunable",
        }
    }
}

/// Which end of its range a knob sits at when the target is out of its reach.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum End {
    /// The smallest value of the range (`bits = 1`, `rate = 0.001`, a threshold of 0).
    Lower,
    /// The largest value that builds (`bits = 8`, `rate = 1`, the threshold's found upper end).
    Upper,
}

impl End {
    /// The end of `[lo, hi]` nearer to `x` (the lower one on a tie, e.g. a one-value range).
    fn of(x: f64, lo: f64, hi: f64) -> Self {
        if (x - lo).abs() <= (hi - x).abs() {
            End::Lower
        } else {
            End::Upper
        }
    }
}

impl Calibrated {
    /// The status as the tables print it: "out of range" names the end of the knob's range
    /// (so `bits = 8` reads as the top of what the knob can do, not as a rounding).
    pub fn status_text(&self) -> String {
        match (self.status, self.end) {
            (Status::OutOfRange, Some(End::Lower)) => "out of range (lower end)".into(),
            (Status::OutOfRange, Some(End::Upper)) => "out of range (upper end)".into(),
            (st, _) => st.text().into(),
        }
    }
}

/// One scheme at one budget.
#[derive(Debug, Clone, Serialize)]
pub struct Calibrated {
    pub label: String,
    pub kind: String,
    pub knob: Option<String>,
    pub value: Option<f64>,
    pub target: f64,
    pub achieved: f64,
    pub status: Status,
    /// With [`Status::OutOfRange`]: the end of the range the knob was left at (`None` when a
    /// bisection inside the range stopped short of the tolerance: the map has a jump there).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub end: Option<End>,
    /// Knob evaluations (pilot runs) spent on this scheme, shared over all budgets.
    #[serde(skip)]
    pub result: SchemeSummary,
}

/// Calibration settings.
#[derive(Debug, Clone, Copy)]
pub struct Options {
    pub axis: Axis,
    /// Relative tolerance on the bits per step (default 0.02).
    pub tolerance: f64,
    /// Trials of the pilot runs (`None`: the scenario's).
    pub pilot_trials: Option<usize>,
    pub threads: usize,
    pub load: LoadOptions,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            axis: Axis::Payload,
            tolerance: 0.02,
            pilot_trials: None,
            threads: 0,
            load: LoadOptions::default(),
        }
    }
}

/// The result at every budget.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub budgets: Vec<f64>,
    /// `rows[b][s]`: budget b, scheme entry s.
    pub rows: Vec<Vec<Calibrated>>,
    /// One summary per budget: every scheme at its calibrated knob (the scenario's header).
    pub summaries: Vec<Summary>,
    /// The scenario text with the knobs of each budget (what was run).
    pub texts: Vec<String>,
    /// Pilot runs made.
    pub evaluations: usize,
    pub axis: Axis,
    pub tolerance: f64,
}

struct Evaluator<'a> {
    base: toml::Table,
    /// The scenario as parsed (once), without its schemes: a pilot run is this with one entry,
    /// built directly (no TOML text per pilot run).
    spec: ScenarioFile,
    file: &'a str,
    opts: &'a Options,
    evaluations: usize,
    /// Pilot runs made, by (scheme entry, knob value's bits): shared by every budget and every
    /// axis calibrated with this evaluator (a pilot run gives the spend on every axis).
    pilots: BTreeMap<(usize, u64), Result<SchemeSummary, String>>,
    /// Runs of the schemes without a knob, by entry.
    plain: BTreeMap<usize, SchemeSummary>,
    /// The PCRB and the rate–distortion floor of the whole scenario, computed once.
    bounds: Option<(
        Option<crate::metrics::pcrb::Pcrb>,
        crate::metrics::floor::ScenarioFloor,
    )>,
    /// Tests: build each pilot run from the scenario text, as before the typed path.
    #[cfg(test)]
    via_text: bool,
}

/// `spec` with the caller's `trials` and `seed` (as [`build::load_with`] applies them).
fn with_load(mut spec: ScenarioFile, load: &LoadOptions) -> ScenarioFile {
    if let Some(t) = load.trials {
        spec.trials = t;
    }
    if let Some(s) = load.seed {
        spec.seed = s;
    }
    spec
}

impl Evaluator<'_> {
    /// The scenario with only `entry`, at `trials`.
    fn text(&self, entries: &[toml::Table], trials: Option<usize>) -> String {
        let mut t = self.base.clone();
        t.insert(
            "schemes".into(),
            toml::Value::Array(entries.iter().cloned().map(toml::Value::Table).collect()),
        );
        if let Some(n) = trials {
            t.insert("trials".into(), toml::Value::Integer(n as i64));
        }
        toml::to_string(&t).expect("a TOML table serializes")
    }

    /// The experiment of `entry` alone, at `trials`.
    fn experiment(&self, entry: &toml::Table, trials: Option<usize>) -> Result<Experiment, String> {
        #[cfg(test)]
        if self.via_text {
            let text = self.text(std::slice::from_ref(entry), trials);
            return build::load_with(&text, self.file, &self.opts.load).map_err(|e| e.to_string());
        }
        let mut spec = self.spec.clone();
        spec.schemes = vec![entry.clone()];
        if let Some(n) = trials {
            spec.trials = n;
        }
        build::build_with(with_load(spec, &self.opts.load), self.file, &self.opts.load)
            .map_err(|e| e.to_string())
    }

    /// Runs `entry` alone; `Err` when it does not build (a knob value out of its range).
    fn run(&mut self, entry: &toml::Table, trials: Option<usize>) -> Result<Summary, String> {
        self.evaluations += 1;
        let exp = self.experiment(entry, trials)?;
        let sums = runner::run(
            &exp,
            runner::RunOptions {
                threads: self.opts.threads,
            },
            &|_| {},
        )
        .map_err(|e| e.to_string())?;
        if let Some(e) = runner::first_failure(&exp, &sums) {
            return Err(e.to_string());
        }
        Ok(results::summarize_schemes(&exp, &sums))
    }
}

fn with_knob(entry: &toml::Table, knob: &str, value: f64, integer: bool) -> toml::Table {
    let mut t = entry.clone();
    t.insert(
        knob.into(),
        if integer {
            toml::Value::Integer(value.round() as i64)
        } else {
            toml::Value::Float(value)
        },
    );
    t
}

/// The scheme entries of a scenario table, without `sweep` and `frontier` (one point each).
fn entries(base: &toml::Table) -> Result<Vec<toml::Table>, String> {
    let list = base
        .get("schemes")
        .and_then(|v| v.as_array())
        .ok_or("the scenario has no [[schemes]]")?;
    list.iter()
        .map(|v| {
            let mut t = v
                .as_table()
                .ok_or("a [[schemes]] entry is not a table")?
                .clone();
            if let Some(sweep) = t.remove("sweep") {
                // A swept entry is calibrated from the first value of each swept parameter.
                if let Some(s) = sweep.as_table() {
                    for (k, vals) in s {
                        if let Some(first) = vals.as_array().and_then(|a| a.first()) {
                            t.insert(k.clone(), first.clone());
                        }
                    }
                }
            }
            t.remove("frontier");
            Ok(t)
        })
        .collect()
}

/// What every scheme's calibration shares.
struct Setup<'a> {
    /// The whole scenario, validated.
    full: Experiment,
    /// Its scheme entries, one point each.
    list: Vec<toml::Table>,
    n_sensors: usize,
    trials: usize,
    pilot: Option<usize>,
    budgets: &'a [f64],
    axis: Axis,
    tol: f64,
}

/// The pilot runs of one scheme entry (number `ci` of the list), cached by knob value in the
/// evaluator; a failure keeps its cause.
struct Pilot<'a> {
    ci: usize,
    entry: &'a toml::Table,
    knob: &'static str,
    range: KnobRange,
    trials: Option<usize>,
}

impl Pilot<'_> {
    fn eval(&mut self, ev: &mut Evaluator, x: f64) -> Result<SchemeSummary, String> {
        let x = if self.range.integer { x.round() } else { x };
        let key = (self.ci, x.to_bits());
        if let Some(r) = ev.pilots.get(&key) {
            return r.clone();
        }
        let r = ev
            .run(
                &with_knob(self.entry, self.knob, x, self.range.integer),
                self.trials,
            )
            .map(|s| s.schemes[0].clone());
        ev.pilots.insert(key, r.clone());
        r
    }
}

/// Calibrates every scheme of the scenario `text` at every budget.
pub fn calibrate(
    text: &str,
    file: &str,
    budgets: &[f64],
    opts: &Options,
) -> Result<Outcome, String> {
    let (mut ev, setup) = prepare(text, file, budgets, opts)?;
    calibrate_all(&mut ev, &setup)
}

/// [`calibrate`] on several axes, each with its budgets (`opts.axis` is not used): one outcome
/// per axis, the same as [`calibrate`] would give for it, but every pilot run, and the floor and
/// the PCRB, made once for all axes (a pilot run gives the spend on every axis). Each outcome's
/// `evaluations` counts the pilot runs its axis added.
pub fn calibrate_axes<'a>(
    text: &str,
    file: &'a str,
    plans: &'a [(Axis, &'a [f64])],
    opts: &'a Options,
) -> Result<Vec<Outcome>, String> {
    let Some(&(axis, budgets)) = plans.first() else {
        return Ok(Vec::new());
    };
    let (mut ev, mut setup) = prepare(text, file, budgets, opts)?;
    setup.axis = axis;
    let mut out = Vec::with_capacity(plans.len());
    for &(axis, budgets) in plans {
        check_budgets(budgets)?;
        setup.axis = axis;
        setup.budgets = budgets;
        let before = ev.evaluations;
        let mut o = calibrate_all(&mut ev, &setup)?;
        o.evaluations = ev.evaluations - before;
        out.push(o);
    }
    Ok(out)
}

fn check_budgets(budgets: &[f64]) -> Result<(), String> {
    if budgets.is_empty() || budgets.iter().any(|b| !(b.is_finite() && *b > 0.0)) {
        return Err("budgets must be positive numbers of bits per step".into());
    }
    Ok(())
}

/// Checks the budgets, applies the caller's trials and seed, validates the whole scenario.
fn prepare<'a>(
    text: &str,
    file: &'a str,
    budgets: &'a [f64],
    opts: &'a Options,
) -> Result<(Evaluator<'a>, Setup<'a>), String> {
    check_budgets(budgets)?;
    let mut base: toml::Table = toml::from_str(text).map_err(|e| format!("{file}: {e}"))?;
    if let Some(t) = opts.load.trials {
        base.insert("trials".into(), toml::Value::Integer(t as i64));
    }
    if let Some(s) = opts.load.seed {
        base.insert("seed".into(), toml::Value::Integer(s as i64));
    }
    // Validate the whole scenario first (errors name the original file and field).
    let mut spec =
        build::parse(&toml::to_string(&base).expect("table"), file).map_err(|e| e.to_string())?;
    if spec.every_scheme {
        // Knobs are set on an explicit list: the registry's applicable kinds, written out.
        build::expand_every_scheme(&mut spec, file).map_err(|e| e.to_string())?;
        base.remove("every_scheme");
        let list = spec
            .schemes
            .iter()
            .cloned()
            .map(toml::Value::Table)
            .collect();
        base.insert("schemes".into(), toml::Value::Array(list));
    }
    let full = build::build_with(with_load(spec.clone(), &opts.load), file, &opts.load)
        .map_err(|e| e.to_string())?;
    spec.schemes.clear();
    let n_sensors = full.system.n_sensors();
    let trials = full.trials;
    let pilot = opts.pilot_trials.map(|p| p.clamp(1, trials));
    let list = entries(&base)?;
    let ev = Evaluator {
        base,
        spec,
        file,
        opts,
        evaluations: 0,
        pilots: BTreeMap::new(),
        plain: BTreeMap::new(),
        bounds: None,
        #[cfg(test)]
        via_text: false,
    };
    let setup = Setup {
        full,
        list,
        n_sensors,
        trials,
        pilot,
        budgets,
        axis: opts.axis,
        tol: opts.tolerance.max(1e-6),
    };
    Ok((ev, setup))
}

/// Every scheme at every budget, then the summaries and texts per budget.
fn calibrate_all(ev: &mut Evaluator, s: &Setup) -> Result<Outcome, String> {
    let mut per_scheme: Vec<Vec<Calibrated>> = Vec::new();
    for (ci, entry) in s.list.iter().enumerate() {
        per_scheme.push(calibrate_entry(ev, s, ci, entry)?);
    }
    Ok(assemble(ev, s, &per_scheme))
}

/// One scheme entry at every budget.
fn calibrate_entry(
    ev: &mut Evaluator,
    s: &Setup,
    ci: usize,
    entry: &toml::Table,
) -> Result<Vec<Calibrated>, String> {
    let kind = s.full.curves[ci].kind.clone();
    let label = s.full.curves[ci].label.clone();
    let reg = registry::find(&kind).ok_or("unknown kind")?;
    let range = reg
        .knob
        .and_then(|k| knob_range(&kind, s.n_sensors).map(|r| (k.name, r)));
    let Some((knob, range)) = range else {
        return uncalibrated(ev, s, ci, entry, &label, &kind, reg.knob.map(|k| k.name));
    };
    let mut p = Pilot {
        ci,
        entry,
        knob,
        range,
        trials: s.pilot,
    };
    let chosen = if range.integer {
        choose_integer(ev, s, &mut p, &label)?
    } else {
        choose_continuous(ev, s, &mut p, &label)?
    };
    let mut rows = Vec::new();
    for ((x, mut sum, st, end), &b) in chosen.into_iter().zip(s.budgets) {
        if s.pilot.is_some_and(|p| p < s.trials) {
            sum = ev
                .run(&with_knob(entry, knob, x, range.integer), None)?
                .schemes[0]
                .clone();
        }
        rows.push(Calibrated {
            label: label.clone(),
            kind: kind.clone(),
            knob: Some(knob.to_string()),
            value: Some(if range.integer { x.round() } else { x }),
            target: b,
            achieved: s.axis.of(&sum),
            status: st,
            end,
            result: sum,
        });
    }
    Ok(rows)
}

/// A scheme without a knob (or whose knob cannot be set): run as it is, at every budget.
fn uncalibrated(
    ev: &mut Evaluator,
    s: &Setup,
    ci: usize,
    entry: &toml::Table,
    label: &str,
    kind: &str,
    knob: Option<&str>,
) -> Result<Vec<Calibrated>, String> {
    let r = match ev.plain.get(&ci) {
        Some(r) => r.clone(),
        None => {
            let r = ev.run(entry, None)?.schemes[0].clone();
            ev.plain.insert(ci, r.clone());
            r
        }
    };
    Ok(s.budgets
        .iter()
        .map(|&b| Calibrated {
            label: label.to_string(),
            kind: kind.to_string(),
            knob: knob.map(str::to_string),
            value: None,
            target: b,
            achieved: s.axis.of(&r),
            status: if knob.is_some() {
                Status::NotTunable
            } else {
                Status::NoKnob
            },
            end: None,
            result: r.clone(),
        })
        .collect())
}

/// A knob value chosen for one budget: the value, its pilot result, how it met the budget and,
/// out of range, at which end.
type Choice = (f64, SchemeSummary, Status, Option<End>);

/// A continuous knob's two ends and their pilot runs; an open upper end is found by
/// quadrupling from 1 until below the smallest target, or until the rate stops falling.
#[allow(clippy::type_complexity)]
fn ends(
    ev: &mut Evaluator,
    s: &Setup,
    p: &mut Pilot,
    label: &str,
) -> Result<((f64, SchemeSummary), (f64, SchemeSummary)), String> {
    let (axis, knob, range) = (s.axis, p.knob, p.range);
    let min_target = s.budgets.iter().copied().fold(f64::INFINITY, f64::min);
    let lo = range.lo;
    let f_lo = p
        .eval(ev, lo)
        .map_err(|e| format!("{label}: `{knob}` = {lo} does not build: {e}"))?;
    let mut hi = range.hi.unwrap_or(1.0);
    let mut f_hi = p
        .eval(ev, hi)
        .map_err(|e| format!("{label}: `{knob}` = {hi} does not build: {e}"))?;
    if range.hi.is_none() {
        let mut n = 0;
        // Quadruple until below the smallest target; stop where the rate no longer
        // falls (a scheme with a floor, e.g. Algorithm 1's send-after-silence), keeping
        // the first value of the floor.
        while axis.of(&f_hi) > min_target && n < 12 {
            match p.eval(ev, hi * 4.0) {
                Ok(s) if axis.of(&s) < axis.of(&f_hi) => {
                    hi *= 4.0;
                    f_hi = s;
                }
                _ => break,
            }
            n += 1;
        }
    }
    Ok(((lo, f_lo), (hi, f_hi)))
}

/// A continuous knob: its ends, then per budget the nearer end when the budget is out of
/// reach, else a bisection.
fn choose_continuous(
    ev: &mut Evaluator,
    s: &Setup,
    p: &mut Pilot,
    label: &str,
) -> Result<Vec<Choice>, String> {
    let (axis, tol) = (s.axis, s.tol);
    let ((lo, f_lo), (hi, f_hi)) = ends(ev, s, p, label)?;
    let increasing = axis.of(&f_hi) >= axis.of(&f_lo);
    let mut chosen = Vec::new();
    for &b in s.budgets {
        let (a_lo, a_hi) = (axis.of(&f_lo), axis.of(&f_hi));
        let (min, max) = (a_lo.min(a_hi), a_lo.max(a_hi));
        if b <= min * (1.0 - tol) || b >= max * (1.0 + tol) {
            let at_lo = (b < min) == (a_lo <= a_hi);
            let (x, s) = if at_lo { (lo, &f_lo) } else { (hi, &f_hi) };
            let (st, end) = if (axis.of(s) - b).abs() <= tol * b {
                (Status::Calibrated, None)
            } else {
                let end = if at_lo { End::Lower } else { End::Upper };
                (Status::OutOfRange, Some(end))
            };
            chosen.push((x, s.clone(), st, end));
            continue;
        }
        let best = if (a_lo - b).abs() < (a_hi - b).abs() {
            (lo, f_lo.clone())
        } else {
            (hi, f_hi.clone())
        };
        chosen.push(bisect(ev, s, p, b, (lo, hi), best, increasing));
    }
    Ok(chosen)
}

/// The point a bisection of `[a, c]` tries next: the arithmetic midpoint, or on a log-scale
/// knob the geometric one (the arithmetic one where an end is not positive).
fn midpoint(a: f64, c: f64, log: bool) -> f64 {
    if log && a > 0.0 && c > 0.0 {
        (a * c).sqrt()
    } else {
        0.5 * (a + c)
    }
}

/// Bisects `[lo, hi]` towards budget `b` from the nearer end `best` (at most 40 halvings).
fn bisect(
    ev: &mut Evaluator,
    s: &Setup,
    p: &mut Pilot,
    b: f64,
    (lo, hi): (f64, f64),
    mut best: (f64, SchemeSummary),
    increasing: bool,
) -> Choice {
    let (axis, tol) = (s.axis, s.tol);
    let (mut a, mut c) = (lo, hi);
    for _ in 0..40 {
        if (axis.of(&best.1) - b).abs() <= tol * b {
            break;
        }
        let mid = midpoint(a, c, p.range.log);
        let Ok(s) = p.eval(ev, mid) else { break };
        let f = axis.of(&s);
        if (f - b).abs() < (axis.of(&best.1) - b).abs() {
            best = (mid, s.clone());
        }
        if (f < b) == increasing {
            a = mid;
        } else {
            c = mid;
        }
    }
    let (st, end) = if (axis.of(&best.1) - b).abs() <= tol * b {
        (Status::Calibrated, None)
    } else if best.0 == lo || best.0 == hi {
        // Left at an end: as far as the range goes towards the budget.
        (Status::OutOfRange, Some(End::of(best.0, lo, hi)))
    } else {
        (Status::OutOfRange, None)
    };
    (best.0, best.1, st, end)
}

/// Per budget: the summary of every scheme at its knob, and the scenario as run.
fn assemble(ev: &mut Evaluator, s: &Setup, per_scheme: &[Vec<Calibrated>]) -> Outcome {
    let mut rows = Vec::new();
    let mut summaries = Vec::new();
    let mut texts = Vec::new();
    let header = results::summarize_schemes(&s.full, &[]);
    let (pcrb, floor) = ev
        .bounds
        .get_or_insert_with(|| {
            (
                crate::metrics::pcrb::compute(&s.full).ok(),
                crate::metrics::floor::floor_of(&s.full),
            )
        })
        .clone();
    for b in 0..s.budgets.len() {
        let mut row: Vec<Calibrated> = per_scheme.iter().map(|r| r[b].clone()).collect();
        let tables: Vec<toml::Table> = s
            .list
            .iter()
            .zip(&row)
            .map(|(e, c)| match (&c.knob, c.value) {
                (Some(k), Some(v)) => with_knob(
                    e,
                    k,
                    v,
                    knob_range(&c.kind, s.n_sensors).is_some_and(|r| r.integer),
                ),
                _ => e.clone(),
            })
            .collect();
        let mut summary = header.clone();
        summary.pcrb = pcrb.clone();
        summary.schemes = row
            .iter()
            .enumerate()
            .map(|(ci, c)| {
                let mut s = c.result.clone();
                s.curve = ci;
                s
            })
            .collect();
        results::apply_floor(&floor, &mut summary);
        for (c, sc) in row.iter_mut().zip(&summary.schemes) {
            c.result.floor_mse = sc.floor_mse;
        }
        texts.push(ev.text(&tables, None));
        summaries.push(summary);
        rows.push(row);
    }
    Outcome {
        budgets: s.budgets.to_vec(),
        rows,
        summaries,
        texts,
        evaluations: ev.evaluations,
        axis: s.axis,
        tolerance: s.tol,
    }
}

/// Why `budgets` cannot be met on `axis`, before any pilot run: on the energy axis, a budget
/// below what the sensors' radios spend asleep, which no scheme goes under. The command line
/// and Python both ask it.
pub fn energy_floor_problem(exp: &Experiment, axis: Axis, budgets: &[f64]) -> Option<String> {
    if axis != Axis::Energy {
        return None;
    }
    let asleep = exp.radio.asleep_step_uj(exp.battery_radios());
    let radios = match exp.network {
        None => format!("{} sensors' radios", exp.system.n_sensors()),
        Some(_) => format!("network's {} battery-powered radios", exp.battery_radios()),
    };
    budgets.iter().find(|&&b| b < asleep).map(|b| {
        format!(
            "budget {} µJ/step is below what the {radios} spend asleep ({} µJ/step), which no scheme goes under",
            short(*b),
            short(asleep)
        )
    })
}

/// A number with at most 4 significant decimals.
pub fn short(v: f64) -> String {
    // Beyond a billion bits the digits say nothing and would widen a table past any screen.
    if v.abs() >= 1e9 {
        let s = format!("{v:.4e}");
        let (mantissa, exponent) = s.split_once('e').expect("exponent form");
        let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
        return format!("{mantissa}e{exponent}");
    }
    let s = format!("{v:.4}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// A bits-per-step cell of a table: one decimal, or [`short`]'s exponent form when huge.
pub fn bits_cell(v: f64) -> String {
    if v.abs() >= 1e9 {
        short(v)
    } else {
        format!("{v:.1}")
    }
}

/// A name for budget `v` that no other f64 shares: [`short`] where it reads back as `v` (24,
/// 12.5), the shortest round-tripping decimal otherwise, and an exponent form (`1e300`,
/// `2e-300`) for very large or small magnitudes.
pub fn dir_label(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-4..1e15).contains(&a) {
        return format!("{v:e}");
    }
    let s = short(v);
    if s.parse::<f64>() == Ok(v) {
        s
    } else {
        format!("{v}")
    }
}

/// Left-aligned first column, right-aligned others, a rule under the header.
pub fn render(rows: &[Vec<String>]) -> String {
    crate::metrics::results::text_table(rows, 1)
}

mod integer;
use integer::choose_integer;
#[cfg(test)]
mod tests;
