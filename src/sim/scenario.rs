//! Scenario files as written by users: plain serde structs that mirror the TOML, with no
//! validation. [`super::build`] turns them into runtime objects that cannot be wrong.
//! Documented field by field in `docs/scenarios.md`.
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

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
    /// Seed of every random stream of the run.
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
    pub schemes: Vec<toml::Table>,
    /// Published numbers and claims to check (`hushfuse reproduce`).
    #[serde(default)]
    pub paper: Option<PaperSpec>,
}

/// Motion model: a preset or explicit matrices.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ModelSpec {
    /// State (x, vx), white-noise acceleration of intensity sigma2.
    /// `noise = "discrete"` uses the discrete white-noise acceleration
    /// Q = sigma2 [[D^4/4, D^3/2], [D^3/2, D^2]] (seed 000 Section VII) instead.
    #[serde(rename = "constant-velocity-1d")]
    ConstantVelocity1d {
        dt: f64,
        sigma2: f64,
        #[serde(default)]
        noise: Option<String>,
    },
    /// State (x, vx, y, vy).
    #[serde(rename = "constant-velocity-2d")]
    ConstantVelocity2d {
        dt: f64,
        sigma2: f64,
        #[serde(default)]
        noise: Option<String>,
    },
    /// State (x, vx, ax, y, vy, ay), white-noise jerk (seed 004 Section V).
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
    /// `linear` (default), `range` (seed 003 eq. (17)) or `rss` (seed 000 Section VII-C).
    #[serde(default)]
    pub kind: Option<String>,
    /// Sensor position (x, y), for `range` and `rss`.
    #[serde(default)]
    pub position: Option<[f64; 2]>,
    /// State indices of the target's (x, y), for `range` and `rss`.
    #[serde(default)]
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
}

/// A field of placed sensors of one kind.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SensorFieldSpec {
    /// `range` or `rss`.
    pub kind: String,
    /// `random` (uniform over `area`, drawn from `seed`) or `grid` (cell centres of an
    /// nx x ny grid over `area`).
    pub layout: String,
    /// [x_min, x_max, y_min, y_max].
    pub area: [f64; 4],
    /// Number of sensors (random layout).
    #[serde(default)]
    pub count: Option<usize>,
    /// Seed of the placement (random layout); independent of the scenario seed, so the
    /// network stays the same across runs with other seeds.
    #[serde(default)]
    pub seed: Option<u64>,
    /// [nx, ny] (grid layout).
    #[serde(default)]
    pub grid: Option<[usize; 2]>,
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

/// Parameters of one scheme at one sweep point.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum SchemeParams {
    /// Centralized KF with every measurement: the bound.
    CentralizedKf,
    /// Centralized KF; each measurement is sent with probability `rate`, else lost.
    CentralizedKfRandom { rate: f64 },
    /// Globalized distributed KF at full rate (seed 004 Section II).
    Dkf,
    /// Algorithm 1 with random communication at average rate `rate` in [0.5, 1].
    DkfAlg1Random { rate: f64 },
    /// Algorithm 1 with the event test (12).
    DkfAlg1Event { alpha: f64 },
    /// Algorithm 2 with test (13): threshold alpha and bound B = b I (or the matrix `B`).
    DkfAlg2Event {
        alpha: f64,
        #[serde(default)]
        b: Option<f64>,
        #[serde(default, rename = "B")]
        b_matrix: Option<Vec<Vec<f64>>>,
    },
    /// Seed 000: censoring sensors and a particle-filter fusion center.
    CensoredPf {
        /// `nis` (censoring, eq. (4)/(31)), `kl` (eq. (24)), `random` (send with probability
        /// l/N), `all`.
        #[serde(default)]
        policy: Option<String>,
        /// Target average number of sensors sending per step (not for `all`).
        #[serde(default)]
        l: Option<f64>,
        /// `none`, `prediction` (CFwMD), `prediction-covariance` (CFwMD2). Default `prediction`.
        #[serde(default)]
        feedback: Option<String>,
        /// `full` (CFwMD), `simple` (CFoMD) or `exact` (CFwMD-exact, no feedback). Default
        /// `full` for censoring, `simple` otherwise.
        #[serde(default)]
        fusion: Option<String>,
        #[serde(default)]
        particles: Option<usize>,
        /// `systematic` (default), `stratified`, `residual`, `multinomial`.
        #[serde(default)]
        resampling: Option<String>,
        /// Resample only when ESS < ess_threshold * particles (default: every step).
        #[serde(default)]
        ess_threshold: Option<f64>,
        /// Vector band probability: `exact` (default) or `monte-carlo` with `band_samples`.
        #[serde(default)]
        band: Option<String>,
        #[serde(default)]
        band_samples: Option<usize>,
        /// Monte Carlo draws of the Prop. 3 / 6 integral (default 200).
        #[serde(default)]
        prop3_samples: Option<usize>,
    },
    /// Seed 003: quantized innovations of activated sensors, fused in information form.
    /// `quantizer`: `zhang` (with `bits` 1-3 and `flag_zone`), `you` or `msechu` (with
    /// `bits`; msechu with 1 bit is SOI-KF's sign), `lloyd-max` (with `levels`), `analog`.
    QuantizedInnovation {
        quantizer: String,
        #[serde(default)]
        bits: Option<u8>,
        #[serde(default)]
        levels: Option<usize>,
        #[serde(default)]
        flag_zone: Option<bool>,
        /// Activate the `activate` sensors nearest to the predicted position (default: all).
        #[serde(default)]
        activate: Option<usize>,
    },
}

impl SchemeParams {
    /// The `kind` string as written in files.
    pub fn kind(&self) -> &'static str {
        match self {
            SchemeParams::CentralizedKf => "centralized-kf",
            SchemeParams::CentralizedKfRandom { .. } => "centralized-kf-random",
            SchemeParams::Dkf => "dkf",
            SchemeParams::DkfAlg1Random { .. } => "dkf-alg1-random",
            SchemeParams::DkfAlg1Event { .. } => "dkf-alg1-event",
            SchemeParams::DkfAlg2Event { .. } => "dkf-alg2-event",
            SchemeParams::QuantizedInnovation { .. } => "quantized-innovation",
            SchemeParams::CensoredPf { .. } => "censored-pf",
        }
    }

    /// Default curve label of a kind.
    pub fn default_label(&self) -> &'static str {
        match self {
            SchemeParams::CentralizedKf => "Centralized KF (all data)",
            SchemeParams::CentralizedKfRandom { .. } => "Centralized KF (random)",
            SchemeParams::Dkf => "Globalized DKF (full rate)",
            SchemeParams::DkfAlg1Random { .. } => "Algorithm 1 (random)",
            SchemeParams::DkfAlg1Event { .. } => "Algorithm 1 (event-based)",
            SchemeParams::DkfAlg2Event { .. } => "Algorithm 2 (event-based)",
            SchemeParams::QuantizedInnovation { .. } => "Quantized innovation",
            SchemeParams::CensoredPf { .. } => "Censored PF",
        }
    }
}

/// Keep only the best variant of a swept scheme per communication-rate bin (seed 004 Fig. 1
/// shows, for Algorithm 2, the smallest error covariance per rate).
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FrontierSpec {
    /// `trace` or `mse` (steady state).
    pub metric: String,
    /// Width of a rate bin.
    pub bin_width: f64,
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
    /// (`transmissions_per_step` or `rate`) is closer to the target v than `b`'s (seed 000
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
    },
}
