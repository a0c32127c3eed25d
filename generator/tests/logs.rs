//! The flight-log reader: every error names the file, the line and the column; segments, yaw
//! unwrapping and the quality report by hand on tiny logs; no panic on random input; the figures of
//! the shared M100 and RotorPy logs (skipped when `../shared/flights` is absent).

mod shared;
use proptest::prelude::*;
use std::f64::consts::PI;
use std::path::PathBuf;
use uavgen::logs::{parse_log, read_log, FlightLog, LogError, LogErrorKind as K, SegmentStart};

const HEADER: &str = "t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate";

/// A data row: time, a state whose entry i is `s + i`, yaw `yaw`, inputs `u + j`.
fn row(t: f64, s: f64, yaw: f64, u: f64) -> String {
    let mut cells = vec![t.to_string()];
    for i in 0..12 {
        cells.push(if i == 5 {
            yaw.to_string()
        } else {
            (s + i as f64).to_string()
        });
    }
    for j in 0..4 {
        cells.push((u + j as f64).to_string());
    }
    cells.join(",")
}

/// Metadata, the standard header, then rows at 10 Hz with distinct states.
fn log(n: usize) -> String {
    let mut text = format!("# source: test\n# rate_hz: 10\n{HEADER}\n");
    for i in 0..n {
        text.push_str(&row(0.1 * i as f64, i as f64, 0.0, 0.0));
        text.push('\n');
    }
    text
}

fn ok(text: &str) -> FlightLog {
    match parse_log(text, "good.csv") {
        Ok(l) => l,
        Err(e) => panic!("rejected a valid log: {e}\n{text}"),
    }
}

fn err(text: &str) -> LogError {
    match parse_log(text, "bad.csv") {
        Ok(_) => panic!("accepted an invalid log:\n{text}"),
        Err(e) => e,
    }
}

/// The error has this kind, line and column, and its message starts with `bad.csv:LINE: ` and
/// mentions every needle.
fn assert_err(text: &str, kind: K, line: Option<usize>, column: Option<&str>, needles: &[&str]) {
    let e = err(text);
    let msg = e.to_string();
    assert_eq!(e.kind, kind, "{msg}");
    assert_eq!(e.line, line, "{msg}");
    assert_eq!(e.column.as_deref(), column, "{msg}");
    let prefix = match line {
        Some(l) => format!("bad.csv:{l}: "),
        None => "bad.csv: ".to_owned(),
    };
    assert!(msg.starts_with(&prefix), "message must start with '{prefix}': {msg}");
    if let Some(c) = column {
        for name in c.split(',') {
            assert!(
                msg.contains(&format!("`{name}`")),
                "message must name column `{name}`: {msg}"
            );
        }
    }
    for n in needles {
        assert!(msg.contains(n), "message must mention '{n}': {msg}");
    }
}

/// `log(n)` with one cell of data line `k` (0-based) replaced; the file line is k + 4.
fn with_cell(n: usize, k: usize, field: usize, value: &str) -> String {
    let mut lines: Vec<String> = log(n).lines().map(str::to_owned).collect();
    let mut cells: Vec<String> = lines[k + 3].split(',').map(str::to_owned).collect();
    cells[field] = value.to_owned();
    lines[k + 3] = cells.join(",");
    lines.join("\n")
}

// ---------------------------------------------------------------- errors

#[test]
fn empty_file() {
    assert_err("", K::Empty, None, None, &["empty"]);
    assert_err(" \n\r\n  \n", K::Empty, None, None, &["empty"]);
}

#[test]
fn no_header() {
    assert_err(
        "# rate_hz: 30\n# a comment\n\n",
        K::NoHeader,
        None,
        None,
        &["no header"],
    );
    // Data where the header should be.
    let text = format!("# rate_hz: 10\n{}\n", row(0.0, 0.0, 0.0, 0.0));
    assert_err(&text, K::NoHeader, Some(2), None, &["no header", "t,x,y,z"]);
}

