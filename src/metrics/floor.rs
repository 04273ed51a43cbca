//! What a run is held to, in bits: each scheme's entropy-coded rate `R_eff` and the
//! rate–distortion floor at that rate (the smallest steady-state MSE any causal scheme reaches
//! with `R_eff` bits per step, [`crate::stats::rate_distortion`]).
//!
//! **The rate.** A sensor that sends or stays silent tells the center one of two things every
//! step it is scheduled: the decision carries up to `h(p_i)` bits (`h` the binary entropy, `p_i`
//! its send probability while scheduled), and a message `b_i` bits more. So
//!
//! `R_eff = Σ_i [ s_i h(p_i) + p_i b_i ]` bits per step,
//!
//! with `s_i` the share of steps sensor i is scheduled (a round-robin slot that always sends
//! carries no decision: `h(1) = 0`; a step it is not scheduled, none). `Σ_i s_i p_i b_i` is the
//! payload per step, counted once per message (ARQ's repeated attempts carry nothing new).
//! `R_eff` is an upper bound on the information the scheme conveys (the symbols' entropy; their
//! correlation over time and across sensors would only lower it), so the floor at `R_eff` is a
//! valid lower bound on the scheme's error: a point below it is a defect.
//!
//! **The floor.** For linear sensors `z = H x + v` (all of them, stacked, `V` block diagonal):
//! the all-data Kalman filter's steady-state error plus the floor of its estimate process
//! (`floor_mse_noisy`); the scalar closed form for one state, the Tanaka et al. SDP otherwise.
//! Censored (Tobit) sensors see less than the linear sensor they censor, so the floor of the
//! uncensored sensor set holds for them too. Nonlinear sensors, a singular process noise or
//! an SDP without BLAS: no floor, and the reason is given.
use crate::linalg::Matrix;
use crate::metrics::sums::Sums;
use crate::scenario::build::Experiment;
use crate::stats::rate_distortion::{self as rd, scalar, FloorError};
use serde::{Deserialize, Serialize};

/// Binary entropy in bits; 0 at p = 0 and p = 1.
pub fn binary_entropy(p: f64) -> f64 {
    if p <= 0.0 || p >= 1.0 {
        return 0.0;
    }
    -(p * p.log2() + (1.0 - p) * (1.0 - p).log2())
}

/// The entropy-coded rate `R_eff` (bits per step) of one variant's sums over `trials` trials of
/// `steps` steps on `n_sensors` sensors, given its payload bits per step as counted
/// (`payload_per_step`, every attempt) and the messages and retransmissions of the whole run
/// (all trials).
///
/// Sensors beyond [`crate::network::MASKED_SENSORS`] have no per-sensor counts: their messages
/// are charged as if each of them were scheduled every step with their common average send
/// probability (by concavity of `h`, an upper bound of their decisions' entropy).
pub fn r_eff_per_step(
    sums: &Sums,
    n_sensors: usize,
    payload_per_step: f64,
    messages: f64,
    retransmissions: f64,
) -> f64 {
    let t = (sums.trials * sums.steps) as f64;
    if t == 0.0 {
        return 0.0;
    }
    let mut decisions = 0.0;
    let mut counted = 0.0;
    for &[scheduled, sent] in &sums.sensors {
        if scheduled > 0 {
            decisions += scheduled as f64 / t * binary_entropy(sent as f64 / scheduled as f64);
        }
        counted += sent as f64;
    }
    let rest = n_sensors.saturating_sub(crate::network::MASKED_SENSORS);
    if rest > 0 {
        let p = ((messages - counted) / (rest as f64 * t)).clamp(0.0, 1.0);
        decisions += rest as f64 * binary_entropy(p);
    }
    // Payload once per message: with ARQ every attempt was counted (all of a message's
    // attempts carry the same bits).
    let first_attempts = if retransmissions > 0.0 && messages > 0.0 {
        messages / (messages + retransmissions)
    } else {
        1.0
    };
    decisions + payload_per_step * first_attempts
}

