//! From merged sums to the numbers people read: `summary.json`, `per_step.csv` and the table.
use crate::metrics::{Layout, Sums};
use crate::scenario::build::Experiment;
use crate::scenario::Params;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// Steady-state averages (steps >= `from_step`) with Monte Carlo standard errors computed from
/// the spread of the per-trial averages.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SteadyState {
    pub from_step: usize,
    /// Total squared error summed over all state components (comparable with `trace`).
    pub mse: f64,
    pub mse_se: f64,
    pub trace: f64,
    pub trace_se: f64,
    /// Mean NEES divided by the state dimension (1 for a consistent filter).
    pub anees: f64,
    pub anees_se: f64,
    pub rate: f64,
    pub rate_se: f64,
}

impl SteadyState {
    /// The steady-state averages of a variant's `sums`, with their standard errors.
    fn of(exp: &Experiment, s: &Sums) -> Self {
        let (n, n_sensors) = (exp.system.state_dim() as f64, exp.system.n_sensors() as f64);
        let (mse, mse_se) = s.steady_mse.mean_se(exp.trials);
        let (trace, trace_se) = s.steady_trace.mean_se(exp.trials);
        let (nees, nees_se) = s.steady_nees.mean_se(exp.trials);
        let (msg, msg_se) = s.steady_messages.mean_se(exp.trials);
        SteadyState {
            from_step: exp.steady_from,
            mse,
            mse_se,
            trace,
            trace_se,
            anees: nees / n,
            anees_se: nees_se / n,
            rate: msg / n_sensors,
            rate_se: msg_se / n_sensors,
        }
    }
}

/// Per-step traffic: mean over trials and its standard error at each step.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TrafficPerStep {
    /// Transmissions / sensors.
    pub rate: Vec<f64>,
    pub rate_se: Vec<f64>,
    /// Uplink payload bits (all sensors).
    pub payload_bits: Vec<f64>,
    pub payload_bits_se: Vec<f64>,
    /// Bits of the 802.15.4 MAC frames sent.
    pub frame_bits: Vec<f64>,
    pub frame_bits_se: Vec<f64>,
    /// Feedback bits from the fusion center.
    pub downlink_bits: Vec<f64>,
    pub downlink_bits_se: Vec<f64>,
}

impl TrafficPerStep {
    /// From the per-step mean (`col`) and standard error (`col_se`) of a layout field, and the
    /// division by the number of sensors (`per_sensor`) that makes a rate of messages.
    fn of(
        col: &dyn Fn(usize) -> Vec<f64>,
        col_se: &dyn Fn(usize) -> Vec<f64>,
        per_sensor: &dyn Fn(Vec<f64>) -> Vec<f64>,
    ) -> Self {
        Self {
            rate: per_sensor(col(Layout::MESSAGES)),
            rate_se: per_sensor(col_se(Layout::MESSAGES)),
            payload_bits: col(Layout::BITS),
            payload_bits_se: col_se(Layout::BITS),
            frame_bits: col(Layout::FRAME_BITS),
            frame_bits_se: col_se(Layout::FRAME_BITS),
            downlink_bits: col(Layout::DOWNLINK_BITS),
            downlink_bits_se: col_se(Layout::DOWNLINK_BITS),
        }
    }
}

