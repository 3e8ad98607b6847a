//! Journal format tests: round trip, torn tails, damage, format 1, and a
//! property test of random damage.

use proptest::prelude::*;

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
        measurement: Measurement {
            fell: false,
            x_m: 1.0 + i as f64,
            y_m: 0.0,
            fall_time_s: None,
            sim_time_s: 10.0,
        },
        worker: "w".into(),
    }
}

use crate::test_dir::{test_dir, TestDir};

fn tmp(name: &str) -> TestDir {
    test_dir(&format!("journal-{name}"))
}

/// A journal of a header and `n` outcomes; returns its directory and bytes.
fn journal(name: &str, n: u64) -> (TestDir, Vec<u8>) {
    let d = tmp(name);
    let mut j = Journal::create(&d, &header()).unwrap();
    for i in 0..n {
        j.append(&outcome(i)).unwrap();
    }
    drop(j);
    let bytes = std::fs::read(Journal::path_in(&d)).unwrap();
    (d, bytes)
}

fn reopen(d: &Path) -> Result<(Journal, Scan), JournalError> {
    let s = Journal::read(d)?;
    let j = Journal::open_for_append(d, &s)?;
    Ok((j, s))
}

#[test]
fn round_trip_starts_with_the_format_header() {
    let (d, bytes) = journal("rt", 3);
    assert_eq!(&bytes[..8], b"NAOFARMJ");
    assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), FORMAT);
    let (mut j, s) = reopen(&d).unwrap();
    assert_eq!(s.records.len(), 4);
    assert_eq!(s.tail, Tail::Clean);
    j.append_all(&[&outcome(7), &outcome(8)]).unwrap();
    drop(j);
    let s = Journal::read(&d).unwrap();
    assert_eq!(s.records().last(), Some(&outcome(8)));
}

#[test]
fn a_torn_tail_is_saved_beside_the_journal_then_cut() {
    let (d, full) = journal("torn", 2);
    let p = Journal::path_in(&d);
    let last = Journal::read(&d).unwrap().records[2].0 as usize;
    for keep in [1usize, 3, 5, 11, 12, 20] {
        let cut = last + keep.min(full.len() - last - 1);
        std::fs::write(&p, &full[..cut]).unwrap();
        let s = Journal::read(&d).unwrap();
        assert_eq!(
            s.tail,
            Tail::Torn {
                offset: last as u64,
                len: (cut - last) as u64
            },
            "keep {keep}"
        );
        let (mut j, _) = reopen(&d).unwrap();
        let side = d.join(format!("{JOURNAL_FILE}.torn-{last}"));
        assert_eq!(std::fs::read(&side).unwrap(), full[last..cut]);
        std::fs::remove_file(&side).unwrap();
        j.append(&outcome(7)).unwrap();
        drop(j);
        let s = Journal::read(&d).unwrap();
        assert_eq!(s.tail, Tail::Clean);
        assert_eq!(s.records().last(), Some(&outcome(7)));
        assert_eq!(s.records.len(), 3);
    }
}

#[test]
fn a_zero_filled_tail_is_torn_and_zeros_before_valid_frames_are_damage() {
    let (d, full) = journal("zeros", 3);
    let p = Journal::path_in(&d);
    let mut zeros = full.clone();
    zeros.extend(std::iter::repeat_n(0u8, 300));
    std::fs::write(&p, &zeros).unwrap();
    assert!(matches!(
        Journal::read(&d).unwrap().tail,
        Tail::Torn { len: 300, .. }
    ));
    // Zeros over the second record, with valid records after them.
    let s = scan(&p, &full).unwrap();
    let (a, b) = (s.records[1].0 as usize, s.records[2].0 as usize);
    let mut mid = full.clone();
    mid[a..b].fill(0);
    std::fs::write(&p, &mid).unwrap();
    let s = Journal::read(&d).unwrap();
    assert_eq!(
        s.tail,
        Tail::Damaged {
            offset: a as u64,
            why: "no frame mark".into(),
            valid_after: 2
        }
    );
    let e = Journal::open_for_append(&d, &s).unwrap_err().to_string();
    assert!(
        e.contains(&format!("offset {a}")) && e.contains("2 valid record") && e.contains("salvage"),
        "{e}"
    );
    assert_eq!(std::fs::read(&p).unwrap(), mid, "nothing was changed");
}

