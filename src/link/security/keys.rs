//! Keys and frame counters: the 128-bit AES key ([`Key`], never printed), the key file that
//! `center`, `node` and `live` read ([`KeyRing::load`]), and the receiver's replay check
//! ([`FrameCounters`]).
//!
//! # Key file
//!
//! Text, one entry a line, `#` starts a comment; a key is 32 hexadecimal digits (16 octets):
//!
//! ```text
//! # one key for the whole network
//! network 000102030405060708090a0b0c0d0e0f
//! # or, instead or as well, a key per sensor (numbered from 0, as in the scenario): the
//! # frames of that sensor and the feedback to it are secured with it
//! sensor 0 c0c1c2c3c4c5c6c7c8c9cacbcccdcecf
//! ```
//!
//! Every sensor needs a key: its own line, else the network's. The file must be readable by its
//! owner only (as ssh demands of private keys): a file any other user may read or write is
//! refused, as is a malformed line, a key of another length, a sensor named twice.
use std::collections::HashMap;
use std::path::Path;

/// A 128-bit AES key. Its `Debug` hides it, and nothing in hushfuse prints or logs it.
#[derive(Clone, PartialEq, Eq)]
pub struct Key([u8; 16]);

impl Key {
    /// The key of these 16 octets.
    pub fn new(bytes: [u8; 16]) -> Self {
        Key(bytes)
    }

    /// Its octets, for the cipher.
    pub fn bytes(&self) -> &[u8; 16] {
        &self.0
    }

    /// A fresh key from the operating system's randomness (through `rand`'s thread generator, a
    /// cryptographically secure generator seeded by the OS). Not a seeded draw, on purpose: a
    /// key that a scenario's seed reproduces is no key.
    pub fn fresh() -> Self {
        use rand::RngCore;
        let mut b = [0; 16];
        rand::rng().fill_bytes(&mut b);
        Key(b)
    }

    /// Its 32 hexadecimal digits, for writing a key file.
    pub fn to_hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// The key of 32 hexadecimal digits.
    pub fn from_hex(hex: &str) -> Result<Self, String> {
        if hex.len() != 32 {
            return Err(format!(
                "a key is 32 hexadecimal digits (16 octets), this one has {} characters",
                hex.chars().count()
            ));
        }
        let mut b = [0; 16];
        for (i, o) in b.iter_mut().enumerate() {
            let pair = hex
                .get(2 * i..2 * i + 2)
                .ok_or("a key is 32 hexadecimal digits")?;
            *o = u8::from_str_radix(pair, 16)
                .map_err(|_| format!("\"{pair}\" is not two hexadecimal digits"))?;
        }
        Ok(Key(b))
    }
}

impl std::fmt::Debug for Key {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Key(<hidden>)")
    }
}

/// The keys of a run: the network's, and each sensor's own where the file gives one.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct KeyRing {
    pub network: Option<Key>,
    pub sensors: HashMap<usize, Key>,
}

impl KeyRing {
    /// One key for every frame.
    pub fn network(key: Key) -> Self {
        KeyRing {
            network: Some(key),
            sensors: HashMap::new(),
        }
    }

    /// The key of sensor `i`'s frames and of the feedback to it.
    pub fn for_sensor(&self, i: usize) -> Option<&Key> {
        self.sensors.get(&i).or(self.network.as_ref())
    }