/// Results of one scheme variant.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SchemeSummary {
    pub name: String,
    pub kind: String,
    pub curve: usize,
    pub params: Params,
    /// The entry's `note`: what differs on this row from the others (absent: nothing).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// RMSE per state group per step.
    pub rmse: BTreeMap<String, Vec<f64>>,
    /// Standard error of `rmse` (delta method: se(MSE) / (2 RMSE)).
    pub rmse_se: BTreeMap<String, Vec<f64>>,
    /// Time average of the per-step RMSE, per group.
    pub mean_rmse: BTreeMap<String, f64>,
    /// An upper bound on the standard error of `mean_rmse`: the time average of `rmse_se`,
    /// exact when the errors of all steps are fully correlated across trials and larger
    /// otherwise (the exact delta-method value needs every pair of steps' covariance).
    pub mean_rmse_se_upper: BTreeMap<String, f64>,
    /// Mean total squared error per step.
    pub mse: Vec<f64>,
    pub mse_se: Vec<f64>,
    /// Mean trace of the fused covariance per step.
    pub trace: Vec<f64>,
    pub trace_se: Vec<f64>,
    /// Mean NEES / state dimension per step.
    pub anees_per_step: Vec<f64>,
    pub anees_per_step_se: Vec<f64>,
    /// Time average of `anees_per_step`.
    pub anees: f64,
    /// Standard error of `anees`, from the per-trial time averages (as for every `*_se` of a
    /// time-averaged mean below).
    pub anees_se: f64,
    /// Transmissions / (sensors x steps).
    pub rate: f64,
    pub rate_se: f64,
    /// Mean number of sensors transmitting per step.
    pub transmissions_per_step: f64,
    pub transmissions_per_step_se: f64,
    /// Mean payload bits sent per step (all sensors).
    pub bits_per_step: f64,
    pub bits_per_step_se: f64,
    /// Mean bits of the 802.15.4 MAC frames sent per step (header, payload, footer).
    pub frame_bits_per_step: f64,
    pub frame_bits_per_step_se: f64,
    /// Mean feedback bits from the fusion center to the sensors per step.
    pub downlink_bits_per_step: f64,
    pub downlink_bits_per_step_se: f64,
    /// What the traffic costs the sensors' radios (`[radio]`): `energy_per_step_uj`, per sensor,
    /// by part, and the average sensor's `lifetime_days` ([`crate::metrics::energy`]).
    /// Over a multi-hop `[network]`: the network's, every battery-powered node's energy added
    /// and the first node to die as `lifetime_days` ([`crate::metrics::network`]).
    #[serde(flatten)]
    pub energy: crate::metrics::energy::EnergySummary,
    /// Over a multi-hop `[network]`: every node's frames, energy and lifetime, and the first
    /// node to die ([`crate::metrics::network`]); absent on a star.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub network: Option<crate::metrics::network::NetworkSummary>,
    /// A decentralized scheme (every node estimates; the row is the mean over its nodes): each
    /// node's steady-state MSE, ANEES and energy, the worst node and the nodes' disagreement
    /// ([`crate::metrics::estimators`]); absent for a scheme with one estimate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimators: Option<crate::metrics::estimators::EstimatorsSummary>,
    /// The entropy-coded rate `R_eff`, bits per step: each sensor's send-or-silence decision
    /// (its binary entropy) plus its payload once per message ([`crate::metrics::floor`]).
    pub r_eff_per_step: f64,
    /// The rate–distortion floor at `r_eff_per_step` on the steady-state MSE
    /// (`steady_state.mse`): no causal scheme spending that rate does better. Null where the
    /// scenario has no floor (`rate_distortion_floor_note` says why) or the rate is too low for
    /// any finite error.
    #[serde(default)]
    pub floor_mse: Option<f64>,
    /// Per step: rate and bits with their standard errors.
    pub traffic_per_step: TrafficPerStep,
    /// Fraction of (trial, step) pairs whose fused covariance was singular (collapsed
    /// particle clouds); their NEES used a 1e-9 relative jitter.
    pub degenerate_covariance_fraction: f64,
    pub degenerate_covariance_fraction_se: f64,
    /// Fraction of (trial, step) pairs whose NEES was below the chi-square 99% quantile: 0.99
    /// for a consistent filter. Robust where the mean NEES is ruined by a few collapsed
    /// particle clouds.
    pub nees_coverage_99: f64,
    pub nees_coverage_99_se: f64,
    /// Fraction of (trial, step) pairs whose NEES was below the chi-square 95% quantile: 0.95
    /// for a consistent filter.
    pub nees_coverage_95: f64,
    pub nees_coverage_95_se: f64,
    /// Fraction of trials that diverged: NEES above the chi-square(n) 99.9% quantile for 10
    /// consecutive steps, or a squared error or NEES that is not finite
    /// ([`crate::metrics::DIVERGENCE_RUN`]).
    pub diverged_fraction: f64,
    /// Binomial standard error sqrt(p (1 - p) / trials).
    pub diverged_fraction_se: f64,
    /// Effective sample size of particle-filter fusion centers (absent for other schemes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ess: Option<EssSummary>,
    /// What the link did to the messages (absent for an ideal link).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<crate::metrics::link::LinkSummary>,
    /// The first trial of this variant that failed (the variant's numbers are then not
    /// reported: null in summary.json, a failed row in the table).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failed: Option<crate::metrics::TrialFailure>,
    /// Statistics of the NEES that a few collapsed trials cannot ruin.
    pub consistency: Consistency,
    pub steady_state: SteadyState,
    /// Per trial: steady-state MSE, total then per group (for paired comparisons; not
    /// written to summary.json).
    #[serde(skip)]
    pub per_trial: Vec<Vec<f64>>,
}