#[test]
fn a_flipped_length_bit_is_damage_not_a_torn_tail() {
    let (d, full) = journal("len", 5);
    let p = Journal::path_in(&d);
    let s = scan(&p, &full).unwrap();
    let third = s.records[2].0 as usize;
    for bit in 0..32 {
        let mut b = full.clone();
        b[third + 4 + bit / 8] ^= 1 << (bit % 8);
        std::fs::write(&p, &b).unwrap();
        let s = Journal::read(&d).unwrap();
        assert_eq!(s.records.len(), 2, "bit {bit}");
        assert!(
            matches!(s.tail, Tail::Damaged { offset, .. } if offset == third as u64),
            "bit {bit}: {:?}",
            s.tail
        );
        assert!(Journal::open_for_append(&d, &s).is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b);
    }
}

#[test]
fn a_format_one_journal_reads_and_is_migrated_keeping_the_old_file() {
    let d = tmp("v1");
    std::fs::create_dir_all(&d).unwrap();
    let recs = [header(), outcome(0), outcome(1)];
    let v1 = encode_v1(&recs.iter().collect::<Vec<_>>());
    let p = Journal::path_in(&d);
    std::fs::write(&p, &v1).unwrap();
    let s = Journal::read(&d).unwrap();
    assert_eq!(s.format, 1);
    assert_eq!(s.records(), recs.to_vec());
    let (mut j, _) = reopen(&d).unwrap();
    j.append(&outcome(2)).unwrap();
    drop(j);
    assert_eq!(
        std::fs::read(d.join("journal.nfj.v1")).unwrap(),
        v1,
        "the old bytes are kept"
    );
    let s = Journal::read(&d).unwrap();
    assert_eq!(s.format, 2);
    assert_eq!(s.records.len(), 4);
}

#[test]
fn an_unknown_format_names_both_versions() {
    let d = tmp("fmt");
    std::fs::create_dir_all(&d).unwrap();
    let mut h = b"NAOFARMJ".to_vec();
    h.extend_from_slice(&9u32.to_le_bytes());
    let crc = crc32fast::hash(&h);
    h.extend_from_slice(&crc.to_le_bytes());
    std::fs::write(Journal::path_in(&d), &h).unwrap();
    let e = Journal::read(&d).unwrap_err().to_string();
    assert!(
        e.contains("format 9") && e.contains("formats 1 and 2"),
        "{e}"
    );
    std::fs::write(Journal::path_in(&d), b"hello world, not a journal").unwrap();
    let e = Journal::read(&d).unwrap_err().to_string();
    assert!(e.contains("not a naofarm journal"), "{e}");
}

#[test]
fn salvage_scan_recovers_every_valid_frame_around_damage() {
    let (d, full) = journal("salv", 6);
    let p = Journal::path_in(&d);
    let s = scan(&p, &full).unwrap();
    let third = s.records[3].0 as usize;
    let mut b = full.clone();
    b[third + 14] ^= 0x55;
    let r = scan_all(&p, &b).unwrap();
    assert_eq!(r.records.len(), 6, "all but the damaged one");
    assert_eq!(r.skipped.len(), 1);
    assert_eq!(r.skipped[0].0, third as u64);
}