#[test]
fn no_data_rows() {
    assert_err(&log(0), K::NoData, Some(3), None, &["no data rows"]);
    let text = format!("{}\n# trailing comment\n\n", log(0));
    assert_err(&text, K::NoData, Some(3), None, &["no data rows"]);
}

#[test]
fn missing_columns_are_all_named() {
    let header = HEADER.replace(",roll,", ",").replace(",u_yaw_rate", "");
    let text = log(2).replace(HEADER, &header);
    assert_err(
        &text,
        K::MissingColumns,
        Some(3),
        Some("roll,u_yaw_rate"),
        &["missing required columns `roll`, `u_yaw_rate`"],
    );
    let text = log(2).replace(HEADER, &HEADER.replace(",yaw,", ",Yaw,"));
    assert_err(
        &text,
        K::MissingColumns,
        Some(3),
        Some("yaw"),
        &["`Yaw`", "case-sensitive"],
    );
    let e = err(&log(2).replace(HEADER, &HEADER.replace(',', ";")));
    assert_eq!((e.kind, e.line), (K::MissingColumns, Some(3)), "{e}");
    assert!(e.to_string().contains("the file must be comma separated"), "{e}");
}

#[test]
fn duplicate_column() {
    let text = format!("{HEADER},pitch\n{},0\n", row(0.0, 0.0, 0.0, 0.0));
    assert_err(
        &text,
        K::DuplicateColumn,
        Some(1),
        Some("pitch"),
        &["twice", "fields 6 and 18"],
    );
}

#[test]
fn non_numeric_cells() {
    // Line 6 = data row 2; field 5 = roll.
    assert_err(
        &with_cell(4, 2, 4, "abc"),
        K::NotNumeric,
        Some(6),
        Some("roll"),
        &["field 5", "`abc` is not a number"],
    );
    assert_err(
        &with_cell(4, 0, 0, ""),
        K::NotNumeric,
        Some(4),
        Some("t"),
        &["is empty"],
    );
    assert_err(
        &with_cell(4, 3, 16, "1,5"),
        K::FieldCount,
        Some(7),
        Some("u_yaw_rate"),
        &["18 fields"],
    );
}

#[test]
fn non_finite_cells() {
    for (value, field, column) in [
        ("NaN", 6, "yaw"),
        ("inf", 13, "u_vz"),
        ("-Infinity", 0, "t"),
        ("1e400", 9, "vz"),
    ] {
        assert_err(
            &with_cell(3, 1, field, value),
            K::NonFinite,
            Some(5),
            Some(column),
            &[
                &format!("field {}", field + 1),
                &format!("`{value}` is not a finite number"),
            ],
        );
    }
}

#[test]
fn wrong_number_of_fields() {
    let mut lines: Vec<String> = log(3).lines().map(str::to_owned).collect();
    let short = lines[5].rsplit_once(',').unwrap().0.to_owned();
    lines[5] = short;
    assert_err(
        &lines.join("\n"),
        K::FieldCount,
        Some(6),
        Some("u_yaw_rate"),
        &["16 fields", "header (line 3) has 17", "field 17"],
    );
    let text = log(3).replace("\n0.1,", "\n0.1,7,"); // one more field on line 5
    assert_err(
        &text,
        K::FieldCount,
        Some(5),
        Some("u_yaw_rate"),
        &["18 fields", "after the last column"],
    );
}

#[test]
fn time_must_increase_within_a_segment() {
    assert_err(
        &with_cell(4, 2, 0, "0.05"),
        K::TimeNotIncreasing,
        Some(6),
        Some("t"),
        &["goes backwards", "line 5", "field 1"],
    );
    assert_err(
        &with_cell(4, 3, 0, "0.2"),
        K::TimeNotIncreasing,
        Some(7),
        Some("t"),
        &["repeats", "line 6"],
    );
}

