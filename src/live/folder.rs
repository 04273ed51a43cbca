//! The live center's output folder: `estimates.csv` (the lines `hushfuse replay` writes,
//! appended and flushed at every step, so a killed center loses nothing it has shown),
//! `center-journal.txt` (what each step's inbox held, for `--resume`) and `live.log` (who
//! joined, who was silent, what was dropped). The folder is claimed like every run's output
//! ([`crate::output::OutputDir`]: its manifest lists these files) and then written in place.
use super::center::{Center, StepRecord};
use super::driver::{CenterSink, Journal};
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

/// What a live run is, the first line of its journal: a center resumed from the journal must
/// be the same run, and a mismatch is refused naming what differs.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunId {
    pub seed: u64,
    pub trial: usize,
    /// `--loss P`, or the scenario's own link.
    pub link: String,
    /// The labels of the schemes run, in order.
    pub schemes: Vec<String>,
    pub steps: usize,
    /// SHA-256 of the scenario's text as run.
    pub scenario_sha256: String,
}

/// The journal's first line starts so, the [`RunId`] in JSON after it.
const JOURNAL_HEAD: &str = "# hushfuse live journal ";

impl RunId {
    /// The run of `exp` (loaded from `text`), trial `trial`, `--loss` `loss`, schemes
    /// `variants`.
    pub fn new(
        exp: &Experiment,
        text: &str,
        trial: usize,
        loss: Option<f64>,
        variants: &[usize],
    ) -> Self {
        Self {
            seed: exp.seed,
            trial,
            link: loss.map_or("the scenario's".to_string(), |p| format!("--loss {p}")),
            schemes: variants
                .iter()
                .map(|&v| exp.curves[exp.variants[v].curve].label.clone())
                .collect(),
            steps: exp.steps,
            scenario_sha256: output::sha256_hex(text.as_bytes()),
        }
    }

    /// Steps of the whole run (every scheme's).
    fn total_steps(&self) -> usize {
        self.steps.saturating_mul(self.schemes.len())
    }

    /// The journal's first line (with its newline).
    fn head_line(&self) -> String {
        format!(
            "{JOURNAL_HEAD}{}\n",
            serde_json::to_string(self).expect("plain fields")
        )
    }

    /// What differs between the run that wrote a journal (`self`) and this center's (`now`),
    /// in words naming the option; `None`: the same run.
    fn mismatch(&self, now: &RunId) -> Option<String> {
        let differ = |what: &str, a: String, b: String| {
            Some(format!(
                "{what} differs (the journal's: {a}; this center's: {b})"
            ))
        };
        if self.seed != now.seed {
            return differ("seed (--seed)", self.seed.to_string(), now.seed.to_string());
        }
        if self.trial != now.trial {
            return differ(
                "trial (--trial)",
                self.trial.to_string(),
                now.trial.to_string(),
            );
        }
        if self.link != now.link {
            return differ("link", self.link.clone(), now.link.clone());
        }
        if self.schemes != now.schemes {
            return differ(
                "schemes (--scheme)",
                self.schemes.join(", "),
                now.schemes.join(", "),
            );
        }
        if self.steps != now.steps {
            return differ(
                "steps (--steps)",
                self.steps.to_string(),
                now.steps.to_string(),
            );
        }
        if self.scenario_sha256 != now.scenario_sha256 {
            return differ(
                "scenario (SHA-256 of its text)",
                self.scenario_sha256.clone(),
                now.scenario_sha256.clone(),
            );
        }
        None
    }
}

