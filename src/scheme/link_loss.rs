//! `link_loss`, the loss probability a loss-aware center assumes for each sensor's link: one
//! number for every sensor, one number per sensor, or `"channel"`: each sensor's own from the
//! scenario's `[channel]` (its per-sensor table where it has one), so that what the link does
//! is written once.
//!
//! Why per sensor: a center that assumes one loss for all reads a silence of a sensor on a
//! clean link as possibly lost (too little information) and one on a bad link as too likely a
//! true silence (too much). With one sensor at 60% loss and the others at none, a center that
//! takes 60% everywhere is inconsistent (ANEES well below 1); each sensor's own loss is not.
use crate::scheme::registry::BuildContext;
use crate::scheme::SchemeError;
use serde::{Deserialize, Serialize};

/// The written value of `link_loss`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum LinkLoss {
    /// The same probability for every sensor.
    All(f64),
    /// One probability per sensor, in file order.
    PerSensor(Vec<f64>),
    /// `"channel"`: each sensor's from its link ([`BuildContext::link_loss`]).
    FromChannel(FromChannel),
}

/// The word `"channel"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FromChannel {
    Channel,
}

/// How `link_loss` reads in the parameter docs.
pub const VALUES: &str = "number in [0, 1), a list of one per sensor, or \"channel\"";

const FIELD: &str = "link_loss";

fn invalid(message: String) -> SchemeError {
    SchemeError::Invalid {
        field: FIELD,
        message,
    }
}

/// Checks one probability: in [0, 1) (p = 1 would make every message a loss and every silence
/// uninformative; the trigger then sends for nothing).
pub fn check(p: f64) -> Result<f64, SchemeError> {
    if (0.0..1.0).contains(&p) {
        Ok(p)
    } else {
        Err(invalid(format!(
            "expected a probability in [0, 1), got {p}"
        )))
    }
}

impl LinkLoss {
    /// Each sensor's loss probability for a system of `sensors` sensors whose links lose what
    /// `cx.link_loss` says.
    ///
    /// Errors: a probability outside [0, 1) and a list of another length than the sensors.
    pub fn per_sensor(&self, cx: &BuildContext) -> Result<Vec<f64>, SchemeError> {
        let n = cx.system.n_sensors();
        let ps = match self {
            LinkLoss::All(p) => vec![*p; n],
            LinkLoss::PerSensor(ps) if ps.len() == n => ps.clone(),
            LinkLoss::PerSensor(ps) => {
                return Err(invalid(format!(
                    "expected one probability per sensor ({n}), got {}",
                    ps.len()
                )))
            }
            LinkLoss::FromChannel(_) => cx.link_loss.map_or(vec![0.0; n], <[f64]>::to_vec),
        };
        for (i, p) in ps.iter().enumerate() {
            check(*p).map_err(|_| {
                invalid(format!(
                    "sensor {i}: expected a probability in [0, 1), got {p}"
                ))
            })?;
        }
        Ok(ps)
    }
}

/// The loss probabilities a center assumes, per sensor: `None` (the published update) for an
/// absent `link_loss` and where every sensor's is 0, where the loss-aware update is the
/// published one, so that the published code runs and its numbers stay bit for bit.
pub fn effective(
    link_loss: Option<&LinkLoss>,
    cx: &BuildContext,
) -> Result<Option<Vec<f64>>, SchemeError> {
    match link_loss {
        None => Ok(None),
        Some(l) => Ok(Some(l.per_sensor(cx)?).filter(|ps| ps.iter().any(|&p| p > 0.0))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::Gaussian;
    use crate::linalg::{Matrix, Vector};
    use crate::model::{LinearSensor, LinearTransition, MeasurementModel};
    use crate::scheme::System;
    use std::sync::Arc;

    fn system(n: usize) -> Arc<System> {
        let sensor =
            Arc::new(LinearSensor::new(Matrix::identity(1, 1), Matrix::identity(1, 1)).unwrap())
                as Arc<dyn MeasurementModel>;
        Arc::new(System {
            transition: LinearTransition::new(Matrix::identity(1, 1), Matrix::identity(1, 1))
                .unwrap(),
            sensors: vec![sensor; n],
            prior: Gaussian::new(Vector::zeros(1), Matrix::identity(1, 1)),
        })
    }

    fn parse(v: &str) -> LinkLoss {
        #[derive(Deserialize)]
        struct T {
            link_loss: LinkLoss,
        }
        toml::from_str::<T>(&format!("link_loss = {v}"))
            .unwrap()
            .link_loss
    }

    #[test]
    fn a_number_a_list_and_the_channel_are_each_sensors_loss() {
        let sys = system(3);
        let from_link = [0.6, 0.0, 0.1];
        let cx = BuildContext {
            system: &sys,
            steps: 10,
            link_loss: Some(&from_link),
        };
        assert_eq!(parse("0.2").per_sensor(&cx).unwrap(), vec![0.2; 3]);
        assert_eq!(
            parse("[0.6, 0, 0.5]").per_sensor(&cx).unwrap(),
            vec![0.6, 0.0, 0.5]
        );
        assert_eq!(parse("\"channel\"").per_sensor(&cx).unwrap(), from_link);
        // Published where nothing is lost.
        assert_eq!(effective(Some(&parse("[0, 0, 0]")), &cx).unwrap(), None);
        assert_eq!(effective(None, &cx).unwrap(), None);
        let ideal = BuildContext {
            link_loss: None,
            ..cx
        };
        assert_eq!(
            effective(Some(&parse("\"channel\"")), &ideal).unwrap(),
            None
        );
    }

    #[test]
    fn bad_values_are_named() {
        let sys = system(3);
        let cx = BuildContext {
            system: &sys,
            steps: 10,
            link_loss: None,
        };
        let msg = |v: &str| match parse(v).per_sensor(&cx) {
            Err(SchemeError::Invalid { field, message }) => {
                assert_eq!(field, "link_loss");
                message
            }
            other => panic!("{v}: {other:?}"),
        };
        assert!(msg("[0.1, 0.2]").contains("one probability per sensor (3), got 2"));
        assert!(msg("[0.1, 1.0, 0.2]").contains("sensor 1"));
        assert!(msg("-0.1").contains("[0, 1)"));
        assert!(toml::from_str::<toml::Table>("link_loss = \"chanel\"")
            .map(|t| LinkLoss::deserialize(t["link_loss"].clone()).is_err())
            .unwrap());
    }
}
