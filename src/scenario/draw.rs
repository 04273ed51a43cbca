//! The data of a scenario's trials: per trial, x_0 from the initial truth, then x_k and every
//! sensor's z_k^i, all from the trial's data stream ([`crate::stats::seeding::trial_rng`]). The
//! runner, the trace, the PCRB and the live driver draw here, so every one of them sees the same
//! numbers for the same (seed, trial).
use crate::linalg::quad::F64x4;
use crate::linalg::Vector;
use crate::metrics::precision::raise_peaks;
use crate::scenario::experiment::Experiment;
use crate::stats::normal_lanes::NormalLanes;
use crate::stats::seeding::{trial_rng, trial_seed};
use multiversion::multiversion;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Truth and measurements of one trial.
pub struct TrialData {
    /// x_1..x_T.
    pub truth: Vec<Vector>,
    /// z_k^i for k = 1..T, i = 1..N.
    pub measurements: Vec<Vec<Vector>>,
}

/// Draws x_0 from the prior, then x_k and every z_k^i, all from one stream.
pub fn draw_trial(exp: &Experiment, trial: usize) -> TrialData {
    let mut drawer = Drawer::new(exp);
    drawer.draw(exp, trial);
    drawer.data
}

/// Draws trials into buffers reused from trial to trial: the same numbers as drawing each
/// vector afresh (`F x + Q^{1/2} w`, `H x + R^{1/2} v`, the same gemv products and the same
/// order of normal draws), without allocating per step.
pub(crate) struct Drawer {
    /// The trial last drawn.
    pub(crate) data: TrialData,
    /// Per measurement component (sensors in order): the largest |reading| of the trial last
    /// drawn, as [`crate::metrics::precision::note_peaks`] finds it, kept while drawing
    /// rather than found by a second pass over every reading. Empty when the scenario sends
    /// doubles: only singles are checked for coarse rounding, so nothing reads it then.
    pub(crate) peaks: Vec<f64>,
    /// Per sensor: the index of its first component in `peaks`.
    offsets: Vec<usize>,
    /// Square root of the initial-truth covariance, once per run instead of once per trial.
    x0_sqrt: crate::linalg::Matrix,
    x: Vector,
    normals: Vector,
    a: Vector,
    b: Vector,
    /// Per sensor: its noise draw v and R^{1/2} v.
    v: Vec<Vector>,
    rv: Vec<Vector>,
    /// Per sensor, when it is linear: H and R^{1/2} (column-major), read per step without a
    /// virtual call.
    linear: Vec<Option<LinearDraw>>,
    /// When every sensor is linear and scalar: per sensor its row H and R^{1/2}, for the
    /// drawer's tight loop (empty otherwise).
    scalar: Vec<ScalarDraw>,
}

/// A linear scalar sensor as the tight loop reads it: H's one row (state dimensions up to 6)
/// and R^{1/2}.
#[derive(Clone, Copy)]
struct ScalarDraw {
    h: [f64; 6],
    r_sqrt: f64,
}

/// A linear sensor's matrices as the drawer reads them.
struct LinearDraw {
    h: Vec<f64>,
    r_sqrt: Vec<f64>,
}

