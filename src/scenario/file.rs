//! Scenario files as written by users: serde structs that mirror the TOML. Serde rejects unknown
//! keys, wrong types, unknown names of choices and lists of the wrong length; [`crate::scenario::build`]
//! checks the rest (ranges, dimensions, consistency) and turns them into runtime objects that
//! cannot be wrong. Documented field by field in `docs/scenarios.md`.
use serde::{Deserialize, Deserializer, Serialize};
use std::collections::BTreeMap;

/// A fixed-length list (`position = [x, y]`): serde's arrays would silently drop extra entries.
fn exact<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    let v: Vec<T> = Vec::deserialize(d)?;
    let len = v.len();
    v.try_into().map_err(|_| {
        serde::de::Error::custom(format!("expected a list of exactly {N} entries, got {len}"))
    })
}

fn exact_opt<'de, D, T, const N: usize>(d: D) -> Result<Option<[T; N]>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    exact::<D, T, N>(d).map(Some)
}

/// A scheme parameter's value as written in a file.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(untagged)]
pub enum ParamValue {
    Number(f64),
    Flag(bool),
    Text(String),
}

impl ParamValue {
    /// Same value (numbers to 1e-12).
    pub fn matches(&self, other: &ParamValue) -> bool {
        match (self, other) {
            (ParamValue::Number(a), ParamValue::Number(b)) => (a - b).abs() < 1e-12,
            (a, b) => a == b,
        }
    }
}

impl std::fmt::Display for ParamValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ParamValue::Number(v) => {
                let s = format!("{v:.6}");
                write!(f, "{}", s.trim_end_matches('0').trim_end_matches('.'))
            }
            ParamValue::Flag(b) => write!(f, "{b}"),
            ParamValue::Text(t) => write!(f, "{t}"),
        }
    }
}

/// A scheme's parameters by name.
pub type Params = BTreeMap<String, ParamValue>;

/// A whole scenario file.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// Short name, used for the output folder.
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Monte Carlo trials.
    pub trials: usize,
    /// Time steps per trial (k = 1..=steps).
    pub steps: usize,
    /// Seed of every random stream of the run: an integer, or (above 2^63 - 1, which TOML
    /// integers cannot hold) a decimal string.
    #[serde(with = "seed_u64")]
    pub seed: u64,
    /// First step of the steady-state averages (default: steps / 2 + 1).
    #[serde(default)]
    pub steady_state_from: Option<usize>,
    pub model: ModelSpec,
    pub prior: PriorSpec,
    /// Distribution of the true x_0 when it differs from the filters' prior (e.g. a known
    /// start: `cov_diag = [0, 0]`). Default: the prior.
    #[serde(default)]
    pub initial_truth: Option<PriorSpec>,
    #[serde(default)]
    pub sensors: Vec<SensorSpec>,
    /// Many sensors of one kind placed at random or on a grid (appended after `sensors`).
    #[serde(default)]
    pub sensor_fields: Vec<SensorFieldSpec>,
    /// Named groups of state indices whose RMSE is reported, e.g. position = [0, 3].
    /// Kept in file order (the first group is the one plotted per step).
    #[serde(default)]
    pub groups: toml::Table,
    /// Schemes to compare; each a table with `kind`, its parameters, and optionally `label`,
    /// `sweep` and `frontier`. Kept as raw tables until each sweep point is expanded.
    #[serde(default)]
    pub schemes: Vec<toml::Table>,
    /// Run every scheme of the registry that applies to the system (the arenas); `schemes`
    /// then lists only the entries that differ from the registry's examples
    /// (`scenario::every_scheme`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub every_scheme: bool,
    /// The link between the sensors and the fusion center (default: ideal), for every sensor
    /// without a `channel` of its own (`scenario::channel`).
    #[serde(default)]
    pub channel: Option<crate::network::channel::ChannelSpec>,
    /// The network's graph: relays, a sink, links and routes (`network::topology`); absent:
    /// the one-hop star.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub network: Option<crate::network::topology::spec::NetworkSpec>,
    /// The sensors' radio and battery, for the energy in `summary.json` (default: the CC2420's
    /// datasheet values, [`crate::network::radio`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radio: Option<crate::network::radio::RadioSpec>,
    /// 802.15.4 MAC security of every frame (`link::security`): its auxiliary header and MIC
    /// are priced on every data and feedback frame, on a graph per hop and node; absent or
    /// `level = "none"`: unsecured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub security: Option<crate::link::security::SecuritySpec>,
    /// Published numbers and claims to check (`hushfuse reproduce`).
    #[serde(default)]
    pub paper: Option<PaperSpec>,
    /// How real numbers cross the network: `"f32"` (default: singles, 32 bits each) or
    /// `"f64"` (doubles, 64 bits each, for analyses that assume real-valued delivery).
    #[serde(default, skip_serializing_if = "crate::link::Reals::is_f32")]
    pub reals: crate::link::Reals,
}