#[test]
fn bad_segment_cells() {
    let text = format!(
        "{HEADER},segment\n{},0\n{},1.5\n",
        row(0.0, 0.0, 0.0, 0.0),
        row(0.1, 1.0, 0.0, 0.0)
    );
    assert_err(
        &text,
        K::NotNumeric,
        Some(3),
        Some("segment"),
        &["field 18", "not an integer"],
    );
    let text = format!("{HEADER},segment\n{},nan\n", row(0.0, 0.0, 0.0, 0.0));
    assert_err(&text, K::NonFinite, Some(2), Some("segment"), &["not a finite number"]);
}

#[test]
fn bad_rate_metadata() {
    assert_err(
        &log(3).replace("rate_hz: 10", "rate_hz: fast"),
        K::Metadata,
        Some(2),
        None,
        &["`rate_hz: fast`", "positive"],
    );
    assert_err(
        &log(3).replace("rate_hz: 10", "rate_hz: -5"),
        K::Metadata,
        Some(2),
        None,
        &["positive"],
    );
    // 100 Hz claimed, 10 Hz measured: every step is a gap of 10 nominal periods, so every row is
    // its own segment, and the report says why.
    let l = ok(&log(3).replace("rate_hz: 10", "rate_hz: 100"));
    assert_eq!(l.segments.len(), 3);
    let shown = l.report.to_string();
    assert!(
        shown.contains("warning: the metadata says rate_hz 100 but the time column is sampled every 0.1 s"),
        "{shown}"
    );
    assert!(shown.contains("warning: 3 segments have a single row"), "{shown}");
    let text = log(3).replace("# source: test\n", "# rate_hz: 20\n");
    assert_err(
        &text,
        K::Metadata,
        Some(2),
        None,
        &["contradicts `rate_hz: 20` on line 1"],
    );
}

#[test]
fn read_log_names_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.csv");
    let e = read_log(&missing).unwrap_err();
    assert_eq!(e.kind, K::Io);
    assert!(
        e.to_string()
            .starts_with(&format!("{}: cannot read", missing.display())),
        "{e}"
    );

    let latin1 = dir.path().join("latin1.csv");
    let mut bytes = log(2).into_bytes();
    bytes.extend_from_slice(b"# caf\xe9\n");
    std::fs::write(&latin1, bytes).unwrap();
    let e = read_log(&latin1).unwrap_err();
    assert_eq!((e.kind, e.line), (K::Encoding, Some(6)), "{e}");
    assert!(
        e.to_string().starts_with(&format!("{}:6: not UTF-8", latin1.display())),
        "{e}"
    );

    let good = dir.path().join("good.csv");
    std::fs::write(&good, log(5)).unwrap();
    let l = read_log(&good).unwrap();
    assert_eq!(l.source, good.display().to_string());
    assert_eq!(l.rows(), 5);
}

// ---------------------------------------------------------------- accepted input

#[test]
fn a_small_log_reads_into_the_typed_structure() {
    let l = ok(&log(4));
    assert_eq!(
        l.metadata,
        vec![("source".into(), "test".into()), ("rate_hz".into(), "10".into())]
    );
    assert_eq!(l.meta("rate_hz"), Some("10"));
    assert_eq!(l.segments.len(), 1);
    let s = &l.segments[0];
    assert_eq!((s.index, s.first_line, s.len()), (0, 4, 4));
    assert_eq!(s.t[2], 0.2);
    assert_eq!(s.x[2], [2.0, 3.0, 4.0, 5.0, 6.0, 0.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0]);
    assert_eq!(s.u[3], [0.0, 1.0, 2.0, 3.0]);
    assert_eq!(s.battery_voltage, None);
    assert_eq!(l.report.metadata_rate_hz, Some(10.0));
    assert_eq!(l.report.nominal_period, Some(0.1));
    assert!(l.report.warnings().is_empty(), "{:?}", l.report.warnings());
}

