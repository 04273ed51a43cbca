//! IEEE 802.15.4 MAC security (802.15.4-2006 §7.6, 802.15.4-2011 §7.3–7.4): what a secured
//! frame costs on air, and the frames themselves ([`ccm_star`]).
//!
//! A secured frame sets Security Enabled (bit 3) in the frame control and frame version 1
//! (bits 12–13; version 0 with the bit set is the different 2003 scheme). After the addressing
//! fields comes the **auxiliary security header** (§7.6.2): security control (1 octet: level in
//! bits 0–2, key identifier mode in bits 3–4), frame counter (4 octets, little-endian on air)
//! and key identifier (0, 1, 5 or 9 octets for key identifier modes 0–3): 5, 6, 10 or 14 octets.
//! After the payload, before the FCS, comes the **MIC**: 4, 8 or 16 octets (levels 1/5, 2/6,
//! 3/7). So a frame grows by [`SecuritySpec::overhead_octets`]: 9 octets (`mic-32`, implicit
//! key) to 30 (`mic-128`, 8-octet key source). Immediate acknowledgements are never secured
//! (2006 §7.2.2.3: no auxiliary security header in an ACK), so ARQ's ACKs cost what they did.
//!
//! Security adds no information: R_eff and every estimate are those of the unsecured run; only
//! frame bits, feedback bits and radio energy grow.
pub mod ccm_star;
pub mod counter;
pub mod keys;
#[cfg(test)]
mod tests;

use serde::{Deserialize, Serialize};

/// The security level of every secured frame (§7.6.2.2.1, Table 95), by name. Level 4 (`enc`,
/// encryption without a MIC) is refused: it authenticates nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SecurityLevel {
    /// Level 0: no security; frames as without `[security]`.
    #[default]
    None,
    /// Level 1: 4-octet MIC over header and payload, payload in clear.
    Mic32,
    /// Level 2: 8-octet MIC.
    Mic64,
    /// Level 3: 16-octet MIC.
    Mic128,
    /// Level 5: payload encrypted, 4-octet MIC.
    EncMic32,
    /// Level 6: payload encrypted, 8-octet MIC.
    EncMic64,
    /// Level 7: payload encrypted, 16-octet MIC.
    EncMic128,
}

impl SecurityLevel {
    /// Every level a scenario may name, in order.
    pub const ALL: [SecurityLevel; 7] = [
        SecurityLevel::None,
        SecurityLevel::Mic32,
        SecurityLevel::Mic64,
        SecurityLevel::Mic128,
        SecurityLevel::EncMic32,
        SecurityLevel::EncMic64,
        SecurityLevel::EncMic128,
    ];

    /// The name in a scenario file.
    pub fn name(self) -> &'static str {
        match self {
            SecurityLevel::None => "none",
            SecurityLevel::Mic32 => "mic-32",
            SecurityLevel::Mic64 => "mic-64",
            SecurityLevel::Mic128 => "mic-128",
            SecurityLevel::EncMic32 => "enc-mic-32",
            SecurityLevel::EncMic64 => "enc-mic-64",
            SecurityLevel::EncMic128 => "enc-mic-128",
        }
    }

    /// The level's number in the security control field (0–3, 5–7).
    pub fn code(self) -> u8 {
        match self {
            SecurityLevel::None => 0,
            SecurityLevel::Mic32 => 1,
            SecurityLevel::Mic64 => 2,
            SecurityLevel::Mic128 => 3,
            SecurityLevel::EncMic32 => 5,
            SecurityLevel::EncMic64 => 6,
            SecurityLevel::EncMic128 => 7,
        }
    }

    /// The level of security-control code `code`; None for 4 (refused) and above 7.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|l| l.code() == code)
    }

    /// Octets of the MIC (Table 95): 0, 4, 8 or 16.
    pub fn mic_octets(self) -> usize {
        match self {
            SecurityLevel::None => 0,
            SecurityLevel::Mic32 | SecurityLevel::EncMic32 => 4,
            SecurityLevel::Mic64 | SecurityLevel::EncMic64 => 8,
            SecurityLevel::Mic128 | SecurityLevel::EncMic128 => 16,
        }
    }

    /// Whether the payload is encrypted (levels 5–7).
    pub fn encrypts(self) -> bool {
        self.code() >= 5
    }
}