impl Drawer {
    pub(crate) fn new(exp: &Experiment) -> Self {
        let sys = &exp.system;
        let n = sys.state_dim();
        let x0_sqrt = crate::model::transition::psd_sqrt(&exp.initial_truth.cov)
            .expect("validated initial truth");
        let zeros = |d: usize| Vector::zeros(d);
        let offsets: Vec<usize> = sys
            .sensors
            .iter()
            .scan(0, |c, s| {
                let first = *c;
                *c += s.meas_dim();
                Some(first)
            })
            .collect();
        let keep_peaks = exp.reals.is_f32();
        let width = sys.sensors.iter().map(|s| s.meas_dim()).sum();
        Self {
            peaks: vec![0.0; if keep_peaks { width } else { 0 }],
            offsets,
            data: TrialData {
                truth: (0..exp.steps).map(|_| zeros(n)).collect(),
                measurements: (0..exp.steps)
                    .map(|_| sys.sensors.iter().map(|s| zeros(s.meas_dim())).collect())
                    .collect(),
            },
            x0_sqrt,
            x: zeros(n),
            normals: zeros(n),
            a: zeros(n),
            b: zeros(n),
            v: sys.sensors.iter().map(|s| zeros(s.meas_dim())).collect(),
            rv: sys.sensors.iter().map(|s| zeros(s.meas_dim())).collect(),
            linear: sys
                .sensors
                .iter()
                .map(|s| {
                    s.as_linear().map(|l| LinearDraw {
                        h: l.h().as_slice().to_vec(),
                        r_sqrt: s.noise_sqrt().as_slice().to_vec(),
                    })
                })
                .collect(),
            scalar: scalar_plans(exp),
        }
    }

    pub(crate) fn draw(&mut self, exp: &Experiment, trial: usize) {
        // State dimensions 1..=6: the same operations on stack arrays.
        match exp.system.state_dim() {
            1 => draw_fixed::<1>(self, exp, trial),
            2 => draw_fixed::<2>(self, exp, trial),
            3 => draw_fixed::<3>(self, exp, trial),
            4 => draw_fixed::<4>(self, exp, trial),
            5 => draw_fixed::<5>(self, exp, trial),
            6 => draw_fixed::<6>(self, exp, trial),
            _ => self.draw_dynamic(exp, trial),
        }
    }

    fn draw_dynamic(&mut self, exp: &Experiment, trial: usize) {
        let sys = &exp.system;
        self.peaks.fill(0.0);
        let mut rng = trial_rng(exp.seed, trial as u64, 0);
        let normal = |rng: &mut Xoshiro256PlusPlus| -> f64 {
            rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, rng)
        };
        // x_0 = mean + S n_0.
        self.normals.iter_mut().for_each(|v| *v = normal(&mut rng));
        crate::linalg::fixed::gemv(&mut self.a, &self.x0_sqrt, &self.normals);
        self.x.copy_from(&exp.initial_truth.mean);
        self.x += &self.a;
        let t = &sys.transition;
        for k in 0..exp.steps {
            // x_k = F x_{k-1} + Q^{1/2} w (LinearTransition::sample_next).
            self.normals.iter_mut().for_each(|v| *v = normal(&mut rng));
            crate::linalg::fixed::gemv(&mut self.a, t.f(), &self.x);
            crate::linalg::fixed::gemv(&mut self.b, t.q_sqrt(), &self.normals);
            self.a += &self.b;
            std::mem::swap(&mut self.x, &mut self.a);
            for (i, (s, z)) in sys
                .sensors
                .iter()
                .zip(self.data.measurements[k].iter_mut())
                .enumerate()
            {
                match s.as_linear() {
                    // z = H x + R^{1/2} v (MeasurementModel::sample).
                    Some(lin) => {
                        let (v, rv) = (&mut self.v[i], &mut self.rv[i]);
                        v.iter_mut().for_each(|e| *e = normal(&mut rng));
                        crate::linalg::fixed::gemv(z, lin.h(), &self.x);
                        crate::linalg::fixed::gemv(rv, s.noise_sqrt(), v);
                        *z += &*rv;
                    }
                    None => *z = s.sample(&self.x, &mut rng),
                }
                if let Some(peaks) = self.peaks.get_mut(self.offsets[i]..) {
                    raise_peaks(peaks, z.as_slice());
                }
            }
            self.data.truth[k].copy_from(&self.x);
        }
    }
}

