//! The scenario keys of a link: the `[channel]` table of a scenario (and of a sensor or link
//! that overrides it). The keys every link has (`kind`, `delay`, `downlink`, `arq`) are fields
//! here; a model's own keys (`loss`, `p_gb`, …) are kept by name as written, and belong to the
//! model that documents them ([`super::models`]): adding a link model is writing its file there,
//! nothing here. Parsing accepts any registered key so that a key of another kind can be named by
//! [`ChannelSpec::validate`], which then checks that the keys fit the kind and their values.
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The loss model of a link: a registered model ([`super::models::LINK_MODELS`]), by its place
/// in the registry ([`ChannelKind::named`] finds one by name, [`ChannelKind::model`] gives its
/// behaviour at no cost: fates ask it once per slot).
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct ChannelKind(pub(super) usize);

impl ChannelKind {
    /// Every packet arrives: the link of a scenario without `[channel]` (the registry's first).
    pub const IDEAL: ChannelKind = ChannelKind(0);
}

impl Default for ChannelKind {
    fn default() -> Self {
        ChannelKind::IDEAL
    }
}

/// The tag of a random delay table (`delay = { kind = "geometric", mean = … }`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum DelayKind {
    /// Geometric number of steps (failures before a success), see [`Delay::Geometric`].
    Geometric,
}

/// A random delay: `{ kind = "geometric", mean = … }`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GeometricDelay {
    /// Always `"geometric"`.
    pub kind: DelayKind,
    /// The mean delay in steps (finite, ≥ 0).
    pub mean: f64,
    /// How many steps the fusion center keeps to re-fuse late packets; later ones are dropped
    /// and counted. Default: the delay's 99.9% quantile.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub horizon: Option<u32>,
}

/// How many steps a delivered packet takes: an integer, or a geometric table.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
#[serde(
    expecting = "a delay: a non-negative integer number of steps or { kind = \"geometric\", mean = … }"
)]
pub enum Delay {
    /// Every packet takes exactly this many steps.
    Fixed(u32),
    /// Geometric number of steps with the given mean (see `fate`).
    Geometric(GeometricDelay),
}

impl Default for Delay {
    fn default() -> Self {
        Delay::Fixed(0)
    }
}

impl Delay {
    /// Steps the fusion center keeps to re-fuse a late packet: the fixed delay itself, or a
    /// geometric delay's `horizon` (default: its 99.9% quantile, the smallest n with
    /// P(delay > n) = (1 - p)^(n + 1) <= 0.001, p = 1 / (1 + mean)).
    pub fn horizon(&self) -> u32 {
        match self {
            Delay::Fixed(d) => *d,
            Delay::Geometric(g) => g.horizon.unwrap_or_else(|| {
                if g.mean <= 0.0 {
                    return 0;
                }
                let q = g.mean / (1.0 + g.mean);
                // ln q, exactly where q rounds to 1 (a mean above about 1e16): ln q = −ln(1 + 1/μ).
                let ln_q = if q < 1.0 {
                    q.ln()
                } else {
                    -(1.0 / g.mean).ln_1p()
                };
                ((0.001f64.ln() / ln_q).ceil() - 1.0).clamp(0.0, 1e6) as u32
            }),
        }
    }

    /// Whether every packet takes zero steps.
    pub fn is_zero(&self) -> bool {
        match self {
            Delay::Fixed(d) => *d == 0,
            Delay::Geometric(g) => g.mean == 0.0,
        }
    }
}

/// Acknowledged retransmission on a link, as the IEEE 802.15.4 MAC does it (2006 §7.5.6.4):
/// after each attempt that arrives the receiver sends an acknowledgment frame on the downlink;
/// a sender that hears none sends again, up to `max_retries` times, within the step (the MAC
/// retries within milliseconds, far below a filter step). See `fate` for the draws and
/// [`crate::network::Traffic`] for what is counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Arq {
    /// Retransmissions allowed after the first attempt (`macMaxFrameRetries`, 0..=7).
    pub max_retries: u32,
}