#[test]
fn comments_blank_lines_crlf_bom_and_quotes() {
    let text = format!(
        "\u{feff}# rate_hz: 10\r\n\r\n# just a remark, not metadata\r\n\"t\",{}\r\n",
        &HEADER[2..]
    ) + &format!(
        "{}\r\n\r\n# a comment between rows\r\n{}\r\n",
        row(0.0, 0.0, 0.0, 0.0),
        row(0.1, 1.0, 0.0, 0.0)
    ) + &format!("{}\r\n", row(0.2, 2.0, 0.0, 0.0).replace("0.2,", "0.2 , "));
    let l = ok(&text);
    assert_eq!(l.metadata, vec![("rate_hz".into(), "10".into())]);
    assert_eq!(l.rows(), 3);
    assert_eq!(l.segments[0].first_line, 5);
    assert_eq!(l.report.segments[0].last_line, 9);
    // Line numbers count the comment and blank lines.
    let bad = text.replace(&row(0.1, 1.0, 0.0, 0.0), &row(0.1, 1.0, 0.0, 0.0).replace("0.1,", "x,"));
    let e = err(&bad);
    assert_eq!((e.line, e.column.as_deref()), (Some(8), Some("t")), "{e}");
}

#[test]
fn extra_columns_are_ignored() {
    let mut text = format!("# rate_hz: 10\nnote,{HEADER},temperature,battery_voltage\n");
    for i in 0..3 {
        text.push_str(&format!(
            "hello {i},{},n/a,{}\n",
            row(0.1 * i as f64, i as f64, 0.0, 0.0),
            12.0 - i as f64
        ));
    }
    let l = ok(&text);
    let plain = ok(&log(3).replace("# source: test\n", ""));
    assert_eq!(l.segments[0].x, plain.segments[0].x);
    assert_eq!(l.segments[0].u, plain.segments[0].u);
    assert_eq!(l.segments[0].battery_voltage, Some(vec![12.0, 11.0, 10.0]));
}

#[test]
fn column_order_does_not_matter() {
    let plain = ok(&log(5));
    // Reverse the columns of every line after the metadata.
    let reversed: Vec<String> = log(5)
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i < 2 {
                l.to_owned()
            } else {
                l.split(',').rev().collect::<Vec<_>>().join(",")
            }
        })
        .collect();
    let l = ok(&reversed.join("\n"));
    assert_eq!(l.segments, plain.segments);
    // Errors name the column wherever it is: roll is field 13 of 17 when reversed.
    let mut lines = reversed;
    let mut cells: Vec<String> = lines[4].split(',').map(str::to_owned).collect();
    cells[12] = "oops".into();
    lines[4] = cells.join(",");
    let e = err(&lines.join("\n"));
    assert_eq!((e.line, e.column.as_deref()), (Some(5), Some("roll")), "{e}");
    assert!(e.to_string().contains("field 13"), "{e}");
}

// ---------------------------------------------------------------- segments

#[test]
fn segments_by_column_with_time_reset() {
    let mut text = format!("# rate_hz: 10\n{HEADER},segment\n");
    for (i, (t, seg)) in [(0.0, 0), (0.1, 0), (0.2, 0), (0.0, 1), (0.1, 1), (5.0, 3), (5.1, 3)]
        .iter()
        .enumerate()
    {
        text.push_str(&format!("{},{seg}\n", row(*t, i as f64, 0.0, 0.0)));
    }
    let l = ok(&text);
    let lens: Vec<usize> = l.segments.iter().map(|s| s.len()).collect();
    assert_eq!(lens, vec![3, 2, 2]);
    let firsts: Vec<usize> = l.segments.iter().map(|s| s.first_line).collect();
    assert_eq!(firsts, vec![3, 6, 8]);
    let q = &l.report.segments;
    assert_eq!(q[0].start, SegmentStart::First);
    assert_eq!(q[1].start, SegmentStart::Column { previous: 0, value: 1 });
    assert_eq!(q[2].start, SegmentStart::Column { previous: 1, value: 3 });
    assert_eq!((q[2].segment_value, q[2].first_line, q[2].last_line), (Some(3), 8, 9));
    assert_eq!(l.segments[1].t, vec![0.0, 0.1]);
}