/// [`Drawer::scalar`]: every sensor linear and scalar, the state at most 6 wide; else empty.
fn scalar_plans(exp: &Experiment) -> Vec<ScalarDraw> {
    let sys = &exp.system;
    let n = sys.state_dim();
    let plans: Option<Vec<ScalarDraw>> = sys
        .sensors
        .iter()
        .map(|s| {
            let l = s.as_linear().filter(|_| s.meas_dim() == 1 && n <= 6)?;
            let mut h = [0.0; 6];
            h[..n].copy_from_slice(l.h().as_slice());
            Some(ScalarDraw {
                h,
                r_sqrt: s.noise_sqrt()[(0, 0)],
            })
        })
        .collect();
    plans.unwrap_or_default()
}

/// [`Drawer::draw_dynamic`] for state dimension N: the same normal draws in the same order
/// and the same products (`fixed`'s kernels repeat nalgebra's gemv), with the state on the
/// stack. Compiled also for AVX2 and picked at run time: the same IEEE operations (no FMA
/// contraction), so the same draws on every x86-64 machine.
#[multiversion(targets("x86_64+avx2"))]
fn draw_fixed<const N: usize>(d: &mut Drawer, exp: &Experiment, trial: usize) {
    use crate::linalg::fixed::{mat_vec, mat_vec_dyn, mat_vec_rows};
    let sys = &exp.system;
    let mut rng = trial_rng(exp.seed, trial as u64, 0);
    let normal = standard_normal;
    let normals = standard_normals::<N>;
    let arr = |v: &Vector| -> [f64; N] { v.as_slice().try_into().expect("state dimension") };
    // x_0 = mean + S n_0.
    let a: [f64; N] = mat_vec(d.x0_sqrt.as_slice(), &normals(&mut rng));
    let mean = arr(&exp.initial_truth.mean);
    let mut x: [f64; N] = std::array::from_fn(|i| mean[i] + a[i]);
    let t = &sys.transition;
    let (f, q_sqrt) = (t.f().as_slice(), t.q_sqrt().as_slice());
    d.peaks.fill(0.0);
    if !d.scalar.is_empty() {
        // Every sensor linear and scalar: the loop below without its per-sensor dispatch.
        let steps = d.data.measurements.iter_mut().zip(&mut d.data.truth);
        for (zs, truth) in steps.take(exp.steps) {
            let w = normals(&mut rng);
            let a: [f64; N] = mat_vec(f, &x);
            let b: [f64; N] = mat_vec(q_sqrt, &w);
            x = std::array::from_fn(|i| a[i] + b[i]);
            for (i, (plan, z)) in d.scalar.iter().zip(zs.iter_mut()).enumerate() {
                let v = normal(&mut rng);
                let hx: [f64; 1] = mat_vec(&plan.h[..N], &x);
                let zi = hx[0] + plan.r_sqrt * v;
                z.as_mut_slice()[0] = zi;
                if let Some(p) = d.peaks.get_mut(i) {
                    *p = p.max(zi.abs());
                }
            }
            truth.as_mut_slice().copy_from_slice(&x);
        }
        return;
    }
    let any_nonlinear = d.linear.iter().any(Option::is_none);
    for k in 0..exp.steps {
        // x_k = F x_{k-1} + Q^{1/2} w (LinearTransition::sample_next).
        let w = normals(&mut rng);
        let a: [f64; N] = mat_vec(f, &x);
        let b: [f64; N] = mat_vec(q_sqrt, &w);
        x = std::array::from_fn(|i| a[i] + b[i]);
        if any_nonlinear {
            d.x.as_mut_slice().copy_from_slice(&x);
        }
        let zs = &mut d.data.measurements[k];
        let sensors = d.linear.iter().zip(zs.iter_mut()).zip(&d.offsets);
        for (i, ((plan, zv), &first)) in sensors.enumerate() {
            let z = zv.as_mut_slice();
            match plan {
                // z = H x + R^{1/2} v (MeasurementModel::sample); a scalar measurement
                // without the loops (the same products and sum).
                Some(LinearDraw { h, r_sqrt }) if z.len() == 1 => {
                    let v = normal(&mut rng);
                    let hx: [f64; 1] = mat_vec(h, &x);
                    z[0] = hx[0] + r_sqrt[0] * v;
                    if let Some(p) = d.peaks.get_mut(first) {
                        *p = p.max(z[0].abs());
                    }
                    continue;
                }
                Some(LinearDraw { h, r_sqrt }) => {
                    let (v, rv) = (d.v[i].as_mut_slice(), d.rv[i].as_mut_slice());
                    v.iter_mut().for_each(|e| *e = normal(&mut rng));
                    mat_vec_rows::<N>(z, h, &x);
                    mat_vec_dyn(rv, r_sqrt, v);
                    for (z, r) in z.iter_mut().zip(rv.iter()) {
                        *z += r;
                    }
                }
                None => *zv = sys.sensors[i].sample(&d.x, &mut rng),
            }
            if let Some(peaks) = d.peaks.get_mut(first..) {
                raise_peaks(peaks, zv.as_slice());
            }
        }
        d.data.truth[k].as_mut_slice().copy_from_slice(&x);
    }
}

