//! The run's durable journal: append-only records, each framed as
//! `[len: u32 LE][crc32 of payload: u32 LE][payload: bincode]`, fsynced before
//! the coordinator acts on them.
//!
//! Reading: a torn last record (short frame, or a bad checksum on the very last
//! frame) is dropped with a warning and the file is truncated to the last good
//! record; a bad record followed by more data is corruption, reported with its
//! byte offset.

use std::{
    fs::{File, OpenOptions},
    io::{Read, Seek, SeekFrom, Write},
    path::{Path, PathBuf},
};

use serde::{Deserialize, Serialize};

use crate::evolve::{DecidedIteration, Imported, OpenedIteration, TrialResult};

/// Name of the journal file inside a run directory.
pub const JOURNAL_FILE: &str = "journal.nfj";
const MAX_RECORD: u32 = 64 << 20;

/// One journal record.
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
        /// The result.
        result: TrialResult,
    },
    /// An iteration was decided.
    Decided(DecidedIteration),
}

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
    /// A record in the middle of the file is damaged.
    #[error("journal {path}: corrupt record at byte offset {offset}: {why}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Offset of the record's frame.
        offset: u64,
        /// What is wrong.
        why: String,
    },
    /// The journal does not start with a header.
    #[error("journal {path}: first record is not a run header")]
    NoHeader {
        /// The file.
        path: PathBuf,
    },
}

/// An open journal, positioned for appending.
#[derive(Debug)]
pub struct Journal {
    file: File,
    path: PathBuf,
}

/// What reading an existing journal found.
#[derive(Debug)]
pub struct Replay {
    /// The good records, in order.
    pub records: Vec<Record>,
    /// Set when a torn last record was dropped: its offset and length left.
    pub torn: Option<(u64, u64)>,
}

impl Journal {
    /// The journal path of a run directory.
    #[must_use]
    pub fn path_in(dir: &Path) -> PathBuf {
        dir.join(JOURNAL_FILE)
    }

    /// Creates a new journal (the file must not exist) and writes its header.
    pub fn create(dir: &Path, header: &Record) -> Result<Self, JournalError> {
        let path = Self::path_in(dir);
        let io = |cause| JournalError::Io {
            path: path.clone(),
            cause,
        };
        std::fs::create_dir_all(dir).map_err(io)?;
        let file = OpenOptions::new()
            .create_new(true)
            .append(true)
            .open(&path)
            .map_err(io)?;
        if let Ok(d) = File::open(dir) {
            let _ = d.sync_all();
        }
        let mut j = Self { file, path };
        j.append(header)?;
        Ok(j)
    }