/// The run and the steps of a journal's text; errors name the file and the line.
fn read_journal(
    exp: &Experiment,
    path: &Path,
    text: &str,
) -> Result<(RunId, Vec<super::driver::JournalLine>), String> {
    let name = path.display();
    let (head, rest) = text.split_once('\n').unwrap_or((text, ""));
    let run: RunId = head
        .strip_prefix(JOURNAL_HEAD)
        .and_then(|j| serde_json::from_str(j).ok())
        .ok_or_else(|| {
            format!(
                "{name} line 1: not the head of a hushfuse live journal (`{JOURNAL_HEAD}{{…}}`)"
            )
        })?;
    let steps =
        Journal::read(rest, exp).map_err(|(line, e)| format!("{name} line {}: {e}", line + 1))?;
    Ok((run, steps))
}

impl<'a> LiveFolder<'a> {
    /// Claims `dir` for a new live run `run` of `exp` (scenario `name`, inputs hashed in
    /// `hash`). A folder that holds an interrupted run's journal is refused: it would be lost;
    /// `--resume` continues it.
    pub fn create(
        exp: &'a Experiment,
        dir: &Path,
        hash: &str,
        run: &RunId,
    ) -> Result<Self, String> {
        Self::refuse_interrupted(exp, dir)?;
        let mut out = OutputDir::open(dir)?;
        out.stage(ESTIMATES, replay::estimates_header(exp).as_bytes())?;
        out.stage(JOURNAL, run.head_line().as_bytes())?;
        out.stage(LOG, b"")?;
        out.commit(output::Manifest::new("live", &exp.name, hash), false)?;
        let lock = output::lock_folder(dir, output::LOCK)?;
        Self::open(exp, dir, lock)
    }

    /// Refuses `dir` when it holds an interrupted run's journal: it would be lost (or, for
    /// `hushfuse live`, the key it needs to resume replaced); `--resume` continues it.
    pub fn refuse_interrupted(exp: &Experiment, dir: &Path) -> Result<(), String> {
        if !dir.exists() {
            return Ok(());
        }
        {
            // Looked at under the lock, so a running center's journal is never judged mid-write.
            let _lock = output::lock_folder(dir, output::LOCK)?;
            let path = dir.join(JOURNAL);
            if let Ok(text) = std::fs::read_to_string(&path) {
                let fused = match read_journal(exp, &path, &text) {
                    Ok((old, steps)) if steps.len() >= old.total_steps() => None,
                    Ok((old, steps)) => Some(format!(
                        "{} fused steps of {}",
                        steps.len(),
                        old.total_steps()
                    )),
                    Err(_) if text.lines().count() > 1 => Some("a journal of another run".into()),
                    Err(_) => None,
                };
                if let Some(what) = fused {
                    return Err(format!(
                        "{} holds an interrupted live run ({what}); continue it with `hushfuse center … --resume` on this folder (and its nodes), or choose another --out (or remove the folder) to start afresh",
                        dir.display()
                    ));
                }
            }
        }
        Ok(())
    }

    fn open(exp: &'a Experiment, dir: &Path, lock: output::FolderLock) -> Result<Self, String> {
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
        run: &RunId,
    ) -> Result<(Self, usize), String> {
        // The lock first: a center running in this folder is refused before anything is read
        // or rewritten.
        if !dir.is_dir() {
            return Err(format!(
                "{} is not a folder; --resume needs the folder of an interrupted center",
                dir.display()
            ));
        }
        let lock = output::lock_folder(dir, output::LOCK)?;
        let journal_path = dir.join(JOURNAL);
        let text = std::fs::read_to_string(&journal_path).map_err(|e| {
            format!(
                "cannot read {}: {e}; --resume needs the folder of an interrupted center",
                journal_path.display()
            )
        })?;
        let (old, steps) = read_journal(exp, &journal_path, &text)?;
        if let Some(why) = old.mismatch(run) {
            return Err(format!(
                "{} was written by another run: {why}; resume with the options of that run, or choose another --out",
                journal_path.display()
            ));
        }
        let mut csv = replay::estimates_header(exp);
        let mut journal = run.head_line();
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
        let mut me = Self::open(exp, dir, lock)?;
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

impl CenterSink for LiveFolder<'_> {
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
