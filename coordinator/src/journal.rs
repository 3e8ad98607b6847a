//! The run's durable journal: append-only records, fsynced before the
//! coordinator acts on them, in a format that tells an interrupted append from
//! damage.
//!
//! Format 2 (written): a 16-byte file header `NAOFARMJ`, the format version
//! (u32 LE) and a CRC32 of those 12 bytes; then frames
//! `[mark "NFR2"][len: u32 LE, ≥ 1][crc32 of len ‖ payload: u32 LE][payload: bincode]`.
//! Format 1 (read, and migrated on resume): frames `[len][crc32 of payload][payload]`
//! with no file header.
//!
//! Reading never writes. A *torn tail* is what one interrupted append leaves: a
//! partial last frame (or a run of zeros) at the end with nothing after it
//! that parses as a frame. [`Journal::open_for_append`] saves those bytes
//! beside the journal (`journal.nfj.torn-<offset>`, fsynced) before cutting
//! them. Any other damage is [`Tail::Damaged`]: nothing is cut, the caller
//! refuses, and [`scan_all`] (for `journal salvage`) recovers every valid
//! frame around it. Must not: truncate or rewrite a byte that is not a saved
//! torn tail, or touch a journal whose run lock it does not hold.

use std::{
    fs::{File, OpenOptions},
    io::Write,
    path::{Path, PathBuf},
};

use serde::{Deserialize, Serialize};

use crate::evolve::{DecidedIteration, Imported, Measurement, OpenedIteration};

/// Name of the journal file inside a run directory.
pub const JOURNAL_FILE: &str = "journal.nfj";
/// The format this build writes.
pub const FORMAT: u32 = 2;
const MAGIC: &[u8; 8] = b"NAOFARMJ";
const FILE_HEADER: usize = 16;
const MARK: &[u8; 4] = b"NFR2";
const FRAME_HEAD_V2: usize = 12;
const FRAME_HEAD_V1: usize = 8;
const MAX_RECORD: u32 = 64 << 20;

/// One journal record. New variants go at the end (bincode numbers them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Record {
    /// First record: what the run is.
    Header {
        /// The experiment file's text, as given.
        experiment_text: String,
        /// FNV-1a hash of that text.
        experiment_hash: u64,
        /// The effective experiment (after command-line overrides), as JSON.
        experiment_json: String,
        /// naofarm version that wrote the journal.
        version: String,
        /// History imported from an earlier run.
        imported: Imported,
    },
    /// An iteration was opened with this p and these seeds.
    Opened(OpenedIteration),
    /// A trial's outcome was accepted.
    Outcome {
        /// Iteration.
        iteration: u64,
        /// Trial index.
        trial: u32,
        /// Seed.
        seed: u64,
        /// What the trial measured.
        measurement: Measurement,
        /// The worker that ran it (informative only; never influences decisions).
        worker: String,
    },
    /// An iteration was decided.
    Decided(DecidedIteration),
    /// A trial could not be run by a worker (journaled so a resume keeps the count).
    Failed {
        /// Iteration.
        iteration: u64,
        /// Trial index.
        trial: u32,
        /// The worker that failed it.
        worker: String,
        /// Its reason.
        reason: String,
    },
    /// The run was extended to this many iterations (by the naofarm `version`).
    Extended {
        /// The new planned total.
        iterations: u64,
        /// naofarm version that extended it.
        version: String,
    },
    /// The run's identity: a UUID given when its directory was created (or
    /// when a journal older than run ids was first resumed). Every key and
    /// message of the run carries it; the experiment's name is a label.
    Identity {
        /// The run id (a UUID, hyphenated).
        id: String,
    },
    /// A control action taken while the run was served (kept across resumes).
    Control {
        /// What was done.
        action: Control,
        /// Who asked (a free-text label: user and host of `naofarm ctl`, or `--priority`).
        by: String,
    },
    /// A wall-clock mark, for the run's wall time only (never read by a
    /// decision): one when a coordinator starts serving the run (`start`),
    /// and one with every batch of decided iterations (in the same fsync).
    Clock {
        /// Milliseconds since the Unix epoch (0 if the clock is before it).
        unix_ms: u64,
        /// Whether a serving session starts here.
        start: bool,
    },
    /// The fingerprint of the workers whose outcomes make this run's history
    /// (their build and their host's maths, `worker::fingerprint`): pinned by
    /// the first worker the run grants trials to, journaled before any
    /// outcome of it; from then on only workers of this fingerprint serve it.
    Fingerprint {
        /// The fingerprint.
        fingerprint: u64,
        /// naofarm version of the worker that pinned it.
        version: String,
        /// That worker's id.
        worker: String,
    },
}