    /// Opens an existing journal, reads every good record, truncates a torn tail.
    pub fn open(dir: &Path) -> Result<(Self, Replay), JournalError> {
        let path = Self::path_in(dir);
        let io = |cause| JournalError::Io {
            path: path.clone(),
            cause,
        };
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(&path)
            .map_err(io)?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io)?;
        let replay = Self::parse(&path, &bytes)?;
        if let Some((offset, _)) = replay.torn {
            file.set_len(offset).map_err(io)?;
            file.sync_all().map_err(io)?;
        }
        file.seek(SeekFrom::End(0)).map_err(io)?;
        if !matches!(replay.records.first(), Some(Record::Header { .. })) {
            return Err(JournalError::NoHeader { path });
        }
        Ok((Self { file, path }, replay))
    }

    /// Parses a journal's bytes.
    pub fn parse(path: &Path, bytes: &[u8]) -> Result<Replay, JournalError> {
        let mut records = Vec::new();
        let mut off = 0usize;
        let total = bytes.len();
        while off < total {
            let corrupt = |why: String| JournalError::Corrupt {
                path: path.to_path_buf(),
                offset: off as u64,
                why,
            };
            if total - off < 8 {
                return Ok(Replay {
                    records,
                    torn: Some((off as u64, (total - off) as u64)),
                });
            }
            let len =
                u32::from_le_bytes([bytes[off], bytes[off + 1], bytes[off + 2], bytes[off + 3]]);
            let crc = u32::from_le_bytes([
                bytes[off + 4],
                bytes[off + 5],
                bytes[off + 6],
                bytes[off + 7],
            ]);
            if len > MAX_RECORD {
                return Err(corrupt(format!("record length {len} exceeds {MAX_RECORD}")));
            }
            let end = off + 8 + len as usize;
            if end > total {
                return Ok(Replay {
                    records,
                    torn: Some((off as u64, (total - off) as u64)),
                });
            }
            let payload = &bytes[off + 8..end];
            let last = end == total;
            if crc32fast::hash(payload) != crc {
                if last {
                    return Ok(Replay {
                        records,
                        torn: Some((off as u64, (total - off) as u64)),
                    });
                }
                return Err(corrupt("checksum mismatch".into()));
            }
            let cfg = bincode::config::standard().with_limit::<{ MAX_RECORD as usize }>();
            let (rec, used): (Record, usize) = bincode::serde::decode_from_slice(payload, cfg)
                .map_err(|e| corrupt(format!("undecodable record: {e}")))?;
            if used != payload.len() {
                return Err(corrupt("trailing bytes inside the record".into()));
            }
            records.push(rec);
            off = end;
        }
        Ok(Replay {
            records,
            torn: None,
        })
    }

    /// Appends records and fsyncs once; returns after they are durable.
    pub fn append_all(&mut self, recs: &[&Record]) -> Result<(), JournalError> {
        let mut buf = Vec::new();
        for rec in recs {
            let payload =
                bincode::serde::encode_to_vec(rec, bincode::config::standard()).map_err(|e| {
                    JournalError::Io {
                        path: self.path.clone(),
                        cause: std::io::Error::other(e.to_string()),
                    }
                })?;
            let len = u32::try_from(payload.len()).unwrap_or(u32::MAX);
            buf.extend_from_slice(&len.to_le_bytes());
            buf.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
            buf.extend_from_slice(&payload);
        }
        let io = |cause| JournalError::Io {
            path: self.path.clone(),
            cause,
        };
        self.file.write_all(&buf).map_err(io)?;
        self.file.sync_data().map_err(io)
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

#[cfg(test)]
mod tests {
    use super::*;

    fn header() -> Record {
        Record::Header {
            experiment_text: "x".into(),
            experiment_hash: 1,
            experiment_json: "{}".into(),
            version: "t".into(),
            imported: Imported::default(),
        }
    }

    fn outcome(i: u64) -> Record {
        Record::Outcome {
            iteration: i,
            trial: 0,
            seed: 9,
            result: TrialResult {
                fell: false,
                x_m: 1.0,
                y_m: 0.0,
                fall_time_s: None,
                sim_time_s: 10.0,
                worker: "w".into(),
            },
        }
    }

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("naofarm-journal-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn round_trip() {
        let d = tmp("rt");
        let mut j = Journal::create(&d, &header()).unwrap();
        j.append(&outcome(0)).unwrap();
        j.append_all(&[&outcome(1), &outcome(2)]).unwrap();
        drop(j);
        let (_, r) = Journal::open(&d).unwrap();
        assert_eq!(r.records.len(), 4);
        assert_eq!(r.records[3], outcome(2));
        assert!(r.torn.is_none());
    }

    #[test]
    fn torn_tail_is_dropped_and_truncated() {
        let d = tmp("torn");
        let mut j = Journal::create(&d, &header()).unwrap();
        j.append(&outcome(0)).unwrap();
        j.append(&outcome(1)).unwrap();
        drop(j);
        let p = Journal::path_in(&d);
        let full = std::fs::read(&p).unwrap();
        for cut in 1..12 {
            std::fs::write(&p, &full[..full.len() - cut]).unwrap();
            let (mut j, r) = Journal::open(&d).unwrap();
            assert_eq!(r.records.len(), 2, "cut {cut}");
            assert!(r.torn.is_some());
            j.append(&outcome(7)).unwrap();
            drop(j);
            let (_, r) = Journal::open(&d).unwrap();
            assert_eq!(r.records.last(), Some(&outcome(7)));
            assert!(r.torn.is_none());
        }
    }

    #[test]
    fn corruption_in_the_middle_names_its_offset() {
        let d = tmp("corrupt");
        let mut j = Journal::create(&d, &header()).unwrap();
        j.append(&outcome(0)).unwrap();
        j.append(&outcome(1)).unwrap();
        drop(j);
        let p = Journal::path_in(&d);
        let mut bytes = std::fs::read(&p).unwrap();
        let (_, r) = Journal::open(&d).unwrap();
        assert_eq!(r.records.len(), 3);
        // Flip a payload byte of the second record.
        let first_len = u32::from_le_bytes(bytes[0..4].try_into().unwrap()) as usize;
        let second = 8 + first_len;
        bytes[second + 9] ^= 0xff;
        std::fs::write(&p, &bytes).unwrap();
        let e = Journal::open(&d).unwrap_err().to_string();
        assert!(e.contains(&format!("byte offset {second}")), "{e}");
    }
}
