//! Batch work spread over processes and machines: `--shard K/N`, results as JSON Lines, and the
//! merge of the shards' files into the report one unsharded run gives.
//!
//! The problems of a batch are numbered in a stable order (sorted family, then problem index);
//! problem `i` (0-based) belongs to shard `(i mod N) + 1`, so the N shards hold every problem
//! exactly once. A shard's results file starts with a [`Header`] line (format, what made it, on
//! which machine, when, the shard, the problem set and the settings) followed by one JSON object
//! per problem (and run) carrying its ordinal `i`. [`read_shards`] checks that a set of files is
//! exactly the N shards of one batch: same program, same settings, same problem set, every
//! problem once, none twice.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::SystemError;

/// Format tag of a batch results file's header line.
pub const BATCH_FORMAT: &str = "embodied-batch/1";

/// Settings keys that name input files: they may differ between machines (another mount
/// point) and are not compared when shards are merged.
pub const PATH_SETTINGS: [&str; 5] = ["urdf", "srdf", "problems", "limits", "list"];

/// One shard of a batch: `k` of `n`, 1-based.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// This shard, `1..=n`.
    pub k: usize,
    /// Number of shards.
    pub n: usize,
}

impl Shard {
    /// The whole batch in one shard.
    pub const ALL: Shard = Shard { k: 1, n: 1 };

    /// Whether problem `i` (0-based, in the batch's stable order) belongs to this shard.
    pub fn holds(self, i: usize) -> bool {
        i % self.n == self.k - 1
    }

    /// How many of `total` problems this shard holds.
    pub fn count(self, total: usize) -> usize {
        (0..total).filter(|&i| self.holds(i)).count()
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// `K/N` with `1 <= K <= N`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("expected K/N with 1 <= K <= N (e.g. 2/4), got `{s}`");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let k: usize = k.trim().parse().map_err(|_| bad())?;
        let n: usize = n.trim().parse().map_err(|_| bad())?;
        if n == 0 || k == 0 || k > n {
            return Err(bad());
        }
        Ok(Shard { k, n })
    }
}

/// The machine a batch ran on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Machine {
    /// Host name (`/proc/sys/kernel/hostname`, else `$HOSTNAME`, else `unknown`).
    pub hostname: String,
    /// CPU model (`/proc/cpuinfo`'s `model name`, else `unknown`).
    pub cpu: String,
    /// Cores available to the process.
    pub cores: usize,
}

impl Machine {
    /// This machine.
    pub fn this() -> Self {
        let hostname = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .or_else(|| std::env::var("HOSTNAME").ok().filter(|s| !s.is_empty()))
            .unwrap_or_else(|| "unknown".to_string());
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|text| {
                text.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_string())
            })
            .unwrap_or_else(|| "unknown".to_string());
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        Machine { hostname, cpu, cores }
    }
}

/// The current time in UTC as `YYYY-MM-DDTHH:MM:SSZ`.
pub fn utc_now() -> String {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    utc_from_unix(secs)
}

/// Seconds since 1970-01-01 as `YYYY-MM-DDTHH:MM:SSZ` (proleptic Gregorian calendar).
pub fn utc_from_unix(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    // Civil date from days since the epoch (the era-based algorithm of H. Hinnant).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem % 3600 / 60, rem % 60)
}

/// The first line of a batch results file.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Header {
    /// [`BATCH_FORMAT`].
    pub format: String,
    /// What the lines are: `bench-mbm` or `plan-batch`.
    pub kind: String,
    /// The program (version and commit) that made the file.
    pub generator: String,
    /// Where it ran.
    pub machine: Machine,
    /// When it started (UTC).
    pub date: String,
    /// Which shard the file holds.
    pub shard: Shard,
    /// Problems in the whole batch (all shards).
    pub problems_total: usize,
    /// SHA-256 of the whole batch's problem names in order (`family/index` per line).
    pub problem_set: String,
    /// Lines per problem (repeated runs).
    pub runs: usize,
    /// The settings the batch ran with (the same for every shard, file paths aside).
    pub settings: serde_json::Value,
}

