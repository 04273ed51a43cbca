//! A sender's frame counter that is never used twice under one key, across crashes and
//! restarts: CCM* with a repeated (key, nonce) pair leaks the XOR of two payloads and lets an
//! attacker forge MICs, and the nonce is (sender, counter, level).
//!
//! Counters are reserved in blocks of [`BLOCK`]: before the first counter of a block is used, the
//! file is rewritten (a temporary file, synced, renamed over the old one, the folder synced) to
//! hold the first counter *after* the block. A restart continues from the file, so a crash at any
//! point loses at most a block's unused counters (of 2³² − 1) and never repeats one; a sync per
//! frame would cost a disk write per message. A missing file is refused ([`CounterStore::open`]):
//! a node started without its counter file under a key it used before would repeat counters, so
//! only [`CounterStore::create`], for a fresh key, starts at 0 (and refuses an existing file).
use std::io::Write;
use std::path::{Path, PathBuf};

/// Counters reserved per sync of the file.
pub const BLOCK: u32 = 4096;

/// The counter 802.15.4 reserves to mean "exhausted" (2006 §7.5.8.2.1: a sender whose counter
/// reached 0xffffffff must stop securing frames under that key).
pub const EXHAUSTED: u32 = u32::MAX;

const HEADER: &str = "hushfuse frame counter v1";

/// A sender's frame counters, kept in a file of its own.
#[derive(Debug)]
pub struct CounterStore {
    path: PathBuf,
    /// The next counter to hand out.
    next: u32,
    /// The first counter not reserved in the file (what a restart would start from).
    reserved_to: u32,
}

impl CounterStore {
    /// A new store at `path`, starting at counter 0 (for a fresh key); refused if the file
    /// exists.
    pub fn create(path: &Path) -> Result<Self, String> {
        if path.exists() {
            return Err(format!(
                "frame counter file {}: exists already (reusing its key from 0 would repeat nonces)",
                path.display()
            ));
        }
        write_atomically(path, 0)?;
        Ok(CounterStore {
            path: path.to_path_buf(),
            next: 0,
            reserved_to: 0,
        })
    }

    /// The store at `path`, continuing after everything it ever reserved. A missing or
    /// malformed file is refused, naming it.
    pub fn open(path: &Path) -> Result<Self, String> {
        let shown = path.display();
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("frame counter file {shown}: cannot read it: {e}"))?;
        let mut lines = text.lines();
        let value = match (lines.next(), lines.next(), lines.next()) {
            (Some(HEADER), Some(v), None) => v.strip_prefix("next_unreserved "),
            _ => None,
        };
        let next: u32 = value.and_then(|v| v.parse().ok()).ok_or_else(|| {
            format!("frame counter file {shown}: not a frame counter file (expected \"{HEADER}\" and \"next_unreserved N\")")
        })?;
        Ok(CounterStore {
            path: path.to_path_buf(),
            next,
            reserved_to: next,
        })
    }

    /// The next frame counter, reserving a block on disk first when the last one is used up.
    /// Errs when the counters under this key are exhausted (a new key is needed) or the file
    /// cannot be written (then no counter is handed out).
    pub fn take(&mut self) -> Result<u32, String> {
        if self.next == EXHAUSTED {
            return Err(format!(
                "frame counter file {}: the counters under this key are used up; make a new key",
                self.path.display()
            ));
        }
        if self.next >= self.reserved_to {
            let to = self.next.saturating_add(BLOCK);
            write_atomically(&self.path, to)?;
            self.reserved_to = to;
        }
        let c = self.next;
        self.next += 1;
        Ok(c)
    }

    /// The counter [`CounterStore::take`] would hand out.
    pub fn peek(&self) -> u32 {
        self.next
    }
}

/// Writes `next_unreserved` to `path` so that a crash leaves the old or the new file, whole.
fn write_atomically(path: &Path, next_unreserved: u32) -> Result<(), String> {
    let shown = path.display();
    let fail = |e: std::io::Error| format!("frame counter file {shown}: cannot write it: {e}");
    // The whole name and ".tmp": files of several ends may share a folder and a stem.
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    {
        let mut options = std::fs::OpenOptions::new();
        options.write(true).create(true).truncate(true);
        #[cfg(unix)]
        std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o600);
        let mut f = options.open(&tmp).map_err(fail)?;
        writeln!(f, "{HEADER}\nnext_unreserved {next_unreserved}").map_err(fail)?;
        f.sync_all().map_err(fail)?;
    }
    std::fs::rename(&tmp, path).map_err(fail)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(fail)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counters strictly increase; a store dropped at any point (a crash: nothing flushed on
    /// drop) and opened again hands out only counters above every one used before.
    #[test]
    fn a_restart_never_repeats_a_counter() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sensor-0.counter");
        let mut used = Vec::new();
        let mut store = CounterStore::create(&path).unwrap();
        for crash_after in [1, BLOCK - 1, 1, BLOCK, BLOCK + 3, 0, 7] {
            for _ in 0..crash_after {
                used.push(store.take().unwrap());
            }
            drop(store);
            store = CounterStore::open(&path).unwrap();
            let max = used.iter().copied().max().unwrap_or(0);
            assert!(
                used.is_empty() || store.peek() > max,
                "{} <= {max}",
                store.peek()
            );
        }
        assert!(used.windows(2).all(|w| w[0] < w[1]));
        assert!(CounterStore::create(&path)
            .unwrap_err()
            .contains("exists already"));
    }

    #[test]
    fn exhaustion_and_bad_files_are_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c");
        std::fs::write(
            &path,
            format!("{HEADER}\nnext_unreserved {}\n", u32::MAX - 2),
        )
        .unwrap();
        let mut s = CounterStore::open(&path).unwrap();
        assert_eq!(s.take().unwrap(), u32::MAX - 2);
        assert_eq!(s.take().unwrap(), u32::MAX - 1);
        let e = s.take().unwrap_err();
        assert!(
            e.contains("used up") && e.contains(&path.display().to_string()),
            "{e}"
        );
        for bad in [
            "",
            "next_unreserved 5\n",
            &format!("{HEADER}\nnext_unreserved -1\n"),
        ] {
            std::fs::write(&path, bad).unwrap();
            let e = CounterStore::open(&path).unwrap_err();
            assert!(e.contains("not a frame counter file"), "{e}");
        }
        let missing = dir.path().join("missing");
        assert!(CounterStore::open(&missing)
            .unwrap_err()
            .contains("cannot read"));
    }
}
