//! What a `[[schemes]]` entry says about its own link: `channel = { … }` (the keys of
//! `[channel]`, for every sensor, replacing the scenario's `[channel]` and any sensor's own for
//! that entry's variants; its keys swept by dotted names, `sweep."channel.loss" = [..]`) and
//! `sequence_bits` (sequence numbers on every packet). Both are taken out of the entry's table
//! before the scheme's registry entry parses it.
use crate::network::channel::ChannelSpec;
use crate::scenario::error::{Ctx, ScenarioError};
use crate::scenario::sweep::CHANNEL_PREFIX;
use crate::scenario::{ParamValue, Params};
use std::sync::Arc;

/// Most bits of a sequence number.
pub const MAX_SEQUENCE_BITS: i64 = 32;

/// The link keys of one sweep point of an entry, taken out of its table.
pub(crate) struct PointLink {
    /// The entry's own `channel` table with the point's swept keys in it.
    pub channel: Option<toml::Table>,
    pub sequence_bits: Option<toml::Value>,
}

impl PointLink {
    /// Takes `channel` and `sequence_bits` out of `t` (the entry's table with the point's
    /// plain keys in it) and puts the point's `channel.<key>` values into the channel table.
    pub(crate) fn take(t: &mut toml::Table, point: &[(String, toml::Value)]) -> Self {
        let mut channel = match t.remove("channel") {
            Some(toml::Value::Table(c)) => Some(c),
            Some(other) => {
                // Not a table: left for `resolve` to report.
                let mut bad = toml::Table::new();
                bad.insert(String::new(), other);
                Some(bad)
            }
            None => None,
        };
        for (k, v) in point {
            if let (Some(sub), Some(c)) = (k.strip_prefix(CHANNEL_PREFIX), channel.as_mut()) {
                c.insert(sub.to_string(), v.clone());
            }
        }
        Self {
            channel,
            sequence_bits: t.remove("sequence_bits"),
        }
    }

    /// The point's parameters that belong to the link, for the variant's `params`: every
    /// scalar key of the entry's `channel` as `channel.<key>`, and `sequence_bits` when given.
    pub(crate) fn params(&self, params: &mut Params) {
        if let Some(c) = &self.channel {
            for (k, v) in c {
                let value = match v {
                    toml::Value::Float(x) => ParamValue::Number(*x),
                    toml::Value::Integer(x) => ParamValue::Number(*x as f64),
                    toml::Value::Boolean(b) => ParamValue::Flag(*b),
                    toml::Value::String(s) => ParamValue::Text(s.clone()),
                    _ => continue,
                };
                params.insert(format!("{CHANNEL_PREFIX}{k}"), value);
            }
        }
        if let Some(toml::Value::Integer(n)) = &self.sequence_bits {
            params.insert("sequence_bits".to_string(), ParamValue::Number(*n as f64));
        }
    }

    /// The variant's link: the entry's own for every one of `n_sensors` sensors (validated,
    /// errors naming `{entry}.channel.<key>` and the sweep point `note`), else `scenario`;
    /// `None` when every link is ideal.
    pub(crate) fn channel(
        &self,
        ctx: &Ctx,
        (entry, note): (&str, &str),
        n_sensors: usize,
        scenario: &Option<Arc<Vec<ChannelSpec>>>,
    ) -> Result<Option<Arc<Vec<ChannelSpec>>>, ScenarioError> {
        let Some(table) = &self.channel else {
            return Ok(scenario.clone());
        };
        let path = format!("{entry}.channel");
        let field = format!("{path}{note}");
        if table.contains_key("") {
            return Err(ctx.err(
                field,
                "expected a table, e.g. channel = { kind = \"bernoulli\", loss = 0.1 }",
            ));
        }
        let spec: ChannelSpec = toml::Value::Table(table.clone())
            .try_into()
            .map_err(|e: toml::de::Error| ctx.err(&field, e.message().trim().to_string()))?;
        spec.validate_at(&path).map_err(|m| {
            // The message names the key (`schemes[0].channel.loss = …`): so does the field.
            let key = m
                .strip_prefix(&format!("{path}."))
                .and_then(|rest| rest.split([' ', '.']).next())
                .filter(|k| !k.is_empty())
                .map_or(String::new(), |k| format!(".{k}"));
            ctx.err(format!("{path}{key}{note}"), m)
        })?;
        Ok((!spec.is_ideal()).then(|| Arc::new(vec![spec; n_sensors])))
    }

    /// The point's `sequence_bits` (default 0), an integer in 0..=[`MAX_SEQUENCE_BITS`].
    pub(crate) fn sequence_bits(
        &self,
        ctx: &Ctx,
        (entry, note): (&str, &str),
    ) -> Result<u32, ScenarioError> {
        match &self.sequence_bits {
            None => Ok(0),
            Some(toml::Value::Integer(n)) if (0..=MAX_SEQUENCE_BITS).contains(n) => Ok(*n as u32),
            Some(v) => Err(ctx.err(
                format!("{entry}.sequence_bits{note}"),
                format!("expected an integer number of bits in 0..={MAX_SEQUENCE_BITS}, got {v}"),
            )),
        }
    }
}
