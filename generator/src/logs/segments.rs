//! Splitting the rows into segments, the nominal sample period, yaw unwrapping.

use super::parse::Row;
use std::f64::consts::PI;
use std::ops::Range;

/// A gap larger than this many nominal sample periods starts a new segment.
pub const GAP_PERIODS: f64 = 5.0;

/// Why a segment starts where it does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SegmentStart {
    /// The first data row of the file.
    First,
    /// The `segment` column changed from `previous` to `value`.
    Column { previous: i64, value: i64 },
    /// The time stepped by `gap` seconds, more than [`GAP_PERIODS`] nominal periods.
    Gap { gap: f64 },
}

/// The median of the values (the mean of the two middle ones for an even count), `None` if empty.
pub fn median(values: &[f64]) -> Option<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(v[n / 2]),
        _ => Some(0.5 * (v[n / 2 - 1] + v[n / 2])),
    }
}

/// The median time step between consecutive rows with the same `segment` value (all positive:
/// time increases within a segment), `None` if there is none.
pub(super) fn measured_period(rows: &[Row]) -> Option<f64> {
    let steps: Vec<f64> = rows
        .windows(2)
        .filter(|w| w[0].segment == w[1].segment)
        .map(|w| w[1].t - w[0].t)
        .collect();
    median(&steps)
}

/// Row ranges of the segments and why each starts: a change of the `segment` column, or a time
/// step larger than [`GAP_PERIODS`] × `nominal`.
pub(super) fn split(rows: &[Row], nominal: Option<f64>) -> Vec<(Range<usize>, SegmentStart)> {
    let mut out = Vec::new();
    if rows.is_empty() {
        return out;
    }
    let mut start = 0;
    let mut why = SegmentStart::First;
    for i in 1..rows.len() {
        let (a, b) = (&rows[i - 1], &rows[i]);
        let next = match (a.segment, b.segment) {
            (Some(previous), Some(value)) if previous != value => Some(SegmentStart::Column { previous, value }),
            _ => {
                let gap = b.t - a.t;
                match nominal {
                    Some(p) if gap > GAP_PERIODS * p => Some(SegmentStart::Gap { gap }),
                    _ => None,
                }
            }
        };
        if let Some(next) = next {
            out.push((start..i, why));
            start = i;
            why = next;
        }
    }
    out.push((start..rows.len(), why));
    out
}

/// Remove the 2π jumps of an angle sequence in place, so that consecutive values differ by at
/// most π; returns the number of jumps removed. The first value is kept.
pub fn unwrap_angle(values: &mut [f64]) -> usize {
    let mut wraps = 0;
    let mut offset = 0.0;
    let mut previous_raw = match values.first() {
        Some(&v) => v,
        None => return 0,
    };
    for v in values.iter_mut().skip(1) {
        let raw = *v;
        let step = raw - previous_raw;
        if step.is_finite() && step.abs() > PI {
            offset -= (step / (2.0 * PI)).round() * 2.0 * PI;
            wraps += 1;
        }
        previous_raw = raw;
        *v = raw + offset;
    }
    wraps
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(ts: &[f64], segs: Option<&[i64]>) -> Vec<Row> {
        ts.iter()
            .enumerate()
            .map(|(i, &t)| Row {
                line: i + 2,
                t,
                x: [0.0; 12],
                u: [0.0; 4],
                battery: None,
                segment: segs.map(|s| s[i]),
            })
            .collect()
    }

    #[test]
    fn median_of_odd_even_and_empty() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(&[]), None);
    }

    #[test]
    fn split_by_gap_and_by_column() {
        let r = rows(&[0.0, 0.1, 0.2, 0.8, 0.9], None);
        assert_eq!(measured_period(&r).map(|p| (p * 1e9).round()), Some(1e8));
        let s = split(&r, Some(0.1));
        assert_eq!(s.len(), 2);
        assert_eq!(s[0], (0..3, SegmentStart::First));
        assert_eq!(s[1].0, 3..5);
        assert!(matches!(s[1].1, SegmentStart::Gap { gap } if (gap - 0.6).abs() < 1e-12));
        // 5 periods exactly is not a gap.
        assert_eq!(split(&rows(&[0.0, 1.0, 6.0], None), Some(1.0)).len(), 1);
        // A column change splits even when time resets.
        let r = rows(&[0.0, 0.1, 0.0, 0.1], Some(&[7, 7, 8, 8]));
        let s = split(&r, Some(0.1));
        assert_eq!(s.len(), 2);
        assert_eq!(s[1], (2..4, SegmentStart::Column { previous: 7, value: 8 }));
        // The period is measured within segments only.
        assert_eq!(measured_period(&r).map(|p| (p * 1e9).round()), Some(1e8));
        assert!(split(&[], Some(1.0)).is_empty());
    }

    #[test]
    fn unwrap_removes_two_pi_jumps() {
        let mut v = [3.0, -3.0, -2.9, 3.1, 0.0];
        let wraps = unwrap_angle(&mut v);
        let tau = 2.0 * PI;
        let expect = [3.0, tau - 3.0, tau - 2.9, 3.1, 0.0];
        assert_eq!(wraps, 2);
        for (a, b) in v.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{v:?}");
        }
        // Two turns in one step (a stale yaw during a fast spin) are removed at once.
        let mut v = [0.0, 4.0 * PI + 0.1];
        assert_eq!(unwrap_angle(&mut v), 1);
        assert!((v[1] - 0.1).abs() < 1e-12);
        let mut empty: [f64; 0] = [];
        assert_eq!(unwrap_angle(&mut empty), 0);
    }
}