impl Arq {
    /// The largest `max_retries`: the range of the MAC PIB attribute `macMaxFrameRetries`
    /// (IEEE 802.15.4-2006 §7.4.2, Table 86: 0–7, default 3).
    pub const MAX_RETRIES: u32 = 7;
}

/// A link model: the `[channel]` table of a scenario, of one sensor or of one link.
///
/// Every key is optional at parse time; [`ChannelSpec::validate`] enforces which keys each
/// `kind` needs and allows (its model's checks). Read and written as documented in `channel/parse.rs`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ChannelSpec {
    /// The loss model (default `"ideal"`).
    pub kind: ChannelKind,
    /// The model keys as written, by name (any registered model's: a key of another kind is
    /// kept so that the checks can name it). Read them with [`ChannelSpec::key`].
    pub keys: BTreeMap<&'static str, f64>,
    /// Delay of a delivered packet, in steps (default 0).
    pub delay: Option<Delay>,
    /// The feedback link (fusion center → sensors); `None` = ideal downlink.
    pub downlink: Option<Box<ChannelSpec>>,
    /// Acknowledged retransmission of the uplink's packets; the acknowledgements travel on
    /// `downlink`. Not allowed on a downlink itself.
    pub arq: Option<Arq>,
}

impl ChannelSpec {
    /// The model key `name` as written, if it is.
    pub fn key(&self, name: &str) -> Option<f64> {
        self.keys.get(name).copied()
    }

    /// The delay (default 0).
    pub fn delay(&self) -> Delay {
        self.delay.unwrap_or_default()
    }

    /// The downlink model (`None` in the file means ideal).
    pub fn downlink_spec(&self) -> ChannelSpec {
        self.downlink.as_deref().cloned().unwrap_or_default()
    }

    /// Whether the link changes nothing: ideal kind, zero delay (a geometric delay of mean 0 is
    /// zero too), an ideal or absent downlink and no `arq` table.
    pub fn is_ideal(&self) -> bool {
        self.kind == ChannelKind::IDEAL
            && self.delay().is_zero()
            && self.downlink.as_deref().is_none_or(ChannelSpec::is_ideal)
            && self.arq.is_none()
    }
}