impl Record {
    /// A [`Record::Clock`] of now.
    #[must_use]
    pub fn clock_now(start: bool) -> Self {
        let unix_ms = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX));
        Self::Clock { unix_ms, start }
    }
}

/// A run's wall time, from its [`Record::Clock`] marks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WallTime {
    /// Milliseconds served: over each session, from its start to its last mark.
    pub served_ms: u64,
    /// Serving sessions (the first and each resume).
    pub sessions: u32,
    /// The first session's start (ms since the Unix epoch).
    pub first_ms: u64,
    /// The last mark (ms since the Unix epoch).
    pub last_ms: u64,
}

impl WallTime {
    /// The wall time the clock marks in `records` give; `None` when they have
    /// none (a journal written before naofarm journaled them).
    #[must_use]
    pub fn of(records: &[Record]) -> Option<Self> {
        let mut w: Option<Self> = None;
        for r in records {
            let &Record::Clock { unix_ms, start } = r else {
                continue;
            };
            let w = w.get_or_insert(Self {
                first_ms: unix_ms,
                ..Self::default()
            });
            if start || w.sessions == 0 {
                w.sessions += 1;
            } else {
                // A clock set back mid-session counts nothing rather than wrapping.
                w.served_ms += unix_ms.saturating_sub(w.last_ms);
            }
            w.last_ms = unix_ms;
        }
        w
    }
}

pub use protocol::wire::Control;

/// Journal failures.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    /// File-system error.
    #[error("journal {path}: {cause}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        cause: std::io::Error,
    },
    /// Damage that is not a torn tail: nothing was changed.
    #[error(
        "journal {path}: damaged frame at byte offset {offset} ({why}); {valid_after} valid record(s) lie after it. \
         Nothing was changed. Recover with `naofarm journal salvage {dir} --out NEW_DIR`"
    )]
    Damaged {
        /// The file.
        path: PathBuf,
        /// Its run directory.
        dir: String,
        /// Offset of the first bad frame.
        offset: u64,
        /// What is wrong there.
        why: String,
        /// Valid records found after it.
        valid_after: usize,
    },
    /// The file is not a naofarm journal, or of a format this build cannot read.
    #[error("journal {path}: {why}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What was found.
        why: String,
    },
    /// The journal does not start with a header.
    #[error("journal {path}: first record is not a run header")]
    NoHeader {
        /// The file.
        path: PathBuf,
    },
    /// An earlier append failed: the journal takes no more records.
    #[error("journal {path}: an earlier write failed; the run must stop and be resumed")]
    Poisoned {
        /// The file.
        path: PathBuf,
    },
}

/// How a journal's bytes end.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Tail {
    /// Every byte belongs to a valid frame.
    Clean,
    /// An interrupted append: `len` bytes at `offset`, nothing valid after them.
    Torn {
        /// Where the partial frame starts.
        offset: u64,
        /// Bytes from there to the end.
        len: u64,
    },
    /// Damage with the first bad frame at `offset`.
    Damaged {
        /// Offset of the first bad frame.
        offset: u64,
        /// What is wrong there.
        why: String,
        /// Valid records that parse after it.
        valid_after: usize,
    },
}

/// What reading a journal found.
#[derive(Debug, Clone)]
pub struct Scan {
    /// The format of the file (1 or 2).
    pub format: u32,
    /// The valid records before the first bad frame, with their offsets.
    pub records: Vec<(u64, Record)>,
    /// How the file ends.
    pub tail: Tail,
    /// The file's length.
    pub bytes: u64,
}

impl Scan {
    /// The records without their offsets.
    #[must_use]
    pub fn records(&self) -> Vec<Record> {
        self.records.iter().map(|(_, r)| r.clone()).collect()
    }

    /// The error to report when the tail is damage (None otherwise).
    #[must_use]
    pub fn damage(&self, path: &Path) -> Option<JournalError> {
        match &self.tail {
            Tail::Damaged {
                offset,
                why,
                valid_after,
            } => Some(JournalError::Damaged {
                path: path.to_path_buf(),
                dir: path
                    .parent()
                    .map_or_else(|| ".".into(), |d| d.display().to_string()),
                offset: *offset,
                why: why.clone(),
                valid_after: *valid_after,
            }),
            _ => None,
        }
    }
}

