//! A trial's signals for the fast trial ([`super::fast`]): the sensors' variant-independent
//! terms, computed once from the measurements and shared by every variant of the plan.
use super::sensor::predict_in_place;
use super::DistributedKfScheme;
use crate::linalg::fixed;
use crate::linalg::Vector;

/// The variant-independent signals of one trial, per step k and sensor i (index
/// `(k - 1) * sensors + i`, each entry `n` long).
pub(super) struct Signals {
    pub(super) n: usize,
    pub(super) sensors: usize,
    /// x̄^{p,i}_k = A x̄^{e,i}_{k-1}.
    pub(super) xbar_p: Vec<f64>,
    /// What the center holds of a sensor that sent at k-1: A times x̄^{e,i}_{k-1} as it
    /// arrived ([`crate::link::as_sent`]; the common prior's mean, unrounded, for k = 1).
    pub(super) held_p: Vec<f64>,
    /// The standard local KF's prediction and estimate (Algorithm 2's test (13)).
    pub(super) kf_p: Vec<f64>,
    pub(super) kf: Vec<f64>,
    /// ||K^i_k (z^i_k - H^i x̂^{p,i}_k)||, the norm of test (12); one per (k, i).
    pub(super) correction_norm: Vec<f64>,
    /// x̄^{e,i}_k as it arrives ([`crate::link::as_sent`]): what the center keeps of the last
    /// one to arrive, for the loss fallback of [`super::loss`].
    pub(super) xbar_e: Vec<f64>,
    /// (C̄^e_k)^{-1} x̄^{e,i}_k: (11)'s term of an estimate that arrived.
    pub(super) info_sent: Vec<f64>,
    /// (C̄^p_k)^{-1} times `held_p`: (11)'s term of an estimate sent at k-1 and omitted at k.
    pub(super) info_omitted: Vec<f64>,
}

impl Signals {
    pub(super) fn at<'a>(&self, v: &'a [f64], k: usize, i: usize) -> &'a [f64] {
        let o = ((k - 1) * self.sensors + i) * self.n;
        &v[o..o + self.n]
    }

    /// x̄^{p,i}_k.
    pub fn xbar_p(&self, k: usize, i: usize) -> &[f64] {
        self.at(&self.xbar_p, k, i)
    }

    /// [`Signals::held_p`] of (k, i).
    pub fn held_p(&self, k: usize, i: usize) -> &[f64] {
        self.at(&self.held_p, k, i)
    }

    /// The standard local KF's prediction x̂^{p,i}_k.
    pub fn kf_p(&self, k: usize, i: usize) -> &[f64] {
        self.at(&self.kf_p, k, i)
    }

    /// The standard local KF's estimate x̂^{e,i}_k.
    pub fn kf(&self, k: usize, i: usize) -> &[f64] {
        self.at(&self.kf, k, i)
    }

    /// The sensors' steps of [`super::DkfSensor::step`] that do not depend on the trigger,
    /// and the center's two data terms, in the same operations.
    pub(super) fn compute(
        scheme: &DistributedKfScheme,
        measurements: &[Vec<Vector>],
        steps: usize,
    ) -> Self {
        let plan = &scheme.plan;
        let sys = &scheme.system;
        let n = sys.state_dim();
        let ns = sys.n_sensors();
        let len = steps * ns * n;
        let mut t = Self {
            n,
            sensors: ns,
            xbar_p: Vec::with_capacity(len),
            held_p: Vec::with_capacity(len),
            kf_p: Vec::with_capacity(len),
            kf: Vec::with_capacity(len),
            correction_norm: Vec::with_capacity(steps * ns),
            xbar_e: Vec::with_capacity(len),
            info_sent: Vec::with_capacity(len),
            info_omitted: Vec::with_capacity(len),
        };
        let a = plan.a();
        let mut xbar: Vec<Vector> = vec![sys.prior.mean.clone(); ns];
        let mut kf: Vec<Vector> = vec![sys.prior.mean.clone(); ns];
        // Per sensor: its last estimate as it arrived (the prior's mean before any).
        let mut arrived: Vec<Vector> = vec![sys.prior.mean.clone(); ns];
        let mut held_p = Vector::zeros(n);
        let mut xbar_p = Vector::zeros(n);
        let mut tmp = Vector::zeros(n);
        let mut tmp2 = Vector::zeros(n);
        let mut zbuf: Vec<Vector> = sys
            .sensors
            .iter()
            .map(|s| Vector::zeros(s.meas_dim()))
            .collect();
        let mut zbuf2 = zbuf.clone();
        for (k, zs) in (1..=steps).zip(measurements) {
            let m = plan.at(k).expect("checked horizon");
            for (i, (s, z)) in sys.sensors.iter().zip(zs).enumerate() {
                let lin = s
                    .as_linear()
                    .expect("the plan exists only for linear sensors");
                let (xbar, kf, arrived) = (&mut xbar[i], &mut kf[i], &mut arrived[i]);
                crate::linalg::fixed::gemv(&mut xbar_p, a, xbar);
                crate::linalg::fixed::gemv(&mut held_p, a, arrived);
                crate::linalg::fixed::gemv(xbar, &m.prediction_weight, &xbar_p);
                crate::linalg::fixed::gemv(&mut tmp, &m.measurement_weight[i], z);
                fixed::add_assign(xbar.as_mut_slice(), tmp.as_slice());
                predict_in_place(a, kf, &mut tmp);
                t.kf_p.extend_from_slice(kf.as_slice());
                let (zbuf, zbuf2) = (&mut zbuf[i], &mut zbuf2[i]);
                crate::linalg::fixed::gemv(zbuf2, lin.h(), kf);
                zbuf.copy_from_slice(z.as_slice());
                fixed::sub_assign(zbuf.as_mut_slice(), zbuf2.as_slice());
                crate::linalg::fixed::gemv(&mut tmp2, &m.kf_gain[i], zbuf);
                fixed::add_assign(kf.as_mut_slice(), tmp2.as_slice());
                t.correction_norm.push(fixed::norm(tmp2.as_slice()));
                t.xbar_p.extend_from_slice(xbar_p.as_slice());
                t.held_p.extend_from_slice(held_p.as_slice());
                t.kf.extend_from_slice(kf.as_slice());
                arrived.copy_from(xbar);
                crate::link::round_as_sent(arrived.as_mut_slice());
                t.xbar_e.extend_from_slice(arrived.as_slice());
                crate::linalg::fixed::gemv(&mut tmp, &m.cbar_e_inv, arrived);
                t.info_sent.extend_from_slice(tmp.as_slice());
                crate::linalg::fixed::gemv(&mut tmp, &m.cbar_p_inv, &held_p);
                t.info_omitted.extend_from_slice(tmp.as_slice());
            }
        }
        t
    }
}