/// Effective sample size `1 / sum w^2` of a particle filter's weights after each update, before
/// resampling.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct EssSummary {
    /// Time average of `mean_per_step`.
    pub mean: f64,
    pub mean_se: f64,
    /// Smallest ESS of any trial at any step.
    pub min: f64,
    /// Mean across trials per step.
    pub mean_per_step: Vec<f64>,
    /// Minimum across trials per step.
    pub min_per_step: Vec<f64>,
}

/// Robust consistency statistics (steady state), beside the mean ANEES.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Consistency {
    /// Median over steady-state (trial, step) pairs of NEES / n (interpolated in a histogram
    /// with 50 bins per decade).
    pub median_nees: f64,
    /// What a consistent filter gives: the chi-square(n) median / n.
    pub median_nees_expected: f64,
    /// The 95% interval of a per-step ANEES (mean NEES over this run's trials / n) of a
    /// consistent filter: chi-square(trials x n) 2.5% and 97.5% quantiles / (trials x n).
    pub anees_interval_95: [f64; 2],
    /// Fraction of steady-state steps whose ANEES lies inside `anees_interval_95` (about 0.95
    /// for a consistent filter).
    pub anees_steps_in_interval: f64,
    /// Share of the summed steady-state NEES carried by the largest 1% of trials (at least
    /// one trial).
    pub top_trials_share: f64,
    /// Whether the mean ANEES is dominated by a few trials: the largest 1% of trials carry
    /// more than half of it (judged from 10 trials on). Read the median and the coverage
    /// instead.
    pub mean_dominated: bool,
}

/// The whole run.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Summary {
    pub scenario: String,
    pub description: String,
    pub source: String,
    pub trials: usize,
    pub steps: usize,
    pub seed: u64,
    pub sensors: usize,
    pub state_dim: usize,
    pub groups: BTreeMap<String, Vec<usize>>,
    /// Group names in file order.
    pub group_order: Vec<String>,
    pub schemes: Vec<SchemeSummary>,
    /// The frames' 802.15.4 security when the scenario secures them (`[security]`): every
    /// scheme's frame bits, feedback bits and energy include its auxiliary header and MIC.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub security: Option<crate::link::security::SecuritySpec>,
    /// The posterior Cramér–Rao bound of the model with every sensor at every step, where it
    /// is defined (see [`crate::metrics::pcrb`]); absent where it was not computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pcrb: Option<crate::metrics::pcrb::Pcrb>,
    /// The rate–distortion floor as a curve of steady-state MSE against bits per step
    /// ([`crate::metrics::floor`]); absent where the scenario has none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_distortion_floor: Option<crate::metrics::floor::FloorCurve>,
    /// Why `rate_distortion_floor` is null.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_distortion_floor_note: Option<String>,
    /// Warnings about the run as a whole, not one scheme's health (readings that singles round
    /// coarser than their noise, [`crate::metrics::precision`]); [`warnings`] prints them after
    /// the schemes' own. Absent when there are none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

/// Turns sums into per-scheme results, with the model's posterior Cramér–Rao bound where it is
/// defined.
pub fn summarize(exp: &Experiment, sums: &[Sums]) -> Summary {
    let mut s = summarize_schemes(exp, sums);
    s.pcrb = crate::metrics::pcrb::compute(exp).ok();
    apply_floor(&crate::metrics::floor::floor_of(exp), &mut s);
    s
}

/// Fills in the rate–distortion floor of a summary's system (`floor`, from
/// [`crate::metrics::floor::floor_of`]): the curve, and each scheme's floor at its
/// `r_eff_per_step`, or the reason there is none.
pub fn apply_floor(floor: &crate::metrics::floor::ScenarioFloor, s: &mut Summary) {
    let rates: Vec<f64> = s.schemes.iter().map(|x| x.r_eff_per_step).collect();
    let at = crate::metrics::floor::floors_at(floor, &rates);
    for (x, f) in s.schemes.iter_mut().zip(at) {
        x.floor_mse = f;
    }
    s.rate_distortion_floor = floor.as_ref().ok().map(|(_, c)| c.clone());
    s.rate_distortion_floor_note = floor.as_ref().err().cloned();
}