/// An open journal, positioned for appending. The caller holds the run lock.
#[derive(Debug)]
pub struct Journal {
    file: File,
    path: PathBuf,
    len: u64,
    poisoned: bool,
}

fn decode(payload: &[u8]) -> Result<Record, String> {
    let cfg = bincode::config::standard().with_limit::<{ MAX_RECORD as usize }>();
    let (rec, used): (Record, usize) =
        bincode::serde::decode_from_slice(payload, cfg).map_err(|e| format!("undecodable: {e}"))?;
    if used != payload.len() {
        return Err("trailing bytes inside the record".into());
    }
    Ok(rec)
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    let s = b.get(at..at + 4)?;
    Some(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
}

/// One frame at `off`: Ok((record, end)), or why it is not a frame, with
/// `true` when the frame runs past the end of the bytes (a cut-short append).
fn frame_at(format: u32, b: &[u8], off: usize) -> Result<(Record, usize), (String, bool)> {
    let rest = &b[off..];
    let head = if format == 1 {
        FRAME_HEAD_V1
    } else {
        FRAME_HEAD_V2
    };
    if format != 1 {
        let n = rest.len().min(4);
        if rest[..n] != MARK[..n] {
            return Err(("no frame mark".into(), false));
        }
    }
    if rest.len() < head {
        return Err(("a frame header cut short".into(), true));
    }
    let (len, crc) = if format == 1 {
        (u32_at(rest, 0), u32_at(rest, 4))
    } else {
        (u32_at(rest, 4), u32_at(rest, 8))
    };
    let (Some(len), Some(crc)) = (len, crc) else {
        return Err(("a frame header cut short".into(), true));
    };
    if len == 0 || len > MAX_RECORD {
        return Err((
            format!("record length {len} outside 1..={MAX_RECORD}"),
            false,
        ));
    }
    let end = head + len as usize;
    if end > rest.len() {
        return Err((
            format!("record length {len} runs past the end of the file"),
            true,
        ));
    }
    let payload = &rest[head..end];
    let sum = if format == 1 {
        crc32fast::hash(payload)
    } else {
        let mut h = crc32fast::Hasher::new();
        h.update(&rest[4..8]);
        h.update(payload);
        h.finalize()
    };
    if sum != crc {
        return Err(("checksum mismatch".into(), false));
    }
    let rec = decode(payload).map_err(|e| (e, false))?;
    Ok((rec, off + end))
}

/// The format of a journal's bytes and where its frames start.
fn format_of(path: &Path, b: &[u8]) -> Result<(u32, usize), JournalError> {
    let bad = |why: String| JournalError::Format {
        path: path.to_path_buf(),
        why,
    };
    if b.len() < MAGIC.len() && MAGIC.starts_with(b) {
        return Err(bad("the file header is cut short".into()));
    }
    if b.len() >= MAGIC.len() && &b[..MAGIC.len()] == MAGIC {
        if b.len() < FILE_HEADER {
            return Err(bad("the file header is cut short".into()));
        }
        let version = u32_at(b, 8).unwrap_or(0);
        let crc = u32_at(b, 12).unwrap_or(0);
        if crc32fast::hash(&b[..12]) != crc {
            return Err(bad("the file header's checksum does not match".into()));
        }
        if version != FORMAT {
            return Err(bad(format!(
                "journal format {version}; this naofarm ({}) reads formats 1 and {FORMAT}",
                env!("CARGO_PKG_VERSION")
            )));
        }
        return Ok((FORMAT, FILE_HEADER));
    }
    if b.is_empty() {
        return Err(bad("the file is empty".into()));
    }
    // Format 1 starts with a valid frame holding a header record.
    match frame_at(1, b, 0) {
        Ok((Record::Header { .. }, _)) => Ok((1, 0)),
        _ => Err(bad(
            "not a naofarm journal (no `NAOFARMJ` header, no format-1 record)".into(),
        )),
    }
}

/// The first offset after `from` where a valid frame starts.
fn next_frame_after(format: u32, b: &[u8], from: usize) -> Option<usize> {
    (from + 1..b.len()).find(|&at| {
        let candidate = if format == 1 {
            // A record is never empty and starts with its variant index.
            u32_at(b, at).is_some_and(|l| {
                l >= 1 && (l as usize) <= b.len().saturating_sub(at + FRAME_HEAD_V1)
            }) && b.get(at + FRAME_HEAD_V1).is_some_and(|v| *v <= 4)
        } else {
            b[at..].starts_with(MARK)
        };
        candidate && frame_at(format, b, at).is_ok()
    })
}

/// Reads a journal's bytes without changing anything.
pub fn scan(path: &Path, b: &[u8]) -> Result<Scan, JournalError> {
    let (format, mut off) = format_of(path, b)?;
    let mut records = Vec::new();
    let tail = loop {
        if off == b.len() {
            break Tail::Clean;
        }
        match frame_at(format, b, off) {
            Ok((rec, end)) => {
                records.push((off as u64, rec));
                off = end;
            }
            Err((why, cut_short)) => {
                let nothing_after = next_frame_after(format, b, off).is_none();
                let zeros = b[off..].iter().all(|x| *x == 0);
                break if nothing_after && (cut_short || zeros) {
                    Tail::Torn {
                        offset: off as u64,
                        len: (b.len() - off) as u64,
                    }
                } else {
                    // Count the records a resynchronising reader recovers.
                    let valid_after = resync(format, b, off).len();
                    Tail::Damaged {
                        offset: off as u64,
                        why,
                        valid_after,
                    }
                };
            }
        }
    };
    Ok(Scan {
        format,
        records,
        tail,
        bytes: b.len() as u64,
    })
}

/// Every valid frame from `off` on, re-synchronising past damaged spans.
fn resync(format: u32, b: &[u8], mut off: usize) -> Vec<(u64, Record)> {
    let mut out = Vec::new();
    while off < b.len() {
        match frame_at(format, b, off) {
            Ok((rec, end)) => {
                out.push((off as u64, rec));
                off = end;
            }
            Err(_) => match next_frame_after(format, b, off) {
                Some(next) => off = next,
                None => break,
            },
        }
    }
    out
}

/// What [`scan_all`] recovered: every valid record and the spans it skipped.
#[derive(Debug, Clone)]
pub struct Recovered {
    /// The format of the file.
    pub format: u32,
    /// Every valid record, in file order, with its offset.
    pub records: Vec<(u64, Record)>,
    /// Skipped byte spans (offset, length).
    pub skipped: Vec<(u64, u64)>,
}

/// Reads every valid frame of a journal, re-synchronising past damage.
pub fn scan_all(path: &Path, b: &[u8]) -> Result<Recovered, JournalError> {
    let (format, start) = format_of(path, b)?;
    let records = resync(format, b, start);
    let mut skipped = Vec::new();
    let mut at = start as u64;
    for (i, (off, _)) in records.iter().enumerate() {
        if *off > at {
            skipped.push((at, off - at));
        }
        let end = records.get(i + 1).map_or(b.len() as u64, |(next, _)| *next);
        // The frame's own end: re-parse to learn it.
        let own_end = frame_at(format, b, *off as usize)
            .map_or(end, |(_, e)| e as u64)
            .min(end);
        at = own_end;
    }
    if (b.len() as u64) > at {
        skipped.push((at, b.len() as u64 - at));
    }
    Ok(Recovered {
        format,
        records,
        skipped,
    })
}

fn encode_frame(rec: &Record, buf: &mut Vec<u8>) -> Result<(), String> {
    let payload = bincode::serde::encode_to_vec(rec, bincode::config::standard())
        .map_err(|e| e.to_string())?;
    let len = u32::try_from(payload.len())
        .ok()
        .filter(|l| *l <= MAX_RECORD)
        .ok_or_else(|| format!("a record of {} bytes is too large", payload.len()))?;
    let mut h = crc32fast::Hasher::new();
    h.update(&len.to_le_bytes());
    h.update(&payload);
    buf.extend_from_slice(MARK);
    buf.extend_from_slice(&len.to_le_bytes());
    buf.extend_from_slice(&h.finalize().to_le_bytes());
    buf.extend_from_slice(&payload);
    Ok(())
}

fn file_header() -> Vec<u8> {
    let mut h = MAGIC.to_vec();
    h.extend_from_slice(&FORMAT.to_le_bytes());
    let crc = crc32fast::hash(&h);
    h.extend_from_slice(&crc.to_le_bytes());
    h
}

fn sync_dir(dir: &Path) -> std::io::Result<()> {
    File::open(dir)?.sync_all()
}

/// Writes `bytes` to a new file (never over an existing one) and fsyncs it and its directory.
fn write_new(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut f = OpenOptions::new().write(true).create_new(true).open(path)?;
    f.write_all(bytes)?;
    f.sync_all()?;
    if let Some(d) = path.parent() {
        sync_dir(d)?;
    }
    Ok(())
}

impl Journal {
    /// The journal path of a run directory.
    #[must_use]
    pub fn path_in(dir: &Path) -> PathBuf {
        dir.join(JOURNAL_FILE)
    }

    /// Reads a run directory's journal without changing anything.
    pub fn read(dir: &Path) -> Result<Scan, JournalError> {
        scan_file(&Self::path_in(dir))
    }

    /// Creates a new journal (the file must not exist) with its header record.
    pub fn create(dir: &Path, header: &Record) -> Result<Self, JournalError> {
        let path = Self::path_in(dir);
        let io = |cause| JournalError::Io {
            path: path.clone(),
            cause,
        };
        std::fs::create_dir_all(dir).map_err(io)?;
        let mut bytes = file_header();
        encode_frame(header, &mut bytes).map_err(|e| io(std::io::Error::other(e)))?;
        write_new(&path, &bytes).map_err(io)?;
        Self::append_handle(&path, bytes.len() as u64)
    }

    fn append_handle(path: &Path, len: u64) -> Result<Self, JournalError> {
        let file = OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|cause| JournalError::Io {
                path: path.to_path_buf(),
                cause,
            })?;
        Ok(Self {
            file,
            path: path.to_path_buf(),
            len,
            poisoned: false,
        })
    }

    /// Opens a scanned journal for appending (the caller holds the run lock and
    /// has checked the header). A torn tail is saved beside the file, then cut;
    /// a format-1 journal is migrated to format 2 first (the old file is kept as
    /// `journal.nfj.v1`). Damage is refused without a write.
    pub fn open_for_append(dir: &Path, scan: &Scan) -> Result<Self, JournalError> {
        let path = Self::path_in(dir);
        if let Some(e) = scan.damage(&path) {
            return Err(e);
        }
        let io = |cause| JournalError::Io {
            path: path.clone(),
            cause,
        };
        let bytes = std::fs::read(&path).map_err(io)?;
        if bytes.len() as u64 != scan.bytes {
            return Err(io(std::io::Error::other(
                "the journal changed while it was being opened (is another coordinator writing it?)",
            )));
        }
        if scan.format == 1 {
            return Self::migrate(dir, scan);
        }
        if let Tail::Torn { offset, len } = scan.tail {
            let side = dir.join(format!("{JOURNAL_FILE}.torn-{offset}"));
            let torn = &bytes[usize::try_from(offset).unwrap_or(bytes.len())..];
            match std::fs::read(&side) {
                Ok(existing) if existing == torn => {}
                Ok(_) => {
                    return Err(io(std::io::Error::other(format!(
                        "{} exists with other bytes; move it away to resume",
                        side.display()
                    ))))
                }
                Err(_) => write_new(&side, torn).map_err(io)?,
            }
            let f = OpenOptions::new().write(true).open(&path).map_err(io)?;
            f.set_len(offset).map_err(io)?;
            f.sync_all().map_err(io)?;
            tracing::warn!(journal = %path.display(), offset, len, saved = %side.display(),
                "cut a torn last record (an interrupted append); its bytes are saved");
            return Self::append_handle(&path, offset);
        }
        Self::append_handle(&path, scan.bytes)
    }

    /// Rewrites a format-1 journal's valid records as format 2 in a new file,
    /// checks it, keeps the old file as `journal.nfj.v1`, and puts the new one in place.
    fn migrate(dir: &Path, scan: &Scan) -> Result<Self, JournalError> {
        let path = Self::path_in(dir);
        let io = |cause| JournalError::Io {
            path: path.clone(),
            cause,
        };
        let old = dir.join(format!("{JOURNAL_FILE}.v1"));
        let new = dir.join(format!("{JOURNAL_FILE}.v2-migrating"));
        if old.exists() {
            return Err(io(std::io::Error::other(format!(
                "{} exists; move it away to migrate this format-1 journal",
                old.display()
            ))));
        }
        let _ = std::fs::remove_file(&new); // our own unfinished migration, never user data
        let mut bytes = file_header();
        for (_, r) in &scan.records {
            encode_frame(r, &mut bytes).map_err(|e| io(std::io::Error::other(e)))?;
        }
        write_new(&new, &bytes).map_err(io)?;
        let check = scan_file(&new)?;
        if check.tail != Tail::Clean || check.records() != scan.records() {
            return Err(io(std::io::Error::other(
                "the migrated journal does not read back the same records; nothing was changed",
            )));
        }
        std::fs::rename(&path, &old).map_err(io)?;
        std::fs::rename(&new, &path).map_err(io)?;
        sync_dir(dir).map_err(io)?;
        tracing::warn!(journal = %path.display(), kept = %old.display(), "migrated a format-1 journal to format 2");
        Self::append_handle(&path, bytes.len() as u64)
    }

    /// Appends records and fsyncs once; returns after they are durable. A failed
    /// write or fsync leaves the file as it was (the partial frame is cut) and
    /// poisons the journal: the run must stop.
    pub fn append_all(&mut self, recs: &[&Record]) -> Result<(), JournalError> {
        if self.poisoned {
            return Err(JournalError::Poisoned {
                path: self.path.clone(),
            });
        }
        let mut buf = Vec::new();
        for rec in recs {
            encode_frame(rec, &mut buf).map_err(|e| JournalError::Io {
                path: self.path.clone(),
                cause: std::io::Error::other(e),
            })?;
        }
        let written = fault_hook(buf.len())
            .and_then(|()| self.file.write_all(&buf))
            .and_then(|()| self.file.sync_data());
        if let Err(cause) = written {
            self.poisoned = true;
            // Only our own partial frame is cut, never an earlier byte.
            let _ = self
                .file
                .set_len(self.len)
                .and_then(|()| self.file.sync_data());
            return Err(JournalError::Io {
                path: self.path.clone(),
                cause,
            });
        }
        self.len += buf.len() as u64;
        Ok(())
    }

    /// Appends one record and fsyncs.
    pub fn append(&mut self, rec: &Record) -> Result<(), JournalError> {
        self.append_all(&[rec])
    }

    /// The journal's path.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Test hook: `NAOFARM_FAULT_JOURNAL_FULL_AFTER=N` makes every append after the
/// first N bytes fail as a full disk would (run time, never a second build;
/// read once per process).
fn fault_hook(adding: usize) -> std::io::Result<()> {
    use std::sync::atomic::{AtomicU64, Ordering};
    static WRITTEN: AtomicU64 = AtomicU64::new(0);
    static LIMIT: std::sync::OnceLock<Option<u64>> = std::sync::OnceLock::new();
    let limit = LIMIT.get_or_init(|| {
        std::env::var("NAOFARM_FAULT_JOURNAL_FULL_AFTER")
            .ok()
            .and_then(|v| v.parse::<u64>().ok())
    });
    let Some(limit) = *limit else {
        return Ok(());
    };
    let total = WRITTEN.fetch_add(adding as u64, Ordering::SeqCst) + adding as u64;
    if total > limit {
        return Err(std::io::Error::new(
            std::io::ErrorKind::StorageFull,
            "no space left on device (NAOFARM_FAULT_JOURNAL_FULL_AFTER)",
        ));
    }
    Ok(())
}

/// Scans a journal file by path.
pub fn scan_file(path: &Path) -> Result<Scan, JournalError> {
    let bytes = std::fs::read(path).map_err(|cause| JournalError::Io {
        path: path.to_path_buf(),
        cause,
    })?;
    scan(path, &bytes)
}

/// Test support: the format-1 encoding of records (the format before 0.2).
#[doc(hidden)]
#[must_use]
pub fn encode_v1(records: &[&Record]) -> Vec<u8> {
    let mut buf = Vec::new();
    for rec in records {
        let payload =
            bincode::serde::encode_to_vec(rec, bincode::config::standard()).unwrap_or_default();
        let len = u32::try_from(payload.len()).unwrap_or(u32::MAX);
        buf.extend_from_slice(&len.to_le_bytes());
        buf.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
        buf.extend_from_slice(&payload);
    }
    buf
}

#[cfg(test)]
mod tests;