#[test]
fn segments_by_time_gap() {
    // 10 Hz; a step of 0.6 s (> 5 periods) splits, one of 0.45 s does not.
    let ts = [0.0, 0.1, 0.2, 0.8, 0.9, 1.35, 1.45];
    let mut text = format!("# rate_hz: 10\n{HEADER}\n");
    for (i, t) in ts.iter().enumerate() {
        text.push_str(&format!("{}\n", row(*t, i as f64, 0.0, 0.0)));
    }
    let l = ok(&text);
    assert_eq!(l.segments.len(), 2);
    assert_eq!(l.segments[1].t, vec![0.8, 0.9, 1.35, 1.45]);
    assert!(matches!(l.report.segments[1].start, SegmentStart::Gap { gap } if (gap - 0.6).abs() < 1e-12));
    let shown = l.report.to_string();
    assert!(
        shown.contains("warning: 1 time gap of more than 5 nominal periods split segments (largest 0.6 s)"),
        "{shown}"
    );
    assert!(shown.contains("segment 1 (lines 6–9, time gap 0.6 s)"), "{shown}");
    // Without rate_hz the nominal period is the median step (0.1 s here): same split.
    let l2 = ok(&text.replace("# rate_hz: 10\n", ""));
    assert_eq!(l2.report.metadata_rate_hz, None);
    assert!((l2.report.nominal_period.unwrap() - 0.1).abs() < 1e-12);
    let ts = |l: &FlightLog| -> Vec<Vec<f64>> { l.segments.iter().map(|s| s.t.clone()).collect() };
    assert_eq!(ts(&l2), ts(&l));
    // The 0.45 s step inside segment 1 is irregular (+350 %).
    let q = &l.report.segments[1];
    assert_eq!(q.irregular_intervals, 1);
    assert!(
        (q.max_period_deviation - 3.5).abs() < 1e-9,
        "{}",
        q.max_period_deviation
    );
}

// ---------------------------------------------------------------- yaw, stale rows, report

#[test]
fn yaw_is_unwrapped_per_segment() {
    // Segment 0: 3.0, -3.0, -2.9, 3.1 → 3.0, 2π−3.0, 2π−2.9, 3.1 (two jumps).
    // Segment 1 starts again from its own first value: -3.1, 3.1 → -3.1, 3.1−2π.
    let mut text = format!("{HEADER},segment\n");
    let data = [
        (0.0, 3.0, 0),
        (0.1, -3.0, 0),
        (0.2, -2.9, 0),
        (0.3, 3.1, 0),
        (0.0, -3.1, 1),
        (0.1, 3.1, 1),
    ];
    for (i, (t, yaw, seg)) in data.iter().enumerate() {
        text.push_str(&format!("{},{seg}\n", row(*t, i as f64, *yaw, 0.0)));
    }
    let l = ok(&text);
    let yaw = |s: usize| -> Vec<f64> { l.segments[s].x.iter().map(|x| x[5]).collect() };
    let close = |a: &[f64], b: &[f64]| a.len() == b.len() && a.iter().zip(b).all(|(p, q)| (p - q).abs() < 1e-12);
    assert!(
        close(&yaw(0), &[3.0, 2.0 * PI - 3.0, 2.0 * PI - 2.9, 3.1]),
        "{:?}",
        yaw(0)
    );
    assert!(close(&yaw(1), &[-3.1, 3.1 - 2.0 * PI]), "{:?}", yaw(1));
    assert_eq!(l.report.segments[0].yaw_wraps, 2);
    assert_eq!(l.report.segments[1].yaw_wraps, 1);
    assert_eq!(l.report.unwrapped_segments(), vec![0, 1]);
    assert!(
        l.report.to_string().contains("yaw: unwrapped in segments 0, 1"),
        "{}",
        l.report
    );
    // Other states are untouched.
    assert_eq!(l.segments[0].x[1][4], 5.0);
}