/// [`summarize`] without the bound: for the many pilot runs of a calibration, whose bound is
/// the scenario's and is computed once.
pub fn summarize_schemes(exp: &Experiment, sums: &[Sums]) -> Summary {
    let n = exp.system.state_dim() as f64;
    let n_sensors = exp.system.n_sensors() as f64;
    let (trials, steps) = (exp.trials as f64, exp.steps);
    let schemes = exp
        .variants
        .iter()
        .zip(sums)
        .map(|(v, s)| {
            let layout = s.layout();
            let col = |f: usize| -> Vec<f64> { (0..steps).map(|k| s.at(k, f) / trials).collect() };
            let col_se =
                |f: usize| -> Vec<f64> { (0..steps).map(|k| s.mean_se_at(k, f).1).collect() };
            // Standard error of a time-averaged mean of field f, scaled like the mean.
            let run_se = |f: usize, scale: f64| s.whole_run[f].mean_se(exp.trials).1 * scale;
            let mut rmse = BTreeMap::new();
            let mut rmse_se = BTreeMap::new();
            let mut mean_rmse = BTreeMap::new();
            let mut mean_rmse_se_upper = BTreeMap::new();
            for (g, (name, _)) in exp.groups.iter().enumerate() {
                let r: Vec<f64> = col(layout.group(g)).into_iter().map(f64::sqrt).collect();
                let r_se: Vec<f64> = col_se(layout.group(g))
                    .into_iter()
                    .zip(&r)
                    .map(|(se, r)| rmse_se_of(se, *r))
                    .collect();
                mean_rmse.insert(name.clone(), r.iter().sum::<f64>() / steps as f64);
                mean_rmse_se_upper.insert(name.clone(), r_se.iter().sum::<f64>() / steps as f64);
                rmse.insert(name.clone(), r);
                rmse_se.insert(name.clone(), r_se);
            }
            let per_sensor =
                |v: Vec<f64>| -> Vec<f64> { v.into_iter().map(|x| x / n_sensors).collect() };
            let traffic_per_step = TrafficPerStep::of(&col, &col_se, &per_sensor);
            let (energy, network, estimators) = crate::metrics::estimators::of_variant(exp, v, s);
            let p_div = s.diverged as f64 / trials;
            let anees_per_step: Vec<f64> = col(Layout::NEES).into_iter().map(|x| x / n).collect();
            let sum = |f: usize| -> f64 { col(f).iter().sum() };
            let [messages, bits, frame_bits, downlink_bits, degenerate, covered] = [
                Layout::MESSAGES,
                Layout::BITS,
                Layout::FRAME_BITS,
                Layout::DOWNLINK_BITS,
                Layout::DEGENERATE,
                Layout::NEES_COVERED,
            ]
            .map(sum);
            let covered_95: f64 = col(Layout::NEES_COVERED_95).iter().sum();
            let ess = s.has_ess.then(|| {
                let mean_per_step = col(Layout::ESS);
                EssSummary {
                    mean: mean_per_step.iter().sum::<f64>() / steps as f64,
                    mean_se: run_se(Layout::ESS, 1.0),
                    min: s.ess_min.iter().copied().fold(f64::INFINITY, f64::min),
                    mean_per_step,
                    min_per_step: s.ess_min.clone(),
                }
            });
            let consistency = consistency(
                exp.system.state_dim(),
                exp.trials,
                exp.steady_from,
                s,
                &anees_per_step,
            );
            SchemeSummary {
                name: exp.curves[v.curve].label.clone(),
                kind: v.kind.to_string(),
                curve: v.curve,
                params: v.params.clone(),
                note: exp.curves[v.curve].note.clone(),
                rmse,
                rmse_se,
                mean_rmse,
                mean_rmse_se_upper,
                mse: col(Layout::TOTAL_SE),
                mse_se: col_se(Layout::TOTAL_SE),
                trace: col(Layout::TRACE),
                trace_se: col_se(Layout::TRACE),
                anees: anees_per_step.iter().sum::<f64>() / steps as f64,
                anees_se: run_se(Layout::NEES, 1.0 / n),
                anees_per_step,
                anees_per_step_se: col_se(Layout::NEES).into_iter().map(|x| x / n).collect(),
                rate: messages / (steps as f64 * n_sensors),
                rate_se: run_se(Layout::MESSAGES, 1.0 / n_sensors),
                transmissions_per_step: messages / steps as f64,
                transmissions_per_step_se: run_se(Layout::MESSAGES, 1.0),
                bits_per_step: bits / steps as f64,
                bits_per_step_se: run_se(Layout::BITS, 1.0),
                frame_bits_per_step: frame_bits / steps as f64,
                frame_bits_per_step_se: run_se(Layout::FRAME_BITS, 1.0),
                downlink_bits_per_step: downlink_bits / steps as f64,
                downlink_bits_per_step_se: run_se(Layout::DOWNLINK_BITS, 1.0),
                energy,
                network,
                estimators,
                r_eff_per_step: crate::metrics::floor::r_eff_of(exp, s, bits, messages),
                floor_mse: None,
                traffic_per_step,
                degenerate_covariance_fraction: degenerate / steps as f64,
                degenerate_covariance_fraction_se: run_se(Layout::DEGENERATE, 1.0),
                nees_coverage_99: covered / steps as f64,
                nees_coverage_99_se: run_se(Layout::NEES_COVERED, 1.0),
                nees_coverage_95: covered_95 / steps as f64,
                nees_coverage_95_se: run_se(Layout::NEES_COVERED_95, 1.0),
                diverged_fraction: p_div,
                diverged_fraction_se: binomial_se(p_div, exp.trials),
                ess,
                link: v
                    .channel
                    .as_ref()
                    .map(|_| crate::metrics::link::summarize(s, exp.trials, col(Layout::MESSAGES))),
                failed: s.failure.clone(),
                consistency,
                per_trial: s.per_trial_rows().map(<[f64]>::to_vec).collect(),
                steady_state: SteadyState::of(exp, s),
            }
        })
        .collect();
    Summary {
        scenario: exp.name.clone(),
        description: exp.description.clone(),
        source: exp.source.clone(),
        trials: exp.trials,
        steps: exp.steps,
        seed: exp.seed,
        sensors: exp.system.n_sensors(),
        state_dim: exp.system.state_dim(),
        groups: exp.groups.iter().cloned().collect(),
        group_order: exp.groups.iter().map(|(g, _)| g.clone()).collect(),
        schemes,
        security: exp.security.is_secured().then_some(exp.security),
        pcrb: None,
        rate_distortion_floor: None,
        rate_distortion_floor_note: None,
        // The readings are the same for every variant: the first's peaks are the run's.
        warnings: sums
            .first()
            .map(|s| crate::metrics::precision::rounding_warnings(exp, &s.reading_peaks))
            .unwrap_or_default(),
    }
}

