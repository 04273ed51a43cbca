//! The live center's output folder: `estimates.csv` (the lines `hushfuse replay` writes,
//! appended and flushed at every step, so a killed center loses nothing it has shown),
//! `center-journal.txt` (what each step's inbox held, for `--resume`) and `live.log` (who
//! joined, who was silent, what was dropped). The folder is claimed like every run's output
//! ([`crate::output::OutputDir`]: its manifest lists these files) and then written in place.
use super::center::{Center, StepRecord};
use super::driver::{Journal, StepSink};
use crate::engine::replay;
use crate::output::{self, OutputDir};
use crate::scenario::experiment::Experiment;
use std::io::Write as _;
use std::path::{Path, PathBuf};

pub const ESTIMATES: &str = "estimates.csv";
pub const JOURNAL: &str = "center-journal.txt";
pub const LOG: &str = "live.log";

/// A live center's folder, open for appending.
pub struct LiveFolder<'a> {
    exp: &'a Experiment,
    dir: PathBuf,
    estimates: std::fs::File,
    journal: Journal,
    log: std::fs::File,
    /// Echo log lines to standard error.
    pub echo: bool,
    /// Held while the center runs: one center per folder.
    _lock: output::FolderLock,
}

fn append(path: &Path) -> Result<std::fs::File, String> {
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|e| format!("cannot open {}: {e}", path.display()))
}

impl<'a> LiveFolder<'a> {
    /// Claims `dir` for a new live run of `exp` (scenario `name`, inputs hashed in `hash`).
    pub fn create(exp: &'a Experiment, dir: &Path, hash: &str) -> Result<Self, String> {
        let mut out = OutputDir::open(dir)?;
        out.stage(ESTIMATES, replay::estimates_header(exp).as_bytes())?;
        out.stage(JOURNAL, b"")?;
        out.stage(LOG, b"")?;
        out.commit(output::Manifest::new("live", &exp.name, hash), false)?;
        Self::open(exp, dir)
    }

    fn open(exp: &'a Experiment, dir: &Path) -> Result<Self, String> {
        let lock = output::lock_folder(dir, output::LOCK)?;
        Ok(Self {
            exp,
            dir: dir.to_path_buf(),
            estimates: append(&dir.join(ESTIMATES))?,
            journal: Journal::append(&dir.join(JOURNAL))?,
            log: append(&dir.join(LOG))?,
            echo: true,
            _lock: lock,
        })
    }

    /// Reopens the folder of an interrupted center and brings `center` to where it was: every
    /// journaled step fused again (the same estimates), `estimates.csv` rewritten from them,
    /// the journal cut after its last whole line. Returns the steps re-fused.
    pub fn resume(
        exp: &'a Experiment,
        dir: &Path,
        center: &mut Center,
    ) -> Result<(Self, usize), String> {
        let journal_path = dir.join(JOURNAL);
        let text = std::fs::read_to_string(&journal_path).map_err(|e| {
            format!(
                "cannot read {}: {e}; --resume needs the folder of an interrupted center",
                journal_path.display()
            )
        })?;
        let steps = Journal::read(&text)?;
        let mut csv = replay::estimates_header(exp);
        let mut journal = String::new();
        for (v, k, inbox, sensors) in steps.iter().cloned() {
            let r = center.fuse(v, k, inbox, sensors).map_err(|e| {
                format!(
                    "{}: {e}; it was written by another run",
                    journal_path.display()
                )
            })?;
            csv.push_str(&row(exp, &r));
            journal.push_str(&Journal::line(&r));
        }
        output::write_file(&dir.join(JOURNAL), journal.as_bytes())?;
        output::write_file(&dir.join(ESTIMATES), csv.as_bytes())?;
        let mut me = Self::open(exp, dir)?;
        me.event(&format!("resumed after {} fused steps", steps.len()));
        Ok((me, steps.len()))
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

fn row(exp: &Experiment, r: &StepRecord) -> String {
    replay::estimates_row(
        exp,
        r.variant,
        r.k,
        &r.estimate,
        r.sensors.iter().map(|s| (s.link, s.bits)),
    )
}

impl StepSink for LiveFolder<'_> {
    fn record(&mut self, _center: &Center, r: &StepRecord) -> Result<(), String> {
        // The journal first: a step in estimates.csv is always one a resumed center has.
        self.journal.write(r)?;
        self.estimates
            .write_all(row(self.exp, r).as_bytes())
            .and_then(|_| self.estimates.flush())
            .map_err(|e| format!("cannot write {ESTIMATES}: {e}"))
    }

    fn event(&mut self, text: &str) {
        if self.echo {
            eprintln!("{text}");
        }
        let _ = writeln!(self.log, "{text}");
        let _ = self.log.flush();
    }
}