/// SHA-256 (hex) of the problem names, one per line, in the batch's order.
pub fn problem_set_hash<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    use sha2::Digest;
    let mut h = sha2::Sha256::new();
    for n in names {
        h.update(n.as_bytes());
        h.update(b"\n");
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// A results file being written: the header first, then one line per result, each flushed so
/// that a shard stopped midway keeps what it finished.
pub struct JsonlWriter {
    name: PathBuf,
    out: Box<dyn Write>,
}

impl JsonlWriter {
    /// Create `path` (`-`: standard output).
    pub fn create(path: &Path) -> Result<Self, SystemError> {
        let out: Box<dyn Write> = if path == Path::new("-") {
            Box::new(std::io::stdout())
        } else {
            Box::new(std::io::BufWriter::new(std::fs::File::create(path).map_err(|e| SystemError::write(path, e))?))
        };
        Ok(JsonlWriter { name: path.to_path_buf(), out })
    }

    /// A writer into any sink, named `name` in errors.
    pub fn new(name: impl Into<PathBuf>, out: Box<dyn Write>) -> Self {
        JsonlWriter { name: name.into(), out }
    }

    /// Write one JSON object as a line.
    pub fn line<T: Serialize>(&mut self, value: &T) -> Result<(), SystemError> {
        let text = serde_json::to_string(value).map_err(|e| SystemError::Failed(e.to_string()))?;
        let to_err = |e: std::io::Error| {
            if self.name == Path::new("-") { SystemError::Output(e) } else { SystemError::write(&self.name, e) }
        };
        writeln!(self.out, "{text}").map_err(to_err)?;
        self.out.flush().map_err(to_err)
    }
}

/// One result line of a shard file, with where it came from.
#[derive(Debug, Clone)]
pub struct ShardLine {
    /// The problem's ordinal in the whole batch.
    pub i: usize,
    /// The run (0-based) of repeated runs.
    pub run: usize,
    /// The file.
    pub file: PathBuf,
    /// 1-based line number.
    pub line: usize,
    /// The line's JSON object.
    pub value: serde_json::Value,
}

/// The shards of one batch, checked and put back in the batch's order.
#[derive(Debug, Clone)]
pub struct MergedShards {
    /// The first file's header (its shard field is that file's).
    pub header: Header,
    /// Every result line, sorted by (problem, run).
    pub lines: Vec<ShardLine>,
}

fn parse_error(file: &Path, line: usize, message: impl Into<String>) -> SystemError {
    SystemError::Parse { file: file.to_path_buf(), line, column: 1, message: message.into() }
}

fn comparable_settings(settings: &serde_json::Value) -> serde_json::Value {
    let mut s = settings.clone();
    if let Some(map) = s.as_object_mut() {
        for key in PATH_SETTINGS {
            map.remove(key);
        }
    }
    s
}

/// Read shard files and check that together they are exactly one batch: every file has a
/// header of the same kind, program, settings (input paths aside), problem set and shard
/// count; no shard comes twice and none is missing; every line belongs to its file's shard
/// and every (problem, run) of the batch is there once.
pub fn read_shards(files: &[PathBuf]) -> Result<MergedShards, SystemError> {
    if files.is_empty() {
        return Err(SystemError::Usage("no shard files to merge".into()));
    }
    let mut first: Option<(PathBuf, Header)> = None;
    let mut shards_seen: BTreeMap<usize, PathBuf> = BTreeMap::new();
    let mut seen: BTreeMap<(usize, usize), (PathBuf, usize)> = BTreeMap::new();
    let mut lines = Vec::new();
    for file in files {
        let text = crate::error::read_input(file, embodied_models::formats::limits::InputKind::Log)?;
        let mut rows = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let Some((h_at, h_text)) = rows.next() else {
            return Err(parse_error(file, 1, "empty file: expected a batch header line"));
        };
        let header: Header = serde_json::from_str(h_text)
            .map_err(|e| parse_error(file, h_at + 1, format!("expected a batch header ({BATCH_FORMAT}) line: {e}")))?;
        if header.format != BATCH_FORMAT {
            return Err(parse_error(file, h_at + 1, format!("format `{}`, expected `{BATCH_FORMAT}`", header.format)));
        }
        if header.shard.k == 0 || header.shard.k > header.shard.n || header.runs == 0 {
            return Err(parse_error(
                file,
                h_at + 1,
                format!("shard {} with {} runs is not valid", header.shard, header.runs),
            ));
        }
        if let Some((f0, h0)) = &first {
            let differs = |what: &str, a: String, b: String| -> Result<(), SystemError> {
                if a == b {
                    return Ok(());
                }
                Err(SystemError::Usage(format!(
                    "{}: {what} is {b}, but {} has {a}: these files are not shards of one batch",
                    file.display(),
                    f0.display()
                )))
            };
            differs("the kind", h0.kind.clone(), header.kind.clone())?;
            differs("the program", h0.generator.clone(), header.generator.clone())?;
            differs("the shard count", h0.shard.n.to_string(), header.shard.n.to_string())?;
            differs("the problem count", h0.problems_total.to_string(), header.problems_total.to_string())?;
            differs("the problem set (hash)", h0.problem_set.clone(), header.problem_set.clone())?;
            differs("the run count", h0.runs.to_string(), header.runs.to_string())?;
            let (a, b) = (comparable_settings(&h0.settings), comparable_settings(&header.settings));
            if a != b {
                let mut keys = Vec::new();
                if let (Some(ma), Some(mb)) = (a.as_object(), b.as_object()) {
                    for (k, v) in ma {
                        if mb.get(k) != Some(v) {
                            keys.push(format!("{k}: {v} vs {}", mb.get(k).unwrap_or(&serde_json::Value::Null)));
                        }
                    }
                    for k in mb.keys().filter(|k| !ma.contains_key(*k)) {
                        keys.push(format!("{k}: only here"));
                    }
                }
                return Err(SystemError::Usage(format!(
                    "{}: settings differ from {} ({}): these files are not shards of one batch",
                    file.display(),
                    f0.display(),
                    keys.join("; ")
                )));
            }
        }
        if let Some(other) = shards_seen.insert(header.shard.k, file.clone()) {
            return Err(SystemError::Usage(format!(
                "{} and {} are both shard {}: a shard must be merged once",
                other.display(),
                file.display(),
                header.shard
            )));
        }
        for (at, text) in rows {
            let value: serde_json::Value = serde_json::from_str(text)
                .map_err(|e| parse_error(file, at + 1, format!("expected a JSON object per line: {e}")))?;
            let index = |key: &str| -> Result<usize, SystemError> {
                value.get(key).and_then(serde_json::Value::as_u64).map(|v| v as usize).ok_or_else(|| {
                    parse_error(file, at + 1, format!("expected a non-negative integer `{key}` on a result line"))
                })
            };
            let i = index("i")?;
            let run = if header.runs > 1 { index("run")? } else { 0 };
            if i >= header.problems_total || run >= header.runs {
                return Err(parse_error(
                    file,
                    at + 1,
                    format!(
                        "problem {i} run {run} is outside the batch ({} problems, {} runs)",
                        header.problems_total, header.runs
                    ),
                ));
            }
            if !header.shard.holds(i) {
                return Err(parse_error(
                    file,
                    at + 1,
                    format!(
                        "problem {i} belongs to shard {}/{}, not to this file's {}",
                        i % header.shard.n + 1,
                        header.shard.n,
                        header.shard
                    ),
                ));
            }
            if let Some((f, l)) = seen.insert((i, run), (file.clone(), at + 1)) {
                return Err(SystemError::Usage(format!(
                    "{}:{}: problem {i} run {run} is already at {}:{l}: overlapping shards",
                    file.display(),
                    at + 1,
                    f.display()
                )));
            }
            lines.push(ShardLine { i, run, file: file.clone(), line: at + 1, value });
        }
        if first.is_none() {
            first = Some((file.clone(), header));
        }
    }
    let Some((f0, header)) = first else {
        return Err(SystemError::Usage("no shard files to merge".into()));
    };
    let missing: Vec<String> = (1..=header.shard.n)
        .filter(|k| !shards_seen.contains_key(k))
        .map(|k| format!("{k}/{}", header.shard.n))
        .collect();
    if !missing.is_empty() {
        return Err(SystemError::Usage(format!(
            "shard{} {} missing (the batch of {} has {} shards)",
            if missing.len() == 1 { "" } else { "s" },
            missing.join(", "),
            f0.display(),
            header.shard.n
        )));
    }
    for i in 0..header.problems_total {
        for run in 0..header.runs {
            if !seen.contains_key(&(i, run)) {
                let k = i % header.shard.n + 1;
                let file = shards_seen.get(&k).map_or_else(String::new, |f| f.display().to_string());
                return Err(SystemError::Usage(format!(
                    "{file}: problem {i} run {run} of shard {k}/{} is missing (an unfinished shard?)",
                    header.shard.n
                )));
            }
        }
    }
    lines.sort_by_key(|l| (l.i, l.run));
    Ok(MergedShards { header, lines })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_partition_the_problems() {
        for n in 1..6 {
            let mut owners = vec![0; 17];
            for k in 1..=n {
                let s = Shard { k, n };
                let held: Vec<usize> = (0..17).filter(|&i| s.holds(i)).collect();
                assert_eq!(held.len(), s.count(17));
                for i in held {
                    owners[i] += 1;
                }
            }
            assert!(owners.iter().all(|&c| c == 1), "{n}: {owners:?}");
        }
    }

    #[test]
    fn shard_specs_parse_and_refuse() {
        assert_eq!("2/4".parse::<Shard>(), Ok(Shard { k: 2, n: 4 }));
        for bad in ["0/4", "5/4", "1/0", "1", "a/b", "1/2/3", ""] {
            let e = bad.parse::<Shard>().expect_err(bad);
            assert!(e.contains("K/N"), "{e}");
        }
    }

    #[test]
    fn dates_are_utc_calendar_dates() {
        assert_eq!(utc_from_unix(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc_from_unix(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc_from_unix(1_795_000_000), "2026-11-18T11:06:40Z");
    }
}