/// Standard error of an RMSE from that of its MSE by the delta method: d sqrt(m) = dm / (2
/// sqrt(m)). A zero RMSE with a zero spread has a zero standard error.
/// sqrt(p (1 - p) / trials); NaN without trials.
fn binomial_se(p: f64, trials: usize) -> f64 {
    if trials > 0 {
        (p * (1.0 - p) / trials as f64).sqrt()
    } else {
        f64::NAN
    }
}

fn rmse_se_of(mse_se: f64, rmse: f64) -> f64 {
    if mse_se == 0.0 {
        0.0
    } else {
        mse_se / (2.0 * rmse)
    }
}

/// Robust consistency statistics of one variant.
pub fn consistency(
    state_dim: usize,
    trials: usize,
    steady_from: usize,
    s: &Sums,
    anees_per_step: &[f64],
) -> Consistency {
    let n = state_dim as f64;
    let q = |dof: f64, tail: f64| crate::stats::chi2::upper_quantile(dof, tail).unwrap_or(f64::NAN);
    let nn = trials as f64 * n;
    let interval = [q(nn, 0.975) / nn, q(nn, 0.025) / nn];
    let steady: Vec<f64> = anees_per_step
        .iter()
        .skip(steady_from.saturating_sub(1))
        .copied()
        .collect();
    let inside = steady
        .iter()
        .filter(|&&a| a >= interval[0] && a <= interval[1])
        .count();
    let mut per_trial = s.per_trial_nees.clone();
    per_trial.sort_by(|a, b| b.total_cmp(a));
    let top = per_trial.len().div_ceil(100).max(1);
    let total: f64 = per_trial.iter().sum();
    let share = if total > 0.0 {
        per_trial.iter().take(top).sum::<f64>() / total
    } else {
        0.0
    };
    let steady_dominated = per_trial.len() >= 10 && share > 0.5;
    // The printed ANEES averages every step, not the steady state alone: a trial that collapses
    // at step 2 carries it without touching the steady-state values. From the per-trial sums of
    // the whole run's NEES (x_t >= 0), the largest trial carries at least Σx²/(Σx)² of it
    // (Σx² <= max x · Σx); more than half is dominance of what is printed.
    let whole = &s.whole_run[Layout::NEES];
    let whole_share = if whole.sum > 0.0 {
        whole.sum_sq / (whole.sum * whole.sum)
    } else {
        0.0
    };
    let whole_dominated = trials >= 10 && whole_share > 0.5;
    Consistency {
        median_nees: s.nees_hist.median().unwrap_or(f64::NAN),
        median_nees_expected: q(n, 0.5) / n,
        anees_interval_95: interval,
        anees_steps_in_interval: inside as f64 / steady.len().max(1) as f64,
        top_trials_share: if whole_dominated {
            share.max(whole_share)
        } else {
            share
        },
        mean_dominated: steady_dominated || whole_dominated,
    }
}