/// Four trials of a runner block drawn side by side, a step at a time, for a lockstep fast
/// path ([`crate::scheme::fast_path::QuadBlock`]): lane j of every entry is trial j's number,
/// the very number [`Drawer::draw`] gives that trial. Only for scenarios whose sensors are all
/// linear and scalar and whose state has at most 6 components ([`Drawer::draws_quads`]).
#[derive(Default)]
pub(crate) struct QuadData {
    /// State components.
    pub(crate) n: usize,
    /// Sensors (one reading each per step).
    pub(crate) sensors: usize,
    /// Steps drawn so far.
    pub(crate) drawn: usize,
    /// x_k's component c: `truth[(k - 1) * n + c]`.
    pub(crate) truth: Vec<F64x4>,
    /// z_k^i: `readings[(k - 1) * sensors + i]`.
    pub(crate) readings: Vec<F64x4>,
    /// Per sensor, the largest |reading| of the four trials so far ([`Drawer::peaks`]);
    /// empty when the scenario sends doubles.
    pub(crate) peaks: Vec<f64>,
    /// Every normal draw of the four trials, in each stream's order: x_0's n, then per step
    /// the state's n and one per sensor (drawn at the start, in one pass).
    noise: Vec<F64x4>,
    /// The four trials' states x_{drawn} (the first n entries), side by side.
    states: [F64x4; 6],
}

impl Drawer {
    /// Whether [`Drawer::start_quad`] takes this experiment's trials.
    pub(crate) fn draws_quads(&self, exp: &Experiment) -> bool {
        !self.scalar.is_empty() && (1..=6).contains(&exp.system.state_dim())
    }

    /// Starts trials `first..first + 4` in `quad` (lane j: trial `first + j`): each trial's
    /// stream and x_0; the steps are drawn by [`Drawer::draw_quad_step`]. False, with nothing
    /// started, when [`Drawer::draws_quads`] is false.
    pub(crate) fn start_quad(&self, exp: &Experiment, first: usize, quad: &mut QuadData) -> bool {
        if !self.draws_quads(exp) {
            return false;
        }
        let seeds = std::array::from_fn(|j| trial_seed(exp.seed, (first + j) as u64, 0));
        let Some(mut normals) = NormalLanes::seeded(seeds) else {
            return false;
        };
        let n = exp.system.state_dim();
        quad.n = n;
        quad.sensors = self.scalar.len();
        quad.drawn = 0;
        quad.noise
            .resize(n + exp.steps * (n + quad.sensors), F64x4::default());
        normals.fill(&mut quad.noise);
        quad.truth.resize(exp.steps * n, F64x4::default());
        quad.readings
            .resize(exp.steps * quad.sensors, F64x4::default());
        quad.peaks.clear();
        quad.peaks.resize(self.peaks.len(), 0.0);
        quad.states = match n {
            1 => quad_initial::<1>(self, exp, &quad.noise),
            2 => quad_initial::<2>(self, exp, &quad.noise),
            3 => quad_initial::<3>(self, exp, &quad.noise),
            4 => quad_initial::<4>(self, exp, &quad.noise),
            5 => quad_initial::<5>(self, exp, &quad.noise),
            _ => quad_initial::<6>(self, exp, &quad.noise),
        };
        true
    }