/// Motion model: a preset or explicit matrices.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ModelSpec {
    /// State (x, vx), white-noise acceleration of intensity sigma2.
    /// `noise = "discrete"` uses the discrete white-noise acceleration
    /// Q = sigma2 [[D^4/4, D^3/2], [D^3/2, D^2]] (Zheng et al. (2014), Section VII) instead.
    #[serde(rename = "constant-velocity-1d")]
    ConstantVelocity1d {
        dt: f64,
        sigma2: f64,
        #[serde(default)]
        noise: NoiseForm,
    },
    /// State (x, vx, y, vy).
    #[serde(rename = "constant-velocity-2d")]
    ConstantVelocity2d {
        dt: f64,
        sigma2: f64,
        #[serde(default)]
        noise: NoiseForm,
    },
    /// State (x, vx, ax, y, vy, ay), white-noise jerk (Dormann et al., Section V).
    #[serde(rename = "near-constant-acceleration-2d")]
    NearConstantAcceleration2d { dt: f64, sigma2: f64 },
    /// 2-D rotation by omega * dt per step, noise q I.
    RotationOscillator { omega: f64, dt: f64, q: f64 },
    /// Any F and Q.
    Matrix {
        #[serde(rename = "F")]
        f: Vec<Vec<f64>>,
        #[serde(rename = "Q")]
        q: Vec<Vec<f64>>,
    },
}

/// How white-noise acceleration enters a constant-velocity model.
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseForm {
    /// Continuous white-noise acceleration, Q = sigma2 [[D^3/3, D^2/2], [D^2/2, D]].
    #[default]
    Continuous,
    /// Discrete white-noise acceleration, Q = sigma2 [[D^4/4, D^3/2], [D^3/2, D^2]].
    Discrete,
}

/// Kinds of sensor.
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum SensorKind {
    /// z = H x + v.
    #[default]
    Linear,
    /// Distance to the sensor (Zhang et al. (2016), eq. (17)).
    Range,
    /// Received signal strength (Zheng et al. (2014), Section VII-C).
    Rss,
}

/// Kinds of placed sensor in a field.
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum PlacedKind {
    Range,
    Rss,
}

/// How a field's sensors are placed.
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Layout {
    /// Uniform over the area, from the field's own seed.
    Random,
    /// Cell centres of an nx x ny grid.
    Grid,
}

/// Prior of x_0: the truth is drawn from it and every filter starts from it.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PriorSpec {
    pub mean: Vec<f64>,
    /// Full covariance (give this or `cov_diag`).
    #[serde(default)]
    pub cov: Option<Vec<Vec<f64>>>,
    /// Diagonal covariance.
    #[serde(default)]
    pub cov_diag: Option<Vec<f64>>,
}

/// One sensor.
#[derive(Debug, Clone, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    #[serde(default)]
    pub name: Option<String>,
    /// `linear` (default), `range` (Zhang et al. (2016), eq. (17)) or `rss` (Zheng et al. (2014), Section VII-C).
    #[serde(default)]
    pub kind: SensorKind,
    /// Sensor position (x, y), for `range` and `rss`.
    #[serde(default, deserialize_with = "exact_opt")]
    pub position: Option<[f64; 2]>,
    /// State indices of the target's (x, y), for `range` and `rss`.
    #[serde(default, deserialize_with = "exact_opt")]
    pub position_indices: Option<[usize; 2]>,
    /// RSS signal power P0.
    #[serde(default)]
    pub p0: Option<f64>,
    /// RSS path-loss coefficient alpha.
    #[serde(default)]
    pub path_loss_alpha: Option<f64>,
    /// RSS path-loss exponent n.
    #[serde(default)]
    pub path_loss_exponent: Option<f64>,
    /// Measurement matrix (give this or `observe`).
    #[serde(default, rename = "H")]
    pub h: Option<Vec<Vec<f64>>>,
    /// Shorthand for H: the state indices the sensor measures directly.
    #[serde(default)]
    pub observe: Option<Vec<usize>>,
    /// Measurement noise covariance (give this or `R_diag`).
    #[serde(default, rename = "R")]
    pub r: Option<Vec<Vec<f64>>>,
    #[serde(default, rename = "R_diag")]
    pub r_diag: Option<Vec<f64>>,
    /// This sensor's link, replacing the scenario's `[channel]` as a whole.
    #[serde(default)]
    pub channel: Option<crate::network::channel::ChannelSpec>,
}