/// Compact "k=v, k=v" of a variant's parameters.
pub fn params_text(p: &Params) -> String {
    p.iter()
        .map(|(k, v)| format!("{k}={v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A number for the table: fixed decimals, scientific beyond 1e6, "overflow" if not finite.
pub fn num(v: f64, decimals: usize) -> String {
    if !v.is_finite() {
        "overflow".to_string()
    } else if v.abs() >= 1e6 {
        format!("{v:.1e}")
    } else {
        format!("{v:.decimals$}")
    }
}

/// The results table printed on the terminal, followed by a warning line per scheme whose
/// health needs attention (see [`warnings`]). Columns for divergence, degenerate covariances
/// and the particle ESS appear only when some scheme has a non-zero value / a particle filter.
pub fn table(summary: &Summary) -> String {
    let groups: Vec<&String> = summary.group_order.iter().collect();
    let any_diverged = summary.schemes.iter().any(|s| s.diverged_fraction > 0.0);
    let any_degenerate = summary
        .schemes
        .iter()
        .any(|s| s.degenerate_covariance_fraction > 0.0);
    let any_ess = summary.schemes.iter().any(|s| s.ess.is_some());
    let mut header = vec!["scheme".to_string(), "params".to_string()];
    header.extend(groups.iter().map(|g| format!("RMSE {g}")));
    let accuracy = [
        "MSE(ss)",
        "±se",
        "trace(ss)",
        "ANEES",
        "NEES med",
        "NEES<95%",
        "NEES<99%",
    ];
    header.extend(accuracy.map(String::from));
    if any_diverged {
        header.push("diverged".to_string());
    }
    if any_degenerate {
        header.push("degenerate".to_string());
    }
    if any_ess {
        header.push("ESS mean/min".to_string());
    }
    let traffic = [
        "rate",
        "tx/step",
        "bits/step",
        "frame bits/step",
        "downlink/step",
        "µJ/step",
        "R_eff",
    ];
    header.extend(traffic.map(String::from));
    // The rate-distortion floor at each row's R_eff, beside MSE(ss) in meaning.
    let any_floor = summary.schemes.iter().any(|s| s.floor_mse.is_some());
    if any_floor {
        header.push("floor(ss)".to_string());
    }
    // Sent messages the link lost (they are in tx/step and the bits: they were sent).
    let any_link = summary.schemes.iter().any(|s| s.link.is_some());
    if any_link {
        header.push("lost/step".to_string());
    }
    let mut rows = vec![header];
    for s in &summary.schemes {
        let mut r = vec![s.name.clone(), params_text(&s.params)];
        r.extend(groups.iter().map(|g| num(s.mean_rmse[*g], 4)));
        r.push(num(s.steady_state.mse, 4));
        // One trial has no standard error (NaN): a dash, not "overflow".
        r.push(if summary.trials == 1 && s.steady_state.mse_se.is_nan() {
            "-".to_string()
        } else {
            num(s.steady_state.mse_se, 4)
        });
        r.push(num(s.steady_state.trace, 4));
        r.push(format!(
            "{}{}",
            num(s.anees, 3),
            if s.consistency.mean_dominated {
                "*"
            } else {
                ""
            }
        ));
        r.push(num(s.consistency.median_nees, 3));
        r.push(format!("{:.3}", s.nees_coverage_95));
        r.push(format!("{:.3}", s.nees_coverage_99));
        if any_diverged {
            r.push(format!("{:.3}", s.diverged_fraction));
        }
        if any_degenerate {
            r.push(format!("{:.3}", s.degenerate_covariance_fraction));
        }
        if any_ess {
            r.push(match &s.ess {
                Some(e) => format!("{:.1}/{:.1}", e.mean, e.min),
                None => "-".to_string(),
            });
        }
        r.push(format!("{:.3}", s.rate));
        r.push(format!("{:.2}", s.transmissions_per_step));
        r.push(format!("{:.0}", s.bits_per_step));
        r.push(format!("{:.0}", s.frame_bits_per_step));
        r.push(format!("{:.0}", s.downlink_bits_per_step));
        r.push(format!("{:.1}", s.energy.energy_per_step_uj));
        r.push(format!("{:.1}", s.r_eff_per_step));
        if any_floor {
            r.push(s.floor_mse.map_or("-".into(), |f| num(f, 4)));
        }
        if any_link {
            r.push(
                s.link
                    .as_ref()
                    .map_or("-".into(), |l| format!("{:.2}", l.lost)),
            );
        }
        if s.failed.is_some() {
            super::failed::blank_row(&mut r);
        }
        rows.push(r);
    }
    let mut out = text_table(&rows, 2);
    for line in failed(summary) {
        let _ = writeln!(out, "failed: {line}");
    }
    if let Some(s) = summary.schemes.first() {
        let c = &s.consistency;
        let _ = writeln!(
            out,
            "NEES med: median NEES / n (consistent: {:.3}); NEES<95%/<99%: share of steps below the chi-square quantile (consistent: 0.95/0.99); a consistent filter's per-step ANEES lies in [{:.3}, {:.3}] at {} trials.",
            c.median_nees_expected, c.anees_interval_95[0], c.anees_interval_95[1], summary.trials
        );
    }
    if let Some(b) = &summary.pcrb {
        let _ = writeln!(
            out,
            "{}.",
            crate::metrics::pcrb::line(b, &summary.group_order)
        );
    }
    out.push_str(&warning_block(summary));
    out
}

/// The [`warnings`] as the terminal prints them under a table: a blank line, then one
/// `warning: ...` line each; empty when every scheme is healthy. Shared by a plain run's table
/// and each budget of `--budget`/`--budgets`, so both say the same thing in the same words.
pub fn warning_block(summary: &Summary) -> String {
    let w = warnings(summary);
    let mut out = String::new();
    if !w.is_empty() {
        out.push('\n');
        for line in w {
            let _ = writeln!(out, "warning: {line}");
        }
    }
    out
}

/// One line per scheme whose health needs attention: diverged trials, degenerate covariances,
/// a mean ANEES dominated by a few trials, an overflow. Each names the scheme and what to
/// change.
pub fn warnings(summary: &Summary) -> Vec<String> {
    let mut out = Vec::new();
    // A failed variant's numbers are not reported: its failure is said under the table.
    for s in summary.schemes.iter().filter(|s| s.failed.is_none()) {
        let who = if s.params.is_empty() {
            s.name.clone()
        } else {
            format!("{} ({})", s.name, params_text(&s.params))
        };
        let ess = s.ess.as_ref().map(|e| {
            format!(
                " (ESS mean {:.1}, min {:.1}): use more particles, or resample on an ESS rule (ess_threshold)",
                e.mean, e.min
            )
        });
        if s.diverged_fraction > 0.0 {
            out.push(format!(
                "{who}: {:.1}% of trials diverged (NEES above the chi-square 99.9% quantile for {} consecutive steps, or not finite){}",
                100.0 * s.diverged_fraction,
                crate::metrics::DIVERGENCE_RUN,
                ess.clone().unwrap_or_else(|| ": check its noise parameters and thresholds; its error bars claim more certainty than it has".to_string())
            ));
        }
        if s.degenerate_covariance_fraction > 0.0 {
            out.push(format!(
                "{who}: fused covariance singular at {:.2}% of (trial, step) pairs (a collapsed particle cloud){}",
                100.0 * s.degenerate_covariance_fraction,
                ess.clone().unwrap_or_default()
            ));
        }
        if s.consistency.mean_dominated {
            out.push(format!(
                "{who}: mean ANEES {} is dominated by a few trials (the largest 1% carry {:.0}% of it); read the median NEES ({}) and the coverage instead",
                num(s.anees, 3),
                100.0 * s.consistency.top_trials_share,
                num(s.consistency.median_nees, 3)
            ));
        }
        let se_ok = s.steady_state.mse_se.is_finite()
            || (summary.trials == 1 && s.steady_state.mse_se.is_nan());
        if !(s.steady_state.mse.is_finite() && se_ok && s.anees.is_finite()) {
            out.push(format!(
                "{who}: overflow (MSE, its standard error or ANEES is not finite): rescale the scenario's units"
            ));
        }
    }
    out.extend(summary.warnings.iter().cloned());
    out
}

/// A point of a curve against the communication rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvePoint {
    pub rate: f64,
    pub mse: f64,
    pub mse_se: f64,
    pub trace: f64,
    /// Index into `summary.schemes`.
    pub variant: usize,
}

/// The steady-state points of curve `curve`, sorted by rate; with a frontier, only the best
/// variant per rate bin.
pub fn curve_points(exp: &Experiment, summary: &Summary, curve: usize) -> Vec<CurvePoint> {
    let mut pts: Vec<CurvePoint> = summary
        .schemes
        .iter()
        .enumerate()
        .filter(|(_, s)| s.curve == curve)
        .map(|(i, s)| CurvePoint {
            rate: s.steady_state.rate,
            mse: s.steady_state.mse,
            mse_se: s.steady_state.mse_se,
            trace: s.steady_state.trace,
            variant: i,
        })
        .collect();
    if let Some(f) = &exp.curves[curve].frontier {
        let mut best: BTreeMap<i64, CurvePoint> = BTreeMap::new();
        for p in pts {
            let bin = (p.rate / f.bin_width).floor() as i64;
            let key = |q: &CurvePoint| match f.metric {
                crate::scenario::FrontierMetric::Mse => q.mse,
                crate::scenario::FrontierMetric::Trace => q.trace,
            };
            match best.get(&bin) {
                Some(b) if key(b) <= key(&p) => {}
                _ => {
                    best.insert(bin, p);
                }
            }
        }
        pts = best.into_values().collect();
    }
    pts.sort_by(|a, b| a.rate.total_cmp(&b.rate));
    pts
}

/// Rows as an aligned text table: the first `left` columns left-aligned, the others
/// right-aligned, a rule under the header row.
pub fn text_table(rows: &[Vec<String>], left: usize) -> String {
    let Some(first) = rows.first() else {
        return String::new();
    };
    let widths: Vec<usize> = (0..first.len())
        .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
        .collect();
    let mut out = String::new();
    for (i, r) in rows.iter().enumerate() {
        let line: Vec<String> = r
            .iter()
            .enumerate()
            .map(|(c, cell)| {
                if c < left {
                    format!("{cell:<w$}", w = widths[c])
                } else {
                    format!("{cell:>w$}", w = widths[c])
                }
            })
            .collect();
        out.push_str(line.join("  ").trim_end());
        out.push('\n');
        if i == 0 {
            out.push_str(&"-".repeat(widths.iter().sum::<usize>() + 2 * (widths.len() - 1)));
            out.push('\n');
        }
    }
    out
}

/// One line per variant whose trial failed: `scheme (params): trial t, step k: message` (the
/// first failure, by trial). A run with one fails (exit 1) after writing its results.
pub fn failed(summary: &Summary) -> Vec<String> {
    summary
        .schemes
        .iter()
        .filter_map(|s| {
            let f = s.failed.as_ref()?;
            let who = if s.params.is_empty() {
                s.name.clone()
            } else {
                format!("{} ({})", s.name, params_text(&s.params))
            };
            Some(format!(
                "{who}: trial {}, step {}: {}",
                f.trial, f.step, f.message
            ))
        })
        .collect()
}

#[cfg(test)]
#[path = "results_tests.rs"]
mod tests;
