//! The fusion center's half of a step, written once for every place a center runs: the
//! engine's [`crate::engine::trial::Trial`] (over a simulated network), its link layer when a
//! late packet makes it fuse the past again, and the live center (over real frames). It holds
//! the rules a center's step has wherever it runs: the center is built for its trial from the
//! trial's center seed ([`crate::stats::seeding::center_seed`]); after every step its feedback
//! is kept as the sensors receive it (every real the single it is priced as, unless the scenario
//! sends doubles); and a center brought again through an edited history is a fresh one (a
//! particle filter draws again from its own seed, so the same history gives the same estimate).
//!
//! The sensor's half is one rule, [`scheduled`]: a sensor steps when the schedule gives it the
//! step and it has a reading.
use crate::filter::Gaussian;
use crate::link::{Reals, Received};
use crate::network::Schedule;
use crate::scenario::experiment::Experiment;
use crate::scheme::{Feedback, FusionCenter, Scheme, SchemeError, SensorNode};
use crate::stats::seeding;

/// Whether sensor `i` of `n` steps at step `k`: the schedule gives it the step, and it has a
/// reading (recorded data may have holes). A sensor that does not step sends nothing and its
/// entry of the center's inbox is [`Received::NotScheduled`].
pub fn scheduled(schedule: Schedule, k: usize, i: usize, n: usize, has_reading: bool) -> bool {
    has_reading && schedule.allows(k, i, n)
}

/// The fusion center of one trial of one variant, and the feedback it last gave.
pub struct FusionSide {
    center: Box<dyn FusionCenter>,
    /// The center's feedback after its last step (before the first: its initial one), as the
    /// sensors receive it.
    feedback: Option<Feedback>,
    reals: Reals,
    trial: usize,
    center_seed: u64,
}

impl FusionSide {
    /// Trial `trial` of variant `variant` of `exp` with its coin stream `stream`
    /// ([`seeding::coin_stream`]): its center, and its sensor nodes (for a caller that runs
    /// them; the live center drops them).
    pub fn new(
        exp: &Experiment,
        variant: usize,
        trial: usize,
        stream: u64,
    ) -> Result<(Self, Vec<Box<dyn SensorNode>>), SchemeError> {
        let center_seed = seeding::center_seed(exp.seed, trial as u64, stream);
        Self::with_seed(exp, variant, trial, center_seed)
    }

    /// [`FusionSide::new`] with the center's seed already drawn (the engine draws it with the
    /// sensors' coins).
    pub(crate) fn with_seed(
        exp: &Experiment,
        variant: usize,
        trial: usize,
        center_seed: u64,
    ) -> Result<(Self, Vec<Box<dyn SensorNode>>), SchemeError> {
        let inst = exp.variants[variant]
            .scheme
            .build_for_trial(trial, center_seed)?;
        let reals = exp.reals;
        let feedback = inst.center.feedback().map(|f| as_received(reals, f));
        let side = Self {
            center: inst.center,
            feedback,
            reals,
            trial,
            center_seed,
        };
        Ok((side, inst.sensors))
    }

    /// Fuses step `k`'s inbox (one entry per sensor) and keeps the feedback that follows.
    pub fn step(&mut self, k: usize, inbox: &[Received]) -> Result<(), SchemeError> {
        self.center.step(k, inbox)?;
        self.refresh_feedback();
        Ok(())
    }

    /// Fuses step `k` from the information the relays summed (in-network aggregation:
    /// [`FusionCenter::fuse_information`]) and keeps the feedback that follows.
    pub fn fuse_information(
        &mut self,
        k: usize,
        sum: Option<&crate::filter::information::Information>,
    ) -> Result<(), SchemeError> {
        self.center.fuse_information(k, sum)?;
        self.refresh_feedback();
        Ok(())
    }

    /// The center built afresh from `scheme` (this side's, with its trial and seed) and brought
    /// through `history` (step j + 1's inbox at j): after an arrival changed the past, or after
    /// a refused frame was taken out of it. The feedback is left as it was: the next step gives
    /// the new one. An error names the step it came from (0: building the center).
    pub fn rebuild(
        &mut self,
        scheme: &dyn Scheme,
        history: &[Vec<Received>],
    ) -> Result<(), (usize, SchemeError)> {
        let mut fresh = scheme
            .build_for_trial(self.trial, self.center_seed)
            .map_err(|e| (0, e))?
            .center;
        for (j, inbox) in history.iter().enumerate() {
            fresh.step(j + 1, inbox).map_err(|e| (j + 1, e))?;
        }
        self.center = fresh;
        Ok(())
    }

    /// The feedback the sensors hold for the next step.
    pub fn feedback(&self) -> Option<&Feedback> {
        self.feedback.as_ref()
    }

    pub fn estimate(&self) -> &Gaussian {
        self.center.estimate()
    }

    /// Effective sample size of a particle filter's center.
    pub fn ess(&self) -> Option<f64> {
        self.center.ess()
    }

    fn refresh_feedback(&mut self) {
        let reals = self.reals;
        self.feedback = self.center.feedback().map(|f| as_received(reals, f));
    }
}

/// Feedback as the sensors receive it: every real number the single it is priced as, unless
/// the scenario sends doubles.
fn as_received(reals: Reals, f: Feedback) -> Feedback {
    if reals.is_f32() {
        f.into_sent()
    } else {
        f
    }
}