    /// The key file at `path`, checked: owner-only permissions, every line well formed, a key
    /// for each of `sensors` sensors. Errors name the file (and the line).
    pub fn load(path: &Path, sensors: usize) -> Result<Self, String> {
        let shown = path.display();
        check_private(path).map_err(|e| format!("key file {shown}: {e}"))?;
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("key file {shown}: cannot read it: {e}"))?;
        let ring = Self::parse(&text).map_err(|e| format!("key file {shown}: {e}"))?;
        if let Some(i) = (0..sensors).find(|&i| ring.for_sensor(i).is_none()) {
            return Err(format!(
                "key file {shown}: no key for sensor {i} (give a `network` key or a `sensor {i}` line)"
            ));
        }
        if let Some(i) = ring.sensors.keys().find(|&&i| i >= sensors) {
            return Err(format!(
                "key file {shown}: sensor {i} does not exist (the scenario has {sensors})"
            ));
        }
        Ok(ring)
    }

    /// The entries of a key file's text (see the module).
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut ring = KeyRing::default();
        for (n, line) in text.lines().enumerate() {
            let at = |e: String| format!("line {}: {e}", n + 1);
            let line = line.split('#').next().unwrap_or("").trim();
            let words: Vec<&str> = line.split_whitespace().collect();
            match words[..] {
                [] => {}
                ["network", hex] => {
                    if ring.network.is_some() {
                        return Err(at("a second `network` key".into()));
                    }
                    ring.network = Some(Key::from_hex(hex).map_err(at)?);
                }
                ["sensor", i, hex] => {
                    let i: usize = i
                        .parse()
                        .map_err(|_| at(format!("\"{i}\" is not a sensor number")))?;
                    let key = Key::from_hex(hex).map_err(at)?;
                    if ring.sensors.insert(i, key).is_some() {
                        return Err(at(format!("sensor {i} named twice")));
                    }
                }
                _ => {
                    return Err(at(
                        "expected `network HEX` or `sensor I HEX` (the line is not shown: it may hold a key)".into(),
                    ))
                }
            }
        }
        if ring.network.is_none() && ring.sensors.is_empty() {
            return Err("no key in it".into());
        }
        Ok(ring)
    }

    /// Writes a fresh network key to `path`, readable and writable by the owner only (the file
    /// is created with mode 0600, never wider).
    pub fn write_fresh(path: &Path) -> Result<Self, String> {
        use std::io::Write;
        #[cfg(unix)]
        use std::os::unix::fs::OpenOptionsExt;
        let key = Key::fresh();
        let mut options = std::fs::OpenOptions::new();
        options.write(true).create_new(true);
        #[cfg(unix)]
        options.mode(0o600);
        let mut f = options
            .open(path)
            .map_err(|e| format!("key file {}: cannot create it: {e}", path.display()))?;
        writeln!(
            f,
            "# hushfuse key file (docs/live.md): keep it private\nnetwork {}",
            key.to_hex()
        )
        .and_then(|_| f.sync_all())
        .map_err(|e| format!("key file {}: cannot write it: {e}", path.display()))?;
        Ok(KeyRing::network(key))
    }
}

/// Refuses a file that users other than its owner may read or write (mode & 077).
fn check_private(path: &Path) -> Result<(), String> {
    let meta = std::fs::metadata(path).map_err(|e| format!("cannot read it: {e}"))?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = meta.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            return Err(format!(
                "permissions {mode:04o} let other users read or change it; \
                 make it private with `chmod 600`"
            ));
        }
    }
    #[cfg(not(unix))]
    let _ = meta;
    Ok(())
}

/// The receiver's replay check (2006 §7.5.8.2.3): per sender, the highest frame counter it
/// accepted; a frame whose counter is not above it is a replay.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FrameCounters {
    last: HashMap<u16, u32>,
}

impl FrameCounters {
    /// Whether a frame from `source` with `counter` is fresh (not a replay).
    pub fn is_fresh(&self, source: u16, counter: u32) -> bool {
        self.last.get(&source).is_none_or(|&l| counter > l)
    }

    /// Records an accepted frame (call after [`FrameCounters::is_fresh`] and the MIC).
    pub fn accept(&mut self, source: u16, counter: u32) {
        let l = self.last.entry(source).or_insert(counter);
        *l = (*l).max(counter);
    }

    /// The highest counter accepted from `source`.
    pub fn last(&self, source: u16) -> Option<u32> {
        self.last.get(&source).copied()
    }

    /// Every sender with the highest counter accepted from it, by address.
    pub fn entries(&self) -> Vec<(u16, u32)> {
        let mut all: Vec<(u16, u32)> = self.last.iter().map(|(&s, &c)| (s, c)).collect();
        all.sort_unstable();
        all
    }
}