/// The link model of each sensor: sensor i's own table if it has one, else the scenario's
/// `[channel]`, else ideal. A per-sensor table REPLACES the global one as a whole; it is not
/// merged key by key (a sensor that overrides `kind` must not inherit, say, a `loss` that only
/// made sense for the global kind). One entry per element of `per_sensor`.
pub fn resolve(
    global: Option<&ChannelSpec>,
    per_sensor: &[Option<ChannelSpec>],
) -> Vec<ChannelSpec> {
    per_sensor
        .iter()
        .map(|own| match own {
            Some(spec) => spec.clone(),
            None => global.cloned().unwrap_or_default(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parses the body of a `[channel]` table.
    fn parse(body: &str) -> Result<ChannelSpec, String> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Doc {
            channel: ChannelSpec,
        }
        toml::from_str::<Doc>(&format!("[channel]\n{body}"))
            .map(|d| d.channel)
            .map_err(|e| e.to_string())
    }

    fn parse_ok(body: &str) -> ChannelSpec {
        match parse(body) {
            Ok(s) => s,
            Err(e) => panic!("{body:?} should parse: {e}"),
        }
    }

    fn invalid(body: &str) -> String {
        match parse_ok(body).validate() {
            Ok(()) => panic!("{body:?} should be invalid"),
            Err(e) => e,
        }
    }

    #[test]
    fn parses_ideal_and_empty_table() {
        let s = parse_ok("kind = \"ideal\"");
        assert_eq!(s, ChannelSpec::default());
        assert!(s.is_ideal());
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(parse_ok(""), ChannelSpec::default());
    }

    #[test]
    fn parses_bernoulli() {
        let s = parse_ok("kind = \"bernoulli\"\nloss = 0.25");
        assert_eq!(s.kind, ChannelKind::named("bernoulli").unwrap());
        assert_eq!(s.key("loss"), Some(0.25));
        assert_eq!(s.validate(), Ok(()));
        assert!(!s.is_ideal());
    }

    #[test]
    fn parses_gilbert_elliott_with_defaults() {
        let s = parse_ok("kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.4");
        assert_eq!(s.kind, ChannelKind::named("gilbert-elliott").unwrap());
        assert_eq!((s.key("p_gb"), s.key("p_bg")), (Some(0.1), Some(0.4)));
        assert_eq!((s.key("loss_good"), s.key("loss_bad")), (None, None));
        assert_eq!(s.validate(), Ok(()));
        let s = parse_ok(
            "kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.4\nloss_good = 0.02\nloss_bad = 0.8",
        );
        assert_eq!(
            (s.key("loss_good"), s.key("loss_bad")),
            (Some(0.02), Some(0.8))
        );
        assert_eq!(s.validate(), Ok(()));
    }

    #[test]
    fn parses_both_delay_forms() {
        let s = parse_ok("delay = 3");
        assert_eq!(s.delay, Some(Delay::Fixed(3)));
        assert!(!s.is_ideal());
        let s = parse_ok("delay = { kind = \"geometric\", mean = 1.5 }");
        assert_eq!(
            s.delay,
            Some(Delay::Geometric(GeometricDelay {
                kind: DelayKind::Geometric,
                mean: 1.5,
                horizon: None,
            }))
        );
        // The horizon: the fixed delay, or the geometric delay's 99.9% quantile unless given.
        assert_eq!(Delay::Fixed(3).horizon(), 3);
        // mean 1.5: q = 0.6, ln(0.001) / ln(0.6) = 13.52..., so n = 13: 0.6^14 = 0.00078.
        assert_eq!(s.delay().horizon(), 13);
        let h = parse_ok("delay = { kind = \"geometric\", mean = 1.5, horizon = 4 }");
        assert_eq!(h.delay().horizon(), 4);
        assert_eq!(s.validate(), Ok(()));
        // Zero delay in either form leaves the link ideal.
        assert!(parse_ok("delay = 0").is_ideal());
        assert!(parse_ok("delay = { kind = \"geometric\", mean = 0.0 }").is_ideal());
    }

    #[test]
    fn rejects_malformed_delays() {
        assert!(parse("delay = -1").is_err());
        assert!(parse("delay = 1.5").is_err());
        assert!(parse("delay = { kind = \"uniform\", mean = 1.0 }").is_err());
        assert!(parse("delay = { kind = \"geometric\", mean = 1.0, max = 3 }").is_err());
        let e = parse("delay = \"soon\"").unwrap_err();
        assert!(e.contains("a delay"), "{e}");
    }

    #[test]
    fn parses_downlink_and_arq() {
        let s = parse_ok(
            "kind = \"bernoulli\"\nloss = 0.1\ndownlink = { kind = \"bernoulli\", loss = 0.3 }\narq = { max_retries = 2 }",
        );
        let down = s.downlink.as_deref().expect("downlink parsed");
        assert_eq!(down.kind, ChannelKind::named("bernoulli").unwrap());
        assert_eq!(down.key("loss"), Some(0.3));
        assert_eq!(s.arq, Some(Arq { max_retries: 2 }));
        assert_eq!(s.validate(), Ok(()));
        // Sub-table syntax works too.
        let toml = "[channel]\nkind = \"ideal\"\n[channel.downlink]\nkind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.5\n";
        #[derive(Deserialize)]
        struct Doc {
            channel: ChannelSpec,
        }
        let doc: Doc = toml::from_str(toml).expect("sub-table parses");
        assert_eq!(
            doc.channel.downlink_spec().kind,
            ChannelKind::named("gilbert-elliott").unwrap()
        );
        assert!(!doc.channel.is_ideal());
    }

    /// A delay on the downlink was accepted and ignored (the run was byte for byte the one
    /// without it): now refused, naming the key; a zero delay is no delay.
    #[test]
    fn a_downlink_delay_is_refused() {
        for d in ["3", "{ kind = \"geometric\", mean = 2.0 }"] {
            let e = invalid(&format!(
                "kind = \"bernoulli\"\nloss = 0.1\ndownlink = {{ delay = {d} }}"
            ));
            assert!(e.contains("channel.downlink.delay is not supported"), "{e}");
        }
        assert!(parse_ok("downlink = { delay = 0 }").validate().is_ok());
    }

    #[test]
    fn is_ideal_needs_every_part_ideal() {
        assert!(parse_ok("downlink = { kind = \"ideal\" }").is_ideal());
        assert!(!parse_ok("downlink = { kind = \"bernoulli\", loss = 0.1 }").is_ideal());
        assert!(!parse_ok("arq = { max_retries = 0 }").is_ideal());
        assert!(ChannelSpec::default().downlink_spec().is_ideal());
    }

    #[test]
    fn lossless_links() {
        for body in [
            "",
            "kind = \"bernoulli\"\nloss = 0.0",
            "kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.2\nloss_bad = 0.0",
            "downlink = { kind = \"bernoulli\", loss = 0.0 }",
            "delay = { kind = \"geometric\", mean = 0.0 }",
        ] {
            assert!(parse_ok(body).is_lossless(), "{body:?}");
        }
        for body in [
            "kind = \"bernoulli\"\nloss = 0.01",
            "kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.2",
            "kind = \"gilbert-elliott\"\np_gb = 0.0\np_bg = 0.2\nloss_good = 0.1\nloss_bad = 0.0",
            "downlink = { kind = \"bernoulli\", loss = 0.5 }",
            "delay = 1",
            "arq = { max_retries = 0 }",
        ] {
            assert!(!parse_ok(body).is_lossless(), "{body:?}");
        }
    }

    #[test]
    fn rejects_unknown_keys() {
        assert!(parse("kind = \"ideal\"\nlos = 0.1").is_err());
        assert!(parse("kind = \"erasure\"").is_err());
        assert!(parse("arq = { max_retries = 1, timeout = 2 }").is_err());
        assert!(parse("downlink = { kind = \"ideal\", extra = 1 }").is_err());
        assert!(parse("arq = { max_retries = -1 }").is_err());
    }

    #[test]
    fn validation_names_missing_keys() {
        assert_eq!(
            invalid("kind = \"bernoulli\""),
            "channel.kind = \"bernoulli\" needs `loss`"
        );
        assert_eq!(
            invalid("kind = \"gilbert-elliott\"\np_bg = 0.5"),
            "channel.kind = \"gilbert-elliott\" needs `p_gb`"
        );
        assert_eq!(
            invalid("kind = \"gilbert-elliott\"\np_gb = 0.5"),
            "channel.kind = \"gilbert-elliott\" needs `p_bg`"
        );
    }

    #[test]
    fn validation_rejects_non_probabilities() {
        assert_eq!(
            invalid("kind = \"bernoulli\"\nloss = 1.5"),
            "channel.loss = 1.5 is not a probability in [0, 1]"
        );
        assert_eq!(
            invalid("kind = \"bernoulli\"\nloss = -0.1"),
            "channel.loss = -0.1 is not a probability in [0, 1]"
        );
        assert_eq!(
            invalid("kind = \"bernoulli\"\nloss = nan"),
            "channel.loss = NaN is not a probability in [0, 1]"
        );
        let ge = "kind = \"gilbert-elliott\"\n";
        assert_eq!(
            invalid(&format!("{ge}p_gb = 2.0\np_bg = 0.5")),
            "channel.p_gb = 2 is not a probability in [0, 1]"
        );
        assert_eq!(
            invalid(&format!("{ge}p_gb = 0.2\np_bg = nan")),
            "channel.p_bg = NaN is not a probability in [0, 1]"
        );
        assert_eq!(
            invalid(&format!("{ge}p_gb = 0.2\np_bg = 0.5\nloss_good = -1.0")),
            "channel.loss_good = -1 is not a probability in [0, 1]"
        );
        assert_eq!(
            invalid(&format!("{ge}p_gb = 0.2\np_bg = 0.5\nloss_bad = 1.01")),
            "channel.loss_bad = 1.01 is not a probability in [0, 1]"
        );
    }

    #[test]
    fn validation_rejects_keys_of_another_kind() {
        assert_eq!(
            invalid("kind = \"bernoulli\"\nloss = 0.1\np_gb = 0.2"),
            "channel.p_gb belongs to kind = \"gilbert-elliott\", not \"bernoulli\""
        );
        assert_eq!(
            invalid("kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.2\nloss = 0.3"),
            "channel.loss belongs to kind = \"bernoulli\", not \"gilbert-elliott\""
        );
        assert_eq!(
            invalid("loss = 0.3"),
            "channel.loss belongs to kind = \"bernoulli\", not \"ideal\""
        );
        assert_eq!(
            invalid("loss_bad = 0.3"),
            "channel.loss_bad belongs to kind = \"gilbert-elliott\", not \"ideal\""
        );
        assert_eq!(
            invalid("kind = \"bernoulli\"\nloss = 0.1\nloss_good = 0.0"),
            "channel.loss_good belongs to kind = \"gilbert-elliott\", not \"bernoulli\""
        );
    }

    #[test]
    fn validation_rejects_bad_geometric_mean() {
        assert_eq!(
            invalid("delay = { kind = \"geometric\", mean = -1.0 }"),
            "channel.delay.mean = -1 must be a finite number of steps >= 0"
        );
        assert_eq!(
            invalid("delay = { kind = \"geometric\", mean = inf }"),
            "channel.delay.mean = inf must be a finite number of steps >= 0"
        );
        assert_eq!(
            invalid("delay = { kind = \"geometric\", mean = nan }"),
            "channel.delay.mean = NaN must be a finite number of steps >= 0"
        );
    }

    #[test]
    fn arq_retries_are_bounded_and_uplink_only() {
        assert_eq!(parse_ok("arq = { max_retries = 7 }").validate(), Ok(()));
        assert_eq!(
            invalid("arq = { max_retries = 8 }"),
            "channel.arq.max_retries = 8 is out of range: 0 to 7 (macMaxFrameRetries of IEEE 802.15.4)"
        );
        assert!(
            invalid("downlink = { kind = \"ideal\", arq = { max_retries = 1 } }")
                .starts_with("channel.downlink.arq is not allowed")
        );
    }

    #[test]
    fn validation_descends_into_downlink() {
        assert_eq!(
            invalid("downlink = { kind = \"bernoulli\" }"),
            "channel.downlink.kind = \"bernoulli\" needs `loss`"
        );
        assert_eq!(
            invalid("downlink = { kind = \"bernoulli\", loss = 3.0 }"),
            "channel.downlink.loss = 3 is not a probability in [0, 1]"
        );
        assert_eq!(
            invalid("downlink = { downlink = { kind = \"ideal\" } }"),
            "channel.downlink.downlink is not allowed: a downlink has no downlink"
        );
        let s = parse_ok("kind = \"bernoulli\"");
        assert_eq!(
            s.validate_at("sensors[2].channel"),
            Err("sensors[2].channel.kind = \"bernoulli\" needs `loss`".to_string())
        );
    }

    #[test]
    fn serializes_back_to_the_same_table() {
        let s = parse_ok(
            "kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.4\ndelay = { kind = \"geometric\", mean = 2.0 }\ndownlink = { kind = \"bernoulli\", loss = 0.3 }",
        );
        let text = toml::to_string(&s).expect("serializes");
        let back: ChannelSpec = toml::from_str(&text).expect("reparses");
        assert_eq!(back, s);
    }

    #[test]
    fn per_sensor_table_replaces_global() {
        let global = parse_ok("kind = \"bernoulli\"\nloss = 0.2\ndelay = 2");
        let own = parse_ok("kind = \"gilbert-elliott\"\np_gb = 0.1\np_bg = 0.5");
        let specs = resolve(Some(&global), &[None, Some(own.clone()), None]);
        assert_eq!(specs, vec![global.clone(), own.clone(), global.clone()]);
        // Replaced, not merged: the global delay is not inherited.
        assert_eq!(specs[1].delay, None);
        let specs = resolve(None, &[None, Some(own.clone())]);
        assert_eq!(specs, vec![ChannelSpec::default(), own]);
        assert!(resolve(Some(&global), &[]).is_empty());
    }
}