#[test]
fn stale_rows_are_counted() {
    // States a a a b b c (rows 2, 3 and 5 repeat, longest run 2); inputs change at every row but
    // the third, so only row 2 repeats state and input.
    let states = [0.0, 0.0, 0.0, 1.0, 1.0, 2.0];
    let inputs = [0.0, 0.0, 1.0, 2.0, 3.0, 4.0];
    let mut text = format!("# rate_hz: 10\n{HEADER}\n");
    for i in 0..6 {
        text.push_str(&format!("{}\n", row(0.1 * i as f64, states[i], 0.5, inputs[i])));
    }
    let l = ok(&text);
    let q = &l.report.segments[0];
    assert_eq!((q.stale_states, q.longest_stale_run, q.stale_rows), (3, 2, 1));
    assert_eq!(l.report.stale_states(), 3);
    assert!((l.report.stale_fraction() - 0.5).abs() < 1e-15);
    let shown = l.report.to_string();
    assert!(
        shown.contains(
            "stale: 3 of 6 rows (50.0 %) repeat the previous state (longest run 2); 1 repeat state and input"
        ),
        "{shown}"
    );
}

#[test]
fn rate_mismatch_is_reported() {
    // "10 Hz" but sampled every 0.09 s: +11.1 %.
    let mut text = format!("# rate_hz: 10\n{HEADER}\n");
    for i in 0..5 {
        text.push_str(&format!("{}\n", row(0.09 * i as f64, i as f64, 0.0, 0.0)));
    }
    let l = ok(&text);
    let m = l.report.rate_mismatch().unwrap();
    assert!((m - 1.0 / 9.0).abs() < 1e-9, "{m}");
    let shown = l.report.to_string();
    assert!(
        shown.contains("sampled every 0.09 s (11.11 Hz), metadata rate_hz 10"),
        "{shown}"
    );
    assert!(shown.contains("warning: the metadata says rate_hz 10"), "{shown}");
    assert!(shown.contains("+11.1 %"), "{shown}");
    assert_eq!(l.report.irregular_intervals(), 0);
}

// ---------------------------------------------------------------- never panic