    /// Draws the next step of the four trials started by [`Drawer::start_quad`] (nothing once
    /// every step is drawn).
    pub(crate) fn draw_quad_step(&self, exp: &Experiment, quad: &mut QuadData) {
        if quad.drawn >= exp.steps
            || quad.noise.len() != quad.n + exp.steps * (quad.n + quad.sensors)
        {
            return;
        }
        match quad.n {
            1 => draw_quad_fixed::<1>(self, exp, quad),
            2 => draw_quad_fixed::<2>(self, exp, quad),
            3 => draw_quad_fixed::<3>(self, exp, quad),
            4 => draw_quad_fixed::<4>(self, exp, quad),
            5 => draw_quad_fixed::<5>(self, exp, quad),
            _ => draw_quad_fixed::<6>(self, exp, quad),
        }
        quad.drawn += 1;
    }
}

/// x_0 of the four trials side by side, as [`draw_fixed`] makes each: x_0 = mean + S n_0, n_0 the first N
/// draws of each stream (`noise`'s first N; in the first N of the 6 entries).
fn quad_initial<const N: usize>(d: &Drawer, exp: &Experiment, noise: &[F64x4]) -> [F64x4; 6] {
    let n0: &[F64x4; N] = noise[..N].try_into().expect("N draws");
    let a: [F64x4; N] = crate::linalg::fixed::mat_vec(d.x0_sqrt.as_slice(), n0);
    let mean = exp.initial_truth.mean.as_slice();
    std::array::from_fn(|c| {
        if c < N {
            F64x4::splat(mean[c]) + a[c]
        } else {
            F64x4::default()
        }
    })
}

/// [`Drawer::draw_quad_step`] for state dimension N: [`draw_fixed`]'s draws and products on
/// the four trials' lanes (each lane's draws from its own stream, in its order). Compiled also
/// for AVX2 and picked at run time (the same IEEE operations).
#[multiversion(targets("x86_64+avx2"))]
fn draw_quad_fixed<const N: usize>(d: &Drawer, exp: &Experiment, quad: &mut QuadData) {
    use crate::linalg::fixed::mat_vec;
    use crate::linalg::quad::Real;
    let (k, sensors) = (quad.drawn, quad.sensors);
    let t = &exp.system.transition;
    let (f, q_sqrt) = (t.f().as_slice(), t.q_sqrt().as_slice());
    let x: [F64x4; N] = std::array::from_fn(|c| quad.states[c]);
    // This step's draws: the state's N, then one per sensor.
    let first = N + k * (N + sensors);
    let noise = &quad.noise[first..first + N + sensors];
    let w: &[F64x4; N] = noise[..N].try_into().expect("N draws");
    let a: [F64x4; N] = mat_vec(f, &x);
    let b: [F64x4; N] = mat_vec(q_sqrt, w);
    let x: [F64x4; N] = std::array::from_fn(|c| a[c] + b[c]);
    for (i, (plan, &v)) in d.scalar.iter().zip(&noise[N..]).enumerate() {
        let hx: [F64x4; 1] = mat_vec(&plan.h[..N], &x);
        let z = hx[0] + F64x4::scaled(plan.r_sqrt, v);
        quad.readings[k * sensors + i] = z;
        if let Some(p) = quad.peaks.get_mut(i) {
            for zj in z.0 {
                *p = p.max(zj.abs());
            }
        }
    }
    quad.states[..N].copy_from_slice(&x);
    quad.truth[k * N..(k + 1) * N].copy_from_slice(&x);
}

