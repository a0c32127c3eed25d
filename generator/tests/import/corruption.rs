//! Corruption is never silent: zero-filled blocks (the usual SD-card fault) inside a ULog are an
//! error that names the byte and what was lost, or with `--partial` an import that says so; NaN
//! in a mapped state field names the topic, field and time.

use super::*;

/// The simulator's states at time `t` (rows are at its own time stamps).
fn sim_row(sim: &FlightLog, t: f64) -> Option<[f64; 12]> {
    for s in &sim.segments {
        if let Some(k) = s.t.iter().position(|x| (x - t).abs() < 1e-9) {
            return Some(s.x[k]);
        }
    }
    None
}

#[test]
fn zero_blocks_in_a_ulog_are_an_error_or_a_partial_import_that_says_what_was_lost() {
    let (_, sim) = simulated();
    let w = px4_ulog(&sim, &Px4Fixture::default());
    let rows: usize = sim.segments.iter().map(|s| s.len()).sum();
    let partial = ImportOptions {
        partial: true,
        ..ImportOptions::default()
    };
    for len in [16usize, 300, 4096] {
        for frac in [0.3, 0.5, 0.7] {
            let at = (w.bytes.len() as f64 * frac) as usize;
            let mut bytes = w.bytes.clone();
            bytes[at..at + len].fill(0);
            let case = format!("{len} zero bytes at byte {at} ({frac})");
            let e = match import_bytes("z.ulg", Some(Format::Ulog), &bytes, &px4(), &ImportOptions::default()) {
                Ok(i) => panic!("{case}: imported without --partial: {}", i.report()),
                Err(e) => e,
            };
            eprintln!("{case}: {e}");
            match import_bytes("z.ulg", Some(Format::Ulog), &bytes, &px4(), &partial) {
                Ok(imported) => {
                    // Not an error: the damage was found, located and its loss stated.
                    assert_eq!(e.kind, ImportErrorKind::Corrupt, "{case}: {e}");
                    assert!(e.message.contains("damaged at byte "), "{case}: {e}");
                    assert!(e.message.contains("pass --partial"), "{case}: {e}");
                    assert_eq!(imported.damaged.len(), 1, "{case}: {:?}", imported.damaged);
                    let d = &imported.damaged[0];
                    assert!(d.contains(" sample"), "{case}: {d}");
                    let from: usize = d["damaged at byte ".len()..]
                        .split(':')
                        .next()
                        .unwrap()
                        .parse()
                        .unwrap();
                    assert!(from <= at && at - from < 200, "{case}: {d}");
                    let csv = imported.to_csv();
                    assert!(csv.contains("# damaged: damaged at byte"), "{case}");
                    assert!(imported.warnings().iter().any(|w| w.contains("lost: `")), "{case}");
                    // What is imported is the flight itself: no row carries a damaged value.
                    let log = parse_log(&csv, "z.csv").unwrap();
                    let got: usize = log.segments.iter().map(|s| s.len()).sum();
                    eprintln!("  --partial: {got} of {rows} rows; {d}");
                    // Lost samples are held (stale bits) or cut out as a gap: never invented.
                    assert!(got <= rows && got + 200 > rows, "{case}: {got} of {rows} rows");
                    // Groups not held (stale bit clear) equal the flight at the row's time; the
                    // Euler rates need a fresh attitude too.
                    let groups: [(u8, std::ops::Range<usize>); 4] = [(1, 0..3), (2, 6..9), (4, 3..6), (12, 9..12)];
                    for r in &imported.rows {
                        let Some(x) = sim_row(&sim, r.t) else {
                            panic!("{case}: a row at t = {} s the flight does not have", r.t)
                        };
                        for (bits, range) in groups.iter().cloned() {
                            if r.stale & bits == 0 {
                                for i in range {
                                    assert!((r.x[i] - x[i]).abs() < 1e-9, "{case}: t = {} state {i}", r.t);
                                }
                            }
                        }
                    }
                }
                Err(p) => {
                    // Still an error with --partial: it names the byte it happened at.
                    eprintln!("  --partial: {p}");
                    assert!(p.message.contains("byte "), "{case}: {p}");
                }
            }
        }
    }
}

#[test]
fn a_zero_block_inside_a_bag_chunk_costs_that_chunk_and_says_so() {
    let (_, sim) = simulated();
    let mut w = dji_bag(&sim, 100);
    w.flush();
    let offsets = w.chunk_offsets.clone();
    let mut bytes = w.finish();
    let whole = import_with("dji-osdk-ros", &bytes, "f.bag", &ImportOptions::default())
        .unwrap()
        .rows();
    // 300 zero bytes in the middle of the third chunk.
    let at = (offsets[2] + offsets[3]) / 2;
    bytes[at..at + 300].fill(0);
    let e = import_with("dji-osdk-ros", &bytes, "z.bag", &ImportOptions::default()).unwrap_err();
    assert_eq!(e.kind, ImportErrorKind::Corrupt);
    assert!(e.message.starts_with("damaged at byte "), "{e}");
    assert!(
        e.message.contains(&format!(
            "the reader resumes at byte {} (inside the chunk at byte {}: ",
            offsets[3], offsets[2]
        )),
        "{e}"
    );
    assert!(e.message.contains("; lost: `/dji_sdk/"), "{e}");
    let partial = ImportOptions {
        partial: true,
        ..ImportOptions::default()
    };
    let profile = Profile::resolve("dji-osdk-ros").unwrap();
    let i = import_bytes("z.bag", Some(Format::Bag), &bytes, &profile, &partial).unwrap();
    assert_eq!(i.damaged.len(), 1, "{:?}", i.damaged);
    // At most the rest of that chunk (100 rows) is lost; the chunks after it are read.
    assert!(
        i.rows.len() < whole && i.rows.len() + 100 >= whole,
        "{} of {whole}",
        i.rows.len()
    );
    assert!(
        i.rows.last().unwrap().t > sim.segments[1].t[0],
        "the last segment is there"
    );
}