/// [`r_eff_per_step`] of one variant's sums, from its per-trial means of payload bits and
/// messages summed over the steps (as `summarize_schemes` has them).
pub fn r_eff_of(exp: &Experiment, sums: &Sums, bits: f64, messages: f64) -> f64 {
    let trials = exp.trials as f64;
    // Frames beyond a message's first: the retransmissions (the link's counter 4,
    // `LINK_COUNTERS`); over a multi-hop network also every forward, all of them carrying the
    // message's payload again (every frame any node sent, less the messages).
    let repeats = if sums.nodes.is_empty() {
        sums.link.iter().map(|r| r[4] as f64).sum()
    } else {
        let frames: u64 = sums.nodes.iter().map(|c| c[0]).sum();
        (frames as f64 - messages * trials).max(0.0)
    };
    r_eff_per_step(
        sums,
        exp.system.n_sensors(),
        bits / exp.steps.max(1) as f64,
        messages * trials,
        repeats,
    )
}

/// The rate–distortion floor of `exp`'s system and its curve, or why there is none.
pub type ScenarioFloor = Result<
    (
        crate::metrics::floor::Floor,
        crate::metrics::floor::FloorCurve,
    ),
    String,
>;

/// [`ScenarioFloor`] of `exp` (a dozen small programs: computed once per run).
pub fn floor_of(exp: &Experiment) -> ScenarioFloor {
    Floor::of(exp).and_then(|f| f.curve().map(|c| (f, c)))
}

/// The floor of each of `rates` (bits per step): `None` without a scenario floor, or where the
/// rate is too low for a finite one. Independent programs, solved in parallel.
pub fn floors_at(floor: &ScenarioFloor, rates: &[f64]) -> Vec<Option<f64>> {
    use rayon::prelude::*;
    match floor {
        Ok((f, _)) => rates.par_iter().map(|r| f.mse_at(*r).ok()).collect(),
        Err(_) => vec![None; rates.len()],
    }
}

/// The floor as a curve, for `summary.json` (`rate_distortion_floor`) and the plots.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FloorCurve {
    /// Rates, bits per step.
    pub rate: Vec<f64>,
    /// The floor on the steady-state MSE (total over the state) at each rate.
    pub mse: Vec<f64>,
    /// The floor as the rate grows without end: the all-data Kalman filter's steady-state MSE.
    pub all_data_mse: f64,
    /// At or below this rate no scheme keeps the error bounded (`Σ max(0, log2|λ_i(F)|)`).
    pub min_rate: f64,
    /// How the floor was computed.
    pub method: String,
}

/// A scenario's floor: the pieces of `D(R) = trace(P_kf) + D_est(R)`.
#[derive(Debug, Clone)]
pub struct Floor {
    a: Matrix,
    /// Covariance of the Kalman estimate's driving term, `M − P_kf`.
    estimate_noise: Matrix,
    all_data_mse: f64,
    /// The rate from which [`Floor::mse_at`] gives the all-data error (see there).
    plateau: Option<f64>,
    /// The curve at [`CURVE_RATES`] above the minimum rate, where the program was solved.
    points: Vec<CurvePoint>,
    /// Why the first point of the curve that was not solved failed.
    curve_error: Option<FloorError>,
}

/// A solved point of the curve: the floor and its slope in the rate (MSE per bit per step).
#[derive(Debug, Clone, Copy)]
struct CurvePoint {
    rate: f64,
    mse: f64,
    slope: f64,
}

/// Largest relative gap between the curve's chord and its tangents at which [`Floor::mse_at`]
/// takes the tangents' bound instead of solving a program of its own: the floor it gives then
/// lies below the exact floor by at most this much (relative).
pub const TANGENT_GAP: f64 = 1e-3;

/// Relative excess of the floor over the all-data error below which [`Floor::mse_at`] gives the
/// all-data error.
pub const NEGLIGIBLE: f64 = 1e-6;

/// Bits per step above the minimum rate where [`Floor::of`] checks for the plateau.
const PLATEAU_RATE: f64 = 24.0;

/// Rates of the curve: the fine steps where the floor bends, then doublings.
const CURVE_RATES: [f64; 12] = [
    0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 24.0,
];