impl Serialize for SecurityLevel {
    /// By name ([`SecurityLevel::name`]), as a scenario writes it.
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for SecurityLevel {
    /// By name; `enc` gets its own refusal, anything else the list of names.
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        if name == "enc" {
            return Err(serde::de::Error::custom(
                "level \"enc\" (802.15.4 level 4) is refused: it encrypts without a MIC and so \
                 authenticates nothing; take \"enc-mic-32\", \"enc-mic-64\" or \"enc-mic-128\"",
            ));
        }
        Self::ALL
            .into_iter()
            .find(|l| l.name() == name)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|l| l.name()).collect();
                serde::de::Error::custom(format!(
                    "unknown security level \"{name}\"; the levels are {}",
                    names.join(", ")
                ))
            })
    }
}

/// How the receiver finds the key (§7.6.2.2.2, Table 96), by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum KeyIdMode {
    /// Mode 0: from the sender and receiver (no key identifier on air).
    Implicit,
    /// Mode 1: a 1-octet key index under the receiver's default key source (the usual choice,
    /// Thread's and ZigBee's).
    #[default]
    Index,
    /// Mode 2: a 4-octet key source and a key index.
    Source4,
    /// Mode 3: an 8-octet key source and a key index.
    Source8,
}

impl KeyIdMode {
    /// The name in a scenario file.
    pub fn name(self) -> &'static str {
        match self {
            KeyIdMode::Implicit => "implicit",
            KeyIdMode::Index => "index",
            KeyIdMode::Source4 => "source4",
            KeyIdMode::Source8 => "source8",
        }
    }

    /// The mode's number in the security control field.
    pub fn code(self) -> u8 {
        match self {
            KeyIdMode::Implicit => 0,
            KeyIdMode::Index => 1,
            KeyIdMode::Source4 => 2,
            KeyIdMode::Source8 => 3,
        }
    }

    /// Octets of the key identifier field: 0, 1, 5 or 9.
    pub fn key_id_octets(self) -> usize {
        match self {
            KeyIdMode::Implicit => 0,
            KeyIdMode::Index => 1,
            KeyIdMode::Source4 => 5,
            KeyIdMode::Source8 => 9,
        }
    }
}

/// Security control (1) and frame counter (4) octets of the auxiliary security header.
pub const AUX_FIXED_OCTETS: usize = 5;

/// A scenario's `[security]`: the level of every frame, the key identifier mode, and whether
/// the feedback is secured too (by default it is: unsecured feedback lets anyone tell the
/// sensors what to censor).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SecuritySpec {
    #[serde(default)]
    pub level: SecurityLevel,
    #[serde(default)]
    pub key_id_mode: KeyIdMode,
    #[serde(default = "yes")]
    pub secure_feedback: bool,
}

fn yes() -> bool {
    true
}

impl Default for SecuritySpec {
    /// No security (and, once a level is set, the feedback secured too).
    fn default() -> Self {
        SecuritySpec {
            level: SecurityLevel::None,
            key_id_mode: KeyIdMode::Index,
            secure_feedback: true,
        }
    }
}

impl SecuritySpec {
    /// Whether frames are secured at all.
    pub fn is_secured(&self) -> bool {
        self.level != SecurityLevel::None
    }

    /// Octets of the auxiliary security header: 5 + the key identifier (0 unsecured).
    pub fn aux_header_octets(&self) -> usize {
        if self.is_secured() {
            AUX_FIXED_OCTETS + self.key_id_mode.key_id_octets()
        } else {
            0
        }
    }

    /// Octets a secured frame adds to the same unsecured frame: the auxiliary header and MIC.
    pub fn overhead_octets(&self) -> usize {
        self.aux_header_octets() + self.level.mic_octets()
    }

    /// [`SecuritySpec::overhead_octets`] in bits, what every secured data frame adds.
    pub fn overhead_bits(&self) -> u64 {
        8 * self.overhead_octets() as u64
    }

    /// What the step's feedback frame adds (0 when the feedback is left unsecured).
    pub fn feedback_overhead_bits(&self) -> u64 {
        if self.secure_feedback {
            self.overhead_bits()
        } else {
            0
        }
    }
}