/// N standard normal draws in order: a function, not a closure, so that it is inlined into
/// the drawer's AVX2 version too (a closure there stayed out of line, a call per step), and a
/// loop rather than `array::from_fn` (whose closure stayed out of line, a call per draw).
#[inline(always)]
fn standard_normals<const N: usize>(rng: &mut Xoshiro256PlusPlus) -> [f64; N] {
    let mut a = [0.0; N];
    for v in &mut a {
        *v = standard_normal(rng);
    }
    a
}

/// One standard normal draw, inlined into the drawer's loops (as a closure it stayed out of
/// line: a call per draw).
#[inline(always)]
fn standard_normal(rng: &mut Xoshiro256PlusPlus) -> f64 {
    rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, rng)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::build::load;
    use crate::scenario::builtin;

    /// A model of `n` states whose F mixes them, with three linear scalar sensors.
    fn scalar_only(n: usize) -> String {
        let f: Vec<String> = (0..n)
            .map(|i| {
                let row: Vec<String> = (0..n)
                    .map(|j| {
                        format!(
                            "{}",
                            if i == j {
                                0.9
                            } else {
                                0.1 / (1 + i + j) as f64
                            }
                        )
                    })
                    .collect();
                format!("[{}]", row.join(", "))
            })
            .collect();
        let mean = vec!["0.5"; n].join(", ");
        let var = vec!["2.0"; n].join(", ");
        let last = n - 1;
        format!(
                "name = \"t\"\ntrials = 3\nsteps = 9\nseed = 11\n[model]\nkind = \"matrix\"\nF = [{f}]\nQ = [{f}]\n[prior]\nmean = [{mean}]\ncov_diag = [{var}]\n[[sensors]]\nobserve = [0]\nR_diag = [4.0]\n[[sensors]]\nobserve = [{last}]\nR_diag = [0.25]\n[[sensors]]\nobserve = [0]\nR_diag = [1.0]\n[[schemes]]\nkind = \"centralized-kf\"\n",
                f = f.join(", ")
            )
    }

    /// A random walk of `n` states, a scalar sensor of the first state and a vector sensor of
    /// the first two, with readings of every sign.
    fn walk(n: usize) -> String {
        let rows: Vec<String> = (0..n)
            .map(|i| {
                let row: Vec<&str> = (0..n).map(|j| if i == j { "1.0" } else { "0.0" }).collect();
                format!("[{}]", row.join(", "))
            })
            .collect();
        let f = rows.join(", ");
        let zeros = vec!["0.0"; n].join(", ");
        let ones = vec!["1.0"; n].join(", ");
        format!(
            "name = \"t\"\ntrials = 3\nsteps = 7\nseed = 5\n[model]\nkind = \"matrix\"\nF = [{f}]\nQ = [{f}]\n[prior]\nmean = [{zeros}]\ncov_diag = [{ones}]\n[[sensors]]\nobserve = [0]\nR_diag = [4.0]\n[[sensors]]\nobserve = [0, 1]\nR_diag = [1.0, 9.0]\n[[schemes]]\nkind = \"centralized-kf\"\n"
        )
    }

    /// The peaks kept while drawing are the ones a pass over the readings finds, for linear
    /// sensors (scalar and vector) in the fixed-size drawer (2 states) and the dynamic one
    /// (8 states), and for the RSS sensors of a built-in; none are kept for a scenario that
    /// sends doubles (nothing reads them).
    #[test]
    fn peaks_kept_while_drawing_equal_a_pass_over_the_readings() {
        let (rss, _) = builtin::resolve("arena-rss", false).unwrap();
        for text in [walk(2), walk(8), rss] {
            let exp = load(&text, "t").unwrap();
            let mut drawer = Drawer::new(&exp);
            for trial in 0..3 {
                drawer.draw(&exp, trial);
                let mut expected = Vec::new();
                crate::metrics::precision::note_peaks(&drawer.data.measurements, &mut expected);
                assert_eq!(drawer.peaks, expected, "trial {trial}");
                assert!(drawer.peaks.iter().any(|&p| p > 0.0));
            }
        }
        let doubles = load(&format!("reals = \"f64\"\n{}", walk(2)), "t").unwrap();
        let mut drawer = Drawer::new(&doubles);
        drawer.draw(&doubles, 0);
        assert!(drawer.peaks.is_empty());
    }

    /// A block drawn side by side holds in lane j, step after step, the truth, readings of
    /// trial `first + j` as `Drawer::draw` draws that trial alone, and the peaks of the four;
    /// for every state dimension it takes, with readings of every sign, and nothing for a
    /// vector sensor or a state wider than 6.
    #[test]
    fn a_block_drawn_side_by_side_holds_each_trial_in_its_lane() {
        let mut texts: Vec<String> = (1..=6).map(scalar_only).collect();
        texts.push(format!("reals = \"f64\"\n{}", scalar_only(2)));
        for text in &texts {
            let exp = load(text, "t").unwrap();
            let n = exp.system.state_dim();
            let mut alone = Drawer::new(&exp);
            let quads = Drawer::new(&exp);
            let mut quad = QuadData::default();
            for first in [0, 5] {
                assert!(quads.start_quad(&exp, first, &mut quad));
                for _ in 0..exp.steps + 2 {
                    quads.draw_quad_step(&exp, &mut quad);
                }
                assert_eq!(quad.drawn, exp.steps);
                let mut peaks = vec![0.0; alone.peaks.len()];
                for j in 0..4 {
                    alone.draw(&exp, first + j);
                    for k in 0..exp.steps {
                        for c in 0..n {
                            let (got, want) = (quad.truth[k * n + c].0[j], alone.data.truth[k][c]);
                            assert_eq!(got.to_bits(), want.to_bits(), "trial {}", first + j);
                        }
                        for (i, z) in alone.data.measurements[k].iter().enumerate() {
                            let got = quad.readings[k * quad.sensors + i].0[j];
                            assert_eq!(got.to_bits(), z[0].to_bits(), "trial {}", first + j);
                        }
                    }
                    for (p, q) in peaks.iter_mut().zip(&alone.peaks) {
                        *p = f64::max(*p, *q);
                    }
                }
                assert_eq!(quad.peaks, peaks);
            }
        }
        for text in [walk(2), walk(8)] {
            let exp = load(&text, "t").unwrap();
            assert!(!Drawer::new(&exp).start_quad(&exp, 0, &mut QuadData::default()));
        }
    }

    /// The fixed-size drawer gives the dynamic drawer's numbers bit for bit: truth, readings
    /// and peaks, for every state dimension it takes, with only scalar linear sensors (its
    /// tight loop; a model whose F mixes the states and readings of every sign) and with a
    /// vector sensor among them (its general loop).
    #[test]
    fn the_fixed_size_drawer_draws_the_dynamic_drawers_numbers() {
        let bits = |d: &TrialData| -> Vec<u64> {
            let truth = d.truth.iter().flat_map(|v| v.iter().map(|x| x.to_bits()));
            let readings = d
                .measurements
                .iter()
                .flatten()
                .flat_map(|v| v.iter().map(|x| x.to_bits()));
            truth.chain(readings).collect()
        };
        let mut texts: Vec<String> = (1..=6).map(scalar_only).collect();
        texts.push(walk(2));
        for text in texts {
            let exp = load(&text, "t").unwrap();
            let mut fixed = Drawer::new(&exp);
            let mut dynamic = Drawer::new(&exp);
            for trial in 0..3 {
                fixed.draw(&exp, trial);
                dynamic.draw_dynamic(&exp, trial);
                assert_eq!(bits(&fixed.data), bits(&dynamic.data), "trial {trial}");
                assert_eq!(fixed.peaks, dynamic.peaks, "trial {trial}");
                assert!(fixed.peaks.iter().all(|&p| p > 0.0));
            }
        }
    }
}