/// A field of placed sensors of one kind.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SensorFieldSpec {
    /// `range` or `rss`.
    pub kind: PlacedKind,
    /// `random` (uniform over `area`, drawn from `seed`) or `grid` (cell centres of an
    /// nx x ny grid over `area`).
    pub layout: Layout,
    /// [x_min, x_max, y_min, y_max].
    #[serde(deserialize_with = "exact")]
    pub area: [f64; 4],
    /// Number of sensors (random layout).
    #[serde(default)]
    pub count: Option<usize>,
    /// Seed of the placement (random layout); independent of the scenario seed, so the
    /// network stays the same across runs with other seeds.
    #[serde(default)]
    pub seed: Option<u64>,
    /// [nx, ny] (grid layout).
    #[serde(default, deserialize_with = "exact_opt")]
    pub grid: Option<[usize; 2]>,
    #[serde(deserialize_with = "exact")]
    pub position_indices: [usize; 2],
    /// Measurement noise variance of every sensor.
    pub r: f64,
    #[serde(default)]
    pub p0: Option<f64>,
    #[serde(default)]
    pub path_loss_alpha: Option<f64>,
    #[serde(default)]
    pub path_loss_exponent: Option<f64>,
}

/// Keep only the best variant of a swept scheme per communication-rate bin (Dormann et al., Fig. 1
/// shows, for Algorithm 2, the smallest error covariance per rate).
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FrontierSpec {
    /// `trace` or `mse` (steady state).
    pub metric: FrontierMetric,
    /// Width of a rate bin.
    pub bin_width: f64,
}

/// What a frontier keeps the best of.
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum FrontierMetric {
    Trace,
    Mse,
}

/// Published results and claims.
#[derive(Debug, Clone, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct PaperSpec {
    /// Full reference of the paper and the figure/table.
    pub citation: String,
    /// Choices the paper leaves open and how we made them.
    #[serde(default)]
    pub notes: Vec<String>,
    /// Monte Carlo trials the paper ran; `hushfuse reproduce` warns when run with fewer.
    #[serde(default)]
    pub trials: Option<usize>,
    /// Numbers printed in the paper.
    #[serde(default)]
    pub published: Vec<PublishedValue>,
    /// Claims the paper makes that we check.
    #[serde(default)]
    pub claims: Vec<ClaimSpec>,
}

/// One number printed in the paper.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PublishedValue {
    /// Curve label of the scheme.
    pub scheme: String,
    /// Parameters identifying the variant (empty for unswept schemes).
    #[serde(default)]
    pub params: Params,
    /// `mse`, `trace`, `rate`, `rmse:<group>`, `transmissions_per_step`.
    pub metric: String,
    pub value: f64,
    /// Where in the paper, e.g. "Table I".
    pub source: String,
    /// Relative tolerance of the verdict for a metric we have no standard error for
    /// (`rmse:<group>`); default 0.05 (ours). Metrics with a standard error agree when within
    /// 2 standard errors.
    #[serde(default)]
    pub tolerance: Option<f64>,
}