fn line_strategy() -> impl Strategy<Value = String> {
    prop_oneof![
        Just(HEADER.to_owned()),
        Just(format!("{HEADER},segment,battery_voltage")),
        Just("# rate_hz: 30".to_owned()),
        Just("# rate_hz: 0".to_owned()),
        Just(String::new()),
        (-1.0e3f64..1.0e3, -10.0f64..10.0, -4.0f64..4.0, -2.0f64..2.0).prop_map(|(t, s, y, u)| row(t, s, y, u)),
        (0.0f64..1.0, 0i64..3, 10.0f64..13.0).prop_map(|(t, g, b)| format!("{},{g},{b}", row(t, 0.0, 3.0, 0.0))),
        proptest::collection::vec(
            prop_oneof![
                Just("nan"),
                Just(""),
                Just("1e999"),
                Just("-0"),
                Just("x"),
                Just("\""),
                Just("1.5"),
                Just("t")
            ],
            0..20
        )
        .prop_map(|v| v.join(",")),
        "[ -~]{0,60}",
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 500, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let text = String::from_utf8_lossy(&bytes);
        let _ = parse_log(&text, "random.csv");
        let mut with_header = format!("{HEADER}\n");
        with_header.push_str(&text);
        let _ = parse_log(&with_header, "random.csv");
    }

    #[test]
    fn mutated_valid_logs_never_panic(
        steps in proptest::collection::vec(
            (prop_oneof![8 => 0.08f64..0.12, 1 => 0.6f64..2.0], -10.0f64..10.0, 0i64..2, any::<bool>()),
            1..40,
        ),
        cut in any::<prop::sample::Index>(),
        insert in any::<prop::sample::Index>(),
        junk in "[,#\n0-9a-z.\"-]{0,8}",
    ) {
        // A valid log (random steps, some zero; yaw anywhere; segment changes; repeated states),
        // then a random piece of junk inserted and the text cut at a random character.
        let mut text = format!("# rate_hz: 10\n{HEADER},segment\n");
        let (mut t, mut state) = (0.0, 0.0);
        for (dt, yaw, seg, hold) in &steps {
            t += dt;
            if !hold {
                state += 1.0;
            }
            text.push_str(&format!("{},{seg}\n", row(t, state, *yaw, t)));
        }
        // Unmutated, it is valid: one segment, plus one per change of `segment` or gap > 0.5 s.
        let valid = parse_log(&text, "valid.csv");
        prop_assert!(valid.is_ok(), "{}", valid.unwrap_err());
        let splits = steps.windows(2).filter(|w| w[1].2 != w[0].2 || w[1].0 > 0.5).count();
        prop_assert_eq!(valid.unwrap().segments.len(), 1 + splits);
        let chars: Vec<char> = text.chars().collect();
        let at = insert.index(chars.len() + 1);
        let mut mutated: String = chars[..at].iter().collect();
        mutated.push_str(&junk);
        mutated.extend(&chars[at..]);
        let n = mutated.chars().count();
        let mutated: String = mutated.chars().take(cut.index(n + 1).max(n / 2)).collect();
        for candidate in [&text, &mutated] {
            if let Ok(l) = parse_log(candidate, "mutated.csv") {
                prop_assert_eq!(l.rows(), l.report.rows);
                prop_assert_eq!(l.segments.len(), l.report.segments.len());
                for s in &l.segments {
                    prop_assert!(s.t.windows(2).all(|w| w[1] > w[0]));
                    prop_assert!(s.x.windows(2).all(|w| (w[1][5] - w[0][5]).abs() <= PI + 1e-9));
                }
                let _ = l.report.to_string();
            }
        }
    }

    #[test]
    fn random_lines_never_panic(lines in proptest::collection::vec(line_strategy(), 0..30)) {
        let text = lines.join("\n");
        match parse_log(&text, "random.csv") {
            Ok(l) => {
                prop_assert!(!l.segments.is_empty());
                prop_assert_eq!(l.rows(), l.report.rows);
                for s in &l.segments {
                    prop_assert!(s.t.windows(2).all(|w| w[1] > w[0]));
                    prop_assert!(s.x.windows(2).all(|w| (w[1][5] - w[0][5]).abs() <= PI + 1e-9));
                }
                let _ = l.report.to_string();
            }
            Err(e) => {
                let msg = e.to_string();
                prop_assert!(msg.starts_with("random.csv"), "{}", msg);
            }
        }
    }
}

// ---------------------------------------------------------------- the shared logs

fn flights() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/flights");
    if dir.join("m100").is_dir() {
        Some(dir.canonicalize().unwrap_or(dir))
    } else {
        shared::skip(&dir.join("m100"));
        None
    }
}

/// One Markdown table row of figures, printed for docs/logs.md.
fn table_row(name: &str, l: &FlightLog) -> String {
    let r = &l.report;
    format!(
        "| {name} | {} | {} | {} | {:.6} | {} | {} ({:.1} %) | {} | {} | {:.2} % | {} |",
        r.rows,
        r.segments.len(),
        r.metadata_rate_hz.map_or("—".to_owned(), |h| h.to_string()),
        r.measured_period.unwrap_or(f64::NAN),
        r.rate_mismatch()
            .map_or("—".to_owned(), |m| format!("{:+.1} %", 100.0 * m)),
        r.stale_states(),
        100.0 * r.stale_fraction(),
        r.longest_stale_run(),
        r.stale_rows(),
        100.0 * r.max_period_deviation(),
        r.segments.iter().map(|s| s.yaw_wraps).sum::<usize>(),
    )
}

const TABLE_HEAD: &str = "| log | rows | segments | rate_hz | median Δt (s) | rate mismatch | stale states | \
                          longest run | stale rows | max Δt deviation | yaw jumps |\n\
                          | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |";