/// Why the floor's curve could not be solved, in words for the user: a solver's own message
/// (Clarabel's status) says nothing about what it means for the run.
fn note_of(e: &FloorError) -> String {
    match e {
        FloorError::Solver(raw) => format!(
            "the rate–distortion floor's semidefinite program (Tanaka et al.) could not be solved for this system, so no floor is given; the run's own numbers are unaffected (solver: {raw})"
        ),
        other => other.to_string(),
    }
}

impl Floor {
    /// The floor of `exp`'s system with every sensor, or why there is none.
    pub fn of(exp: &Experiment) -> Result<Self, String> {
        let sys = &exp.system;
        let n = sys.state_dim();
        let mut rows = 0;
        let mut linear = Vec::new();
        for (i, s) in sys.sensors.iter().enumerate() {
            let l = s
                .as_linear()
                .ok_or_else(|| format!("sensor {i} is not linear"))?;
            rows += l.h().nrows();
            linear.push((l.h(), s.noise_cov()));
        }
        if linear.is_empty() {
            return Err("no sensors".into());
        }
        let mut h = Matrix::zeros(rows, n);
        let mut v = Matrix::zeros(rows, rows);
        let mut r0 = 0;
        for (hi, ri) in &linear {
            let m = hi.nrows();
            h.view_mut((r0, 0), (m, n)).copy_from(*hi);
            v.view_mut((r0, r0), (m, m)).copy_from(*ri);
            r0 += m;
        }
        let a = sys.transition.f().clone();
        let kf =
            rd::kalman_steady_state(&a, sys.transition.q(), &h, &v).map_err(|e| e.to_string())?;
        Ok(Self::from_split(
            a,
            kf.estimate_noise(),
            kf.posterior.trace(),
        ))
    }

    /// The floor of the Kalman split: the estimate process `x̂' = A x̂ + e`, `e ~ N(0,
    /// estimate_noise)`, on top of the all-data error.
    fn from_split(a: Matrix, estimate_noise: Matrix, all_data_mse: f64) -> Self {
        let mut floor = Self {
            estimate_noise,
            all_data_mse,
            a,
            plateau: None,
            points: Vec::new(),
            curve_error: None,
        };
        floor.solve_curve();
        // The curve's last rate is PLATEAU_RATE above the minimum.
        floor.plateau = floor
            .points
            .last()
            .filter(|p| {
                (p.rate - floor.min_rate() - PLATEAU_RATE).abs() < 1e-12
                    && p.mse - floor.all_data_mse <= NEGLIGIBLE * floor.all_data_mse
            })
            .map(|p| p.rate);
        floor
    }

    /// Solves the program at every rate of [`CURVE_RATES`] (in parallel: independent
    /// programs), keeping the points that were solved in rate order.
    fn solve_curve(&mut self) {
        use rayon::prelude::*;
        let min = self.min_rate();
        let points: Vec<_> = CURVE_RATES
            .par_iter()
            .map(|r| (r + min, self.solve(r + min)))
            .collect();
        for (rate, d) in points {
            match d {
                Ok((mse, slope)) => self.points.push(CurvePoint { rate, mse, slope }),
                Err(e) => {
                    self.curve_error.get_or_insert(e);
                }
            }
        }
    }

    /// The floor at `rate` from the solved curve alone, when that is tight: the largest of the
    /// tangents at the solved points (the floor is convex in the rate, so each lies below it)
    /// and the all-data error, provided the chord of the two points around `rate` (which lies
    /// above the floor) is within [`TANGENT_GAP`] of it. Beyond the curve's last rate the
    /// floor lies between that point and the all-data error. `None` below the curve's first
    /// rate (the floor is steep there) or where the bound is looser.
    fn bound_from_curve(&self, rate: f64) -> Option<f64> {
        let first = self.points.first()?;
        let last = self.points.last()?;
        if rate < first.rate {
            return None;
        }
        let tangents = self
            .points
            .iter()
            .map(|p| p.mse + p.slope * (rate - p.rate))
            .fold(self.all_data_mse, f64::max);
        let above = match self.points.iter().position(|p| p.rate >= rate) {
            Some(0) => first.mse,
            Some(k) => {
                let (lo, hi) = (self.points[k - 1], self.points[k]);
                let t = (rate - lo.rate) / (hi.rate - lo.rate);
                lo.mse + t * (hi.mse - lo.mse)
            }
            None => last.mse,
        };
        (above - tangents <= TANGENT_GAP * tangents).then_some(tangents)
    }

