//! A `[channel]` table read and written: its `kind` matched with the registered link models
//! ([`super::models::LINK_MODELS`]), its model keys kept by name (any registered model's, so
//! that a key of another kind can be named by the checks), and written back in the order it is
//! documented: `kind`, the model keys in the registry's order, then `delay`, `downlink`, `arq`.
use super::models::{self, model_keys};
use super::spec::{Arq, ChannelKind, ChannelSpec, Delay};
use serde::de::Error as _;
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::collections::BTreeMap;

impl Serialize for ChannelKind {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for ChannelKind {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        ChannelKind::named(&name).ok_or_else(|| {
            let kinds: Vec<String> = models::LINK_MODELS
                .iter()
                .map(|m| format!("`{}`", m.name))
                .collect();
            D::Error::custom(format!(
                "unknown variant `{name}`, expected one of {}",
                kinds.join(", ")
            ))
        })
    }
}

/// A `[channel]` table as parsed, before its model keys are matched with the registry.
#[derive(Deserialize)]
struct RawChannel {
    #[serde(default)]
    kind: ChannelKind,
    #[serde(default)]
    delay: Option<Delay>,
    #[serde(default)]
    downlink: Option<Box<ChannelSpec>>,
    #[serde(default)]
    arq: Option<Arq>,
    #[serde(flatten)]
    keys: BTreeMap<String, f64>,
}

impl<'de> Deserialize<'de> for ChannelSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let raw = RawChannel::deserialize(d)?;
        let mut keys = BTreeMap::new();
        for (name, value) in raw.keys {
            let Some(known) = model_keys().find(|k| *k == name) else {
                let mut expected = vec!["`kind`".to_string()];
                expected.extend(model_keys().map(|k| format!("`{k}`")));
                expected.extend(["`delay`", "`downlink`", "`arq`"].map(String::from));
                return Err(D::Error::custom(format!(
                    "unknown field `{name}`, expected one of {}",
                    expected.join(", ")
                )));
            };
            keys.insert(known, value);
        }
        Ok(ChannelSpec {
            kind: raw.kind,
            keys,
            delay: raw.delay,
            downlink: raw.downlink,
            arq: raw.arq,
        })
    }
}

impl Serialize for ChannelSpec {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(None)?;
        m.serialize_entry("kind", &self.kind)?;
        for key in model_keys() {
            if let Some(v) = self.keys.get(key) {
                m.serialize_entry(key, v)?;
            }
        }
        if let Some(d) = &self.delay {
            m.serialize_entry("delay", d)?;
        }
        if let Some(d) = &self.downlink {
            m.serialize_entry("downlink", d)?;
        }
        if let Some(a) = &self.arq {
            m.serialize_entry("arq", a)?;
        }
        m.end()
    }
}

/// Links built in code rather than read from a file.
impl ChannelSpec {
    /// A link of model `kind` with model keys `keys` and nothing else (ideal downlink, no
    /// delay, no `arq`). Panics on a kind or key that is not registered.
    pub fn of_kind(kind: &str, keys: &[(&str, f64)]) -> Self {
        let mut spec = ChannelSpec {
            kind: ChannelKind::named(kind).unwrap_or_else(|| panic!("no link model {kind}")),
            ..ChannelSpec::default()
        };
        for &(name, value) in keys {
            let known = model_keys()
                .find(|k| *k == name)
                .unwrap_or_else(|| panic!("no link model key {name}"));
            spec.keys.insert(known, value);
        }
        spec
    }

    /// This link with model `kind` and keys `keys` in place of its own (its delay, downlink and
    /// `arq` kept). Panics as [`ChannelSpec::of_kind`].
    pub fn as_kind(&self, kind: &str, keys: &[(&str, f64)]) -> Self {
        ChannelSpec {
            delay: self.delay,
            downlink: self.downlink.clone(),
            arq: self.arq,
            ..ChannelSpec::of_kind(kind, keys)
        }
    }
}