#[test]
fn m100_logs() {
    let Some(dir) = flights() else { return };
    let mut table = vec![TABLE_HEAD.to_owned()];
    for (run, rows) in [(1, 668), (2, 902), (3, 668), (4, 668), (5, 902), (7, 1801)] {
        let name = format!("m100_run{run}.csv");
        let l = read_log(&dir.join("m100").join(&name)).unwrap_or_else(|e| panic!("{e}"));
        eprintln!("{}\n", l.report);
        table.push(table_row(&name, &l));
        let r = &l.report;
        assert_eq!(l.rows(), rows, "{name}");
        assert_eq!(l.segments.len(), 1, "{name}");
        assert_eq!(r.metadata_rate_hz, Some(30.0));
        assert!(l.meta("source").unwrap().contains("M100"));
        // Sample-and-hold telemetry: about a third of the rows repeat the previous state; the
        // inputs never repeat.
        let f = r.stale_fraction();
        assert!((0.2..0.4).contains(&f), "{name}: stale fraction {f}");
        assert_eq!(r.stale_rows(), 0, "{name}");
        // Runs 1, 3, 4 are sampled every 0.03 s although the header says 30 Hz.
        let m = r.rate_mismatch().unwrap();
        let p = r.measured_period.unwrap();
        if [1, 3, 4].contains(&run) {
            assert!((p - 0.03).abs() < 1e-9, "{name}: {p}");
            assert!((m - 1.0 / 9.0).abs() < 1e-6, "{name}: {m}");
            assert!(r.to_string().contains("warning: the metadata says rate_hz 30"), "{r}");
        } else {
            assert!((p - 1.0 / 30.0).abs() < 1e-6, "{name}: {p}");
            assert!(m.abs() < 1e-5, "{name}: {m}");
        }
        assert_eq!(r.irregular_intervals(), 0, "{name}");
        // Continuous yaw after unwrapping.
        assert!(l.segments[0].x.windows(2).all(|w| (w[1][5] - w[0][5]).abs() <= PI));
    }
    let run1 = read_log(&dir.join("m100/m100_run1.csv")).unwrap();
    assert_eq!(run1.report.stale_states(), 226);
    eprintln!(
        "run 1: {} of {} rows stale ({:.1} %)",
        226,
        668,
        100.0 * run1.report.stale_fraction()
    );
    eprintln!("{}", table.join("\n"));
}

#[test]
fn rotorpy_logs() {
    let Some(dir) = flights() else { return };
    let mut table = vec![TABLE_HEAD.to_owned()];
    for (name, rows, segments) in [
        ("rotorpy_nominal_train.csv", 5400, 1),
        ("rotorpy_nominal_test.csv", 2700, 2),
        ("rotorpy_drag_train.csv", 5400, 1),
        ("rotorpy_drag_test.csv", 2700, 2),
    ] {
        let path = dir.join(name);
        if !path.is_file() {
            shared::skip(&path);
            continue;
        }
        let l = read_log(&path).unwrap_or_else(|e| panic!("{e}"));
        eprintln!("{}\n", l.report);
        table.push(table_row(name, &l));
        assert_eq!(l.rows(), rows, "{name}");
        assert_eq!(l.segments.len(), segments, "{name}");
        assert!(l
            .segments
            .iter()
            .all(|s| s.battery_voltage.as_ref().map(Vec::len) == Some(s.len())));
        assert_eq!(l.report.stale_states(), 0, "{name}");
        if segments == 2 {
            assert_eq!(
                l.report.segments[1].start,
                SegmentStart::Column { previous: 0, value: 1 }
            );
            assert_eq!(l.segments[0].len(), 1800);
        }
        assert!(l
            .segments
            .iter()
            .all(|s| s.x.windows(2).all(|w| (w[1][5] - w[0][5]).abs() <= PI)));
    }
    eprintln!("{}", table.join("\n"));
}