/// A claim of the paper, checked on our numbers.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ClaimSpec {
    /// Curve `a`'s steady-state metric is below curve `b`'s at every rate of `a` inside
    /// `rate_range` (b interpolated linearly in the rate).
    Below {
        text: String,
        a: String,
        b: String,
        metric: String,
        #[serde(deserialize_with = "exact")]
        rate_range: [f64; 2],
    },
    /// Some variant of `scheme` communicates at a rate below `rate`.
    ReachesRateBelow {
        text: String,
        scheme: String,
        rate: f64,
    },
    /// Steady-state MSE <= trace (within 3 Monte Carlo standard errors) for every variant of
    /// the listed schemes.
    Consistent { text: String, schemes: Vec<String> },
    /// Scheme `a` has a smaller steady-state `metric` (`mse` or `mse:<group>`) than `b`, by a
    /// paired difference on the same trials at least 2 standard errors below zero.
    Better {
        text: String,
        a: String,
        #[serde(default)]
        a_params: Params,
        b: String,
        #[serde(default)]
        b_params: Params,
        metric: String,
    },
    /// For every sweep value v of `param` shared by curves `a` and `b`, `a`'s `metric`
    /// (`transmissions_per_step` or `rate`) is closer to the target v than `b`'s (Zheng et al. (2014)
    /// Tables I-III: CFwMD2's transmissions are closer to l than CFwMD's).
    CloserToTarget {
        text: String,
        a: String,
        b: String,
        param: String,
        metric: String,
    },
    /// The steady-state `metric` of `a` is within the relative tolerance `within` of `b`'s.
    Close {
        text: String,
        a: String,
        #[serde(default)]
        a_params: Params,
        b: String,
        #[serde(default)]
        b_params: Params,
        metric: String,
        within: f64,
        /// Where `within` comes from: `"paper: '<quote>'"` or `"ours"` (the default).
        #[serde(default = "ours")]
        tolerance_source: String,
    },
    /// Kalman filtering with intermittent observations (Sinopoli et al. 2004; Gilbert–Elliott
    /// bursts: Huang and Dey 2007) on a scalar system, checked at every variant of curve
    /// `scheme` (the all-data Kalman filter, each variant with its own link) against an
    /// independent computation: the data-free variance recursion over arrival sequences drawn
    /// by the claim checker from its own generator (`crate::scenario::intermittent`).
    Intermittent {
        text: String,
        scheme: String,
        check: IntermittentCheck,
        /// Relative resolution of the `trace-recursion`, `mse-recursion` and `bounds` checks: a
        /// point holds only when the Monte Carlo noise could have seen a difference this large
        /// (default 0.05, ours).
        #[serde(default)]
        within: Option<f64>,
        /// Arrival sequences of the independent computation (default 20000).
        #[serde(default)]
        sequences: Option<usize>,
        /// Only the variants whose γ (Bernoulli) or p_bg (Gilbert–Elliott) lies in [lo, hi].
        #[serde(default, deserialize_with = "exact_opt")]
        range: Option<[f64; 2]>,
    },
    /// The classic covariance-reduction factor of Kalman filtering with quantized
    /// innovations (Ribeiro, Giannakis and Roumeliotis 2006: 2/π for the sign; Msechu,
    /// Roumeliotis, Ribeiro and Giannakis 2008: c = 1 - D for an N-cell Lloyd–Max quantizer)
    /// on a scalar system, checked at every variant of curve `scheme` against the
    /// variance recursion P+ = P- - c P-² / (P- + r) computed independently by the claim
    /// checker (`crate::output::report::classic`).
    Inflation {
        text: String,
        scheme: String,
        check: InflationCheck,
        /// `efficiency`: the curve (one variant) whose steady-state MSE divides the scheme's.
        #[serde(default)]
        reference: Option<String>,
        /// Relative tolerance of the equivalence test (default 0.05, ours): a point holds when
        /// its relative difference from the recursion plus the Bonferroni quantile of standard
        /// errors is at most this, fails when the difference minus them exceeds it.
        #[serde(default)]
        within: Option<f64>,
    },
    /// Curve `a`'s network radio energy a step (a consensus scheme) is at least `at_least`
    /// times curve `b`'s (the all-data KF summed by the relays), each energy equal to the claim
    /// checker's independent count of frames, windows and sleep
    /// (`crate::output::report::energy_ratio`).
    EnergyRatio {
        text: String,
        a: String,
        b: String,
        at_least: f64,
    },
}

/// What an `inflation` claim checks.
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum InflationCheck {
    /// The steady-state `trace` equals the recursion with the quantizer's factor.
    TraceRecursion,
    /// The steady-state MSE (actual squared error) equals that recursion.
    MseRecursion,
    /// The ratio of the steady-state MSE to `reference`'s equals the ratio of their
    /// recursions (one sign bit against all data: π/2 for a static state, √(π/2) for a slow
    /// random walk).
    Efficiency,
}

/// What an `intermittent` claim checks.
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum IntermittentCheck {
    /// Where the mean is finite: the steady-state posterior variance (the filter's `trace`)
    /// between the posterior equivalents of Sinopoli's lower and upper bounds (Bernoulli only).
    Bounds,
    /// Where the mean is finite: the steady-state `trace` equals the independent recursion's
    /// expectation.
    TraceRecursion,
    /// Where the mean is finite: the steady-state MSE (actual squared error) equals the
    /// independent recursion's expectation (the filter is consistent under loss).
    MseRecursion,
    /// At and beyond the critical value: the expected error diverges, judged by the tail of
    /// the per-trial errors.
    Diverges,
}

fn ours() -> String {
    "ours".to_string()
}

/// A u64 in TOML: an integer where it fits in TOML's signed 64 bits, a decimal string
/// otherwise (`seed = "18446744073709551615"`), so every seed round-trips through a file.
mod seed_u64 {
    use serde::{de, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &u64, s: S) -> Result<S::Ok, S::Error> {
        match i64::try_from(*v) {
            Ok(i) => s.serialize_i64(i),
            Err(_) => s.serialize_str(&v.to_string()),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
        struct V;
        impl de::Visitor<'_> for V {
            type Value = u64;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a seed: an integer from 0 to 18446744073709551615 (as a string above 9223372036854775807)")
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<u64, E> {
                u64::try_from(v).map_err(|_| E::custom(format!("a seed must be >= 0, got {v}")))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<u64, E> {
                Ok(v)
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<u64, E> {
                v.trim().parse().map_err(|_| {
                    E::custom(format!(
                        "expected a seed from 0 to 18446744073709551615, got {v:?}"
                    ))
                })
            }
        }
        d.deserialize_any(V)
    }
}