    /// The smallest rate with a finite floor.
    pub fn min_rate(&self) -> f64 {
        if self.a.nrows() == 1 {
            scalar::min_rate(self.a[(0, 0)])
        } else {
            rd::min_rate(&self.a)
        }
    }

    /// The floor on the steady-state MSE at `rate` bits per step, or a lower bound of it
    /// within [`NEGLIGIBLE`] (relative) of it: from `Floor::plateau` bits per step on, where
    /// the estimate-process term has fallen below that, the all-data error itself (the floor
    /// decreases with the rate, so the all-data error bounds it from below everywhere, and
    /// there it is as tight as the solver; this spares one program per scheme).
    ///
    /// Errors: at or below [`Floor::min_rate`] (the floor is infinite) or when the program
    /// cannot be solved.
    pub fn mse_at(&self, rate: f64) -> Result<f64, FloorError> {
        if self.plateau.is_some_and(|p| rate >= p) {
            return Ok(self.all_data_mse);
        }
        if self.a.nrows() > 1 {
            if let Some(d) = self.bound_from_curve(rate) {
                return Ok(d);
            }
        }
        match self.solve(rate) {
            Ok((d, _)) => Ok(d),
            // Where the solver does not converge (very low rates on a marginally stable
            // system): the floor at the next rate of the curve that was solved, or the all-data
            // error; both lie below the floor at `rate`, which decreases with the rate.
            Err(FloorError::Solver(_)) => Ok(self
                .points
                .iter()
                .find(|p| p.rate >= rate)
                .map_or(self.all_data_mse, |p| p.mse)),
            Err(e) => Err(e),
        }
    }

    /// The floor at `rate` and its slope in the rate, from the program (or the closed form
    /// for one state, whose slope is `dD/dR = −2 ln 2 · 2^{2R} w / (2^{2R} − a²)²`).
    fn solve(&self, rate: f64) -> Result<(f64, f64), FloorError> {
        let (est, slope) = if self.a.nrows() == 1 {
            let (a, w) = (self.a[(0, 0)], self.estimate_noise[(0, 0)]);
            let d = scalar::distortion(a, w, rate)?;
            let g = 2f64.powf(2.0 * rate);
            (
                d,
                -2.0 * std::f64::consts::LN_2 * g * w / (g - a * a).powi(2),
            )
        } else {
            rd::floor_point(&self.a, &self.estimate_noise, rate)?
        };
        Ok((self.all_data_mse + est, slope))
    }

