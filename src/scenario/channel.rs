//! The scenario's link model: the top-level `[channel]` table and a sensor's own `channel`
//! (which replaces the global table for that sensor), checked and resolved per sensor. The
//! model itself (kinds, fates, stability checks) is [`crate::network::channel`].
use crate::network::channel::{self, ChannelSpec};
use crate::scenario::error::{Ctx, ScenarioError};
use crate::scenario::file::ScenarioFile;

/// Every sensor's link model, or `None` when every link is ideal (the engine then runs exactly
/// as without a channel: the same draws and the same fast paths). Sensors of `[[sensor_fields]]`
/// take the global table.
pub(crate) fn build_channel(
    ctx: &Ctx,
    file: &ScenarioFile,
    n_sensors: usize,
) -> Result<Option<Vec<ChannelSpec>>, ScenarioError> {
    if let Some(global) = &file.channel {
        global
            .validate_at("channel")
            .map_err(|m| ctx.err("channel", m))?;
    }
    let mut own: Vec<Option<ChannelSpec>> = vec![None; n_sensors];
    for (i, s) in file.sensors.iter().enumerate() {
        if let Some(c) = &s.channel {
            let field = format!("sensors[{i}].channel");
            c.validate_at(&field).map_err(|m| ctx.err(&field, m))?;
            own[i] = Some(c.clone());
        }
    }
    let specs = channel::resolve(file.channel.as_ref(), &own);
    Ok((!specs.iter().all(ChannelSpec::is_ideal)).then_some(specs))
}