/// What a damaged copy must satisfy (the property of the durability issue).
fn check_damage(full: &[u8], damaged: &[u8], first_bad: usize, true_tear: bool, name: &str) {
    let d = tmp(name);
    std::fs::create_dir_all(&d).unwrap();
    let p = Journal::path_in(&d);
    std::fs::write(&p, damaged).unwrap();
    let original = scan(&p, full).unwrap();
    // Records wholly before the damage.
    let before: Vec<Record> = original
        .records
        .iter()
        .enumerate()
        .filter(|(i, _)| {
            let end = original
                .records
                .get(i + 1)
                .map_or(full.len(), |(o, _)| *o as usize);
            end <= first_bad
        })
        .map(|(_, (_, r))| r.clone())
        .collect();
    match Journal::read(&d) {
        Err(_) => assert!(
            first_bad < FILE_HEADER + 12,
            "only a damaged file header or first frame is unreadable"
        ),
        Ok(s) => {
            let got = s.records();
            assert!(
                got.len() >= before.len() && got[..before.len()] == before[..],
                "kept every record before the damage"
            );
            let opened = Journal::open_for_append(&d, &s);
            let now = std::fs::read(&p).unwrap();
            match (&s.tail, opened) {
                (Tail::Torn { offset, .. }, Ok(_)) => {
                    assert!(
                        *offset as usize <= first_bad || !true_tear,
                        "a tear is found where it is"
                    );
                    assert_eq!(now, damaged[..*offset as usize]);
                    let side =
                        std::fs::read(d.join(format!("{JOURNAL_FILE}.torn-{offset}"))).unwrap();
                    assert_eq!(side, damaged[*offset as usize..]);
                }
                (Tail::Clean, Ok(_)) => assert_eq!(now, damaged),
                (Tail::Damaged { .. }, Err(_)) => assert_eq!(now, damaged, "bytes unchanged"),
                (t, o) => panic!("tail {t:?} opened {:?}", o.is_ok()),
            }
            if let Ok(r) = scan_all(&p, damaged) {
                let all: Vec<Record> = r.records.into_iter().map(|(_, r)| r).collect();
                assert!(
                    all.len() >= before.len() && all[..before.len()] == before[..],
                    "salvage keeps the records before the damage"
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&d);
}

fn reference() -> Vec<u8> {
    let (_, b) = journal("prop-ref", 12);
    b
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_damage_never_panics_or_loses_what_came_before(
        kind in 0u8..4, at in 0usize..10_000, bit in 0u8..8, len in 1usize..200, seed in any::<u64>()
    ) {
        let full = reference();
        let at = at % full.len();
        let mut b = full.clone();
        let (first_bad, tear) = match kind {
            0 => { b[at] ^= 1 << bit; (at, false) }
            1 => { b.truncate(at.max(1)); (at.max(1), true) }
            2 => { let end = (at + len).min(b.len()); b[at..end].fill(0); (at, false) }
            _ => {
                b.truncate(at.max(1));
                let mut x = seed;
                for _ in 0..len { x = crate::evolve::mix(x); b.push(x as u8); }
                (at.max(1), false)
            }
        };
        check_damage(&full, &b, first_bad, tear, &format!("prop-{kind}-{at}-{bit}-{len}"));
    }
}

#[test]
fn a_failed_append_leaves_the_file_as_it_was_and_poisons_the_journal() {
    let (d, _) = journal("full", 2);
    let s = Journal::read(&d).unwrap();
    let mut j = Journal::open_for_append(&d, &s).unwrap();
    let before = std::fs::read(Journal::path_in(&d)).unwrap();
    // Replace the file handle with a read-only one: the write fails.
    j.file = File::open(Journal::path_in(&d)).unwrap();
    assert!(j.append(&outcome(5)).is_err());
    assert!(matches!(
        j.append(&outcome(6)),
        Err(JournalError::Poisoned { .. })
    ));
    assert_eq!(std::fs::read(Journal::path_in(&d)).unwrap(), before);
}

fn structured_bytes() -> impl Strategy<Value = Vec<u8>> {
    // Raw bytes, or a valid file header followed by mark-led fragments, so the
    // reader's frame paths are reached, not only the format check.
    let raw = proptest::collection::vec(any::<u8>(), 0..600);
    let framed = proptest::collection::vec(
        (any::<bool>(), proptest::collection::vec(any::<u8>(), 0..80)),
        0..12,
    )
    .prop_map(|parts| {
        let mut b = file_header();
        for (mark, body) in parts {
            if mark {
                b.extend_from_slice(MARK);
            }
            b.extend_from_slice(&body);
        }
        b
    });
    prop_oneof![raw, framed]
}

proptest! {
    // PROPTEST_CASES raises the count (the closing note's fuzz run used 100000).
    #![proptest_config(ProptestConfig::default())]

    #[test]
    fn arbitrary_bytes_never_panic_the_reader(bytes in structured_bytes()) {
        let p = Path::new("fuzz.nfj");
        if let Ok(s) = scan(p, &bytes) {
            let _ = s.damage(p);
        }
        let _ = scan_all(p, &bytes);
    }
}

#[test]
fn wall_time_sums_each_session_from_its_start_to_its_last_mark() {
    let clock = |unix_ms, start| Record::Clock { unix_ms, start };
    assert_eq!(WallTime::of(&[header(), outcome(0)]), None);
    let records = [
        header(),
        clock(1_000, true),
        outcome(0),
        clock(4_000, false),
        clock(6_000, false),
        // A crash, then a resume an hour later: the gap is not served time.
        clock(3_606_000, true),
        clock(3_607_500, false),
        // A clock set back counts nothing.
        clock(3_600_000, false),
        clock(3_601_000, false),
    ];
    let w = WallTime::of(&records).expect("marks");
    assert_eq!(w.sessions, 2);
    assert_eq!(w.served_ms, 5_000 + 1_500 + 1_000);
    assert_eq!((w.first_ms, w.last_ms), (1_000, 3_601_000));
}