    /// The curve at `CURVE_RATES` above the minimum rate (points that could not be solved
    /// are left out); `Err` when no point could.
    pub fn curve(&self) -> Result<FloorCurve, String> {
        if self.points.is_empty() {
            return Err(self.curve_error.as_ref().map_or("no point".into(), note_of));
        }
        Ok(FloorCurve {
            rate: self.points.iter().map(|p| p.rate).collect(),
            mse: self.points.iter().map(|p| p.mse).collect(),
            all_data_mse: self.all_data_mse,
            min_rate: self.min_rate(),
            method: if self.a.nrows() == 1 {
                "closed form (Tatikonda, Sahai, Mitter), noisy sensors by the Kalman split".into()
            } else {
                "semidefinite program of Tanaka et al. (Clarabel), noisy sensors by the Kalman split"
                    .into()
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_solver_failure_reads_as_what_it_means() {
        let n = note_of(&FloorError::Solver("InsufficientProgress".into()));
        assert!(
            n.contains("could not be solved") && n.contains("unaffected"),
            "{n}"
        );
        assert!(n.ends_with("(solver: InsufficientProgress)"));
    }

    /// Between the curve's points `mse_at` may take the tangents' bound instead of a program:
    /// it must lie below the exact floor (up to the solver's accuracy) and within
    /// [`TANGENT_GAP`] of it, and the tangent path must be taken somewhere.
    #[test]
    #[cfg_attr(not(hushfuse_blas), ignore = "no BLAS/LAPACK in this build")]
    fn a_floor_read_from_the_curve_is_below_the_exact_floor_and_close() {
        let a = Matrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 0.9]);
        let w = Matrix::from_row_slice(2, 2, &[0.3, 0.05, 0.05, 0.2]);
        let floor = Floor::from_split(a, w, 0.7);
        assert_eq!(
            floor.points.len(),
            CURVE_RATES.len(),
            "{:?}",
            floor.curve_error
        );
        let mut from_curve = 0;
        for k in 0..200 {
            let rate = floor.min_rate() + 0.3 + 0.15 * k as f64;
            let got = floor.mse_at(rate).unwrap();
            let (exact, _) = floor.solve(rate).unwrap();
            assert!(got <= exact * (1.0 + 1e-7), "R={rate}: {got} above {exact}");
            assert!(
                got >= exact * (1.0 - TANGENT_GAP) - 1e-12,
                "R={rate}: {got} too far below {exact}"
            );
            from_curve += usize::from(floor.bound_from_curve(rate).is_some());
        }
        assert!(
            from_curve > 10,
            "the tangent bound was used {from_curve} times"
        );
    }

    /// The closed form's slope is the derivative of the closed form.
    #[test]
    fn the_scalar_slope_is_the_derivative() {
        let floor = Floor::from_split(
            Matrix::from_element(1, 1, 1.3),
            Matrix::from_element(1, 1, 0.4),
            0.2,
        );
        for rate in [0.5, 1.0, 3.0] {
            let (_, slope) = floor.solve(rate).unwrap();
            let h = 1e-5;
            let fd =
                (floor.solve(rate + h).unwrap().0 - floor.solve(rate - h).unwrap().0) / (2.0 * h);
            assert!(
                (slope - fd).abs() < 1e-6 * fd.abs(),
                "R={rate}: {slope} vs {fd}"
            );
        }
    }

    #[test]
    fn binary_entropy_by_hand() {
        assert_eq!(binary_entropy(0.0), 0.0);
        assert_eq!(binary_entropy(1.0), 0.0);
        assert!((binary_entropy(0.5) - 1.0).abs() < 1e-15);
        // h(1/4) = 2 - (3/4) log2 3
        assert!((binary_entropy(0.25) - (2.0 - 0.75 * 3f64.log2())).abs() < 1e-15);
    }

    fn sums(sensors: Vec<[u64; 2]>, trials: usize, steps: usize) -> Sums {
        let mut s = Sums::new(1, steps, 1);
        s.trials = trials;
        s.sensors = sensors;
        s
    }

    #[test]
    fn r_eff_is_the_payload_when_every_sensor_always_sends() {
        let s = sums(vec![[200, 200], [200, 200], [200, 200]], 2, 100);
        assert_eq!(r_eff_per_step(&s, 3, 96.0, 600.0, 0.0), 96.0);
    }

    #[test]
    fn r_eff_by_hand() {
        // Sensor 0 scheduled every step, sends at half of them: h(1/2) = 1 bit a step.
        // Sensor 1 scheduled at a quarter of the steps (round robin of 4), always sends: 0.
        // Sensor 2 scheduled every step, sends a quarter: h(1/4).
        let s = sums(vec![[400, 200], [100, 100], [400, 100]], 4, 100);
        let payload = 16.0 * (200.0 + 100.0 + 100.0) / 400.0;
        let want = 1.0 + binary_entropy(0.25) + payload;
        let got = r_eff_per_step(&s, 3, payload, 400.0, 0.0);
        assert!((got - want).abs() < 1e-12, "{got} vs {want}");
        // ARQ: with one retransmission per message the payload counted twice is halved.
        let got = r_eff_per_step(&s, 3, 2.0 * payload, 400.0, 400.0);
        assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    }
}
