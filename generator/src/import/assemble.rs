//! From a [`Recording`] and a [`Profile`] to rows of the log contract: frame conversions, the
//! time grid, zero-order hold, stale flags and segments (docs/import.md, "Resampling").
//!
//! - Every channel (position, velocity, attitude, rates, each input, battery) is a time series of
//!   its own topic. Attitudes are converted to ENU/FLU Euler angles per sample and their yaw
//!   unwrapped; vectors and body rates are converted at the row times (they need the attitude).
//! - Rows: without a rate, at the time stamps of the position topic (no resampling at all); with
//!   `rate_hz`, on a uniform grid that starts anew at each segment's start.
//! - Each channel's value at a row time is its latest sample at or before it (zero-order hold; a
//!   sample up to 0.1 % of a row period after a row time counts as at it, for clock rounding).
//!   Nothing is interpolated.
//! - A state channel (position, velocity, attitude, rates) with no new sample since the previous
//!   row is held; the row's `stale` column says which (bit 0 position, 1 velocity, 2 attitude,
//!   3 rates). A row where all four are held repeats the previous row's states exactly: a stale row
//!   of the log contract, which identify, evaluate and diagnose flag (and by default interpolate).
//! - Setpoints are held (that is what an autopilot does with them); NaN setpoint samples (PX4
//!   marks axes it does not command so) are skipped and counted.
//! - A gap in any channel longer than `GAP_PERIODS` of its median period splits the flight:
//!   rows in the gap are not written, and the next rows carry the next `segment` number. A segment
//!   starts when every channel has a sample again.

use super::error::{ImportError, ImportErrorKind};
use super::frames::{self, Body, Inertial};
use super::profile::{Angle, Profile, RatesKind, VectorFrame};
use super::recording::Recording;
use crate::logs::{median, unwrap_angle, GAP_PERIODS};

/// How the rows are timed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GridOptions {
    /// A uniform rate in Hz; `None`: the position topic's own time stamps.
    pub rate_hz: Option<f64>,
}

/// One output row.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub t: f64,
    pub x: [f64; 12],
    pub u: [f64; 4],
    pub battery_voltage: Option<f64>,
    pub segment: usize,
    /// Bit 0 position, 1 velocity, 2 attitude, 3 rates: held (no new sample since the last row).
    pub stale: u8,
}

/// What was done, for the user.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Summary {
    pub rows: usize,
    pub segments: usize,
    /// Rows with a held channel, per state group (position, velocity, attitude, rates).
    pub held: [usize; 4],
    /// Rows whose 12 states all repeat the previous row's.
    pub stale_rows: usize,
    /// NaN setpoint samples skipped, per input.
    pub nan_setpoints: [usize; 4],
    /// The gaps that split the flight: (from, to) in s.
    pub gaps: Vec<(f64, f64)>,
    /// Segments of fewer than two rows, dropped.
    pub dropped_segments: usize,
    /// Samples per second of each state topic (median).
    pub topic_rates: Vec<(String, f64)>,
    /// Other remarks (an optional channel left out, …).
    pub notes: Vec<String>,
}

pub const GROUPS: [&str; 4] = ["position", "velocity", "attitude", "rates"];

/// The most rows a uniform grid may have (a guard against a mistyped `--rate`).
pub const MAX_ROWS: f64 = 2e7;

/// A channel: sample times and per-sample values (already converted where that needs no other
/// channel).
struct Channel<const N: usize> {
    what: String,
    t: Vec<f64>,
    v: Vec<[f64; N]>,
}

impl<const N: usize> Channel<N> {
    fn period(&self) -> Option<f64> {
        let steps: Vec<f64> = self.t.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
        median(&steps)
    }
    /// Gaps longer than `GAP_PERIODS` median periods (and longer than `min`).
    fn gaps(&self, min: f64) -> Vec<(f64, f64)> {
        let Some(p) = self.period() else { return Vec::new() };
        let limit = (GAP_PERIODS * p).max(min);
        self.t
            .windows(2)
            .filter(|w| w[1] - w[0] > limit)
            .map(|w| (w[0], w[1]))
            .collect()
    }
}

/// Zero-order hold cursor over a channel.
struct Hold {
    next: usize,
}

impl Hold {
    /// Index of the latest sample at or before `t + tol`, advancing monotonically.
    fn at<const N: usize>(&mut self, c: &Channel<N>, t: f64, tol: f64) -> Option<usize> {
        while self.next < c.t.len() && c.t[self.next] <= t + tol {
            self.next += 1;
        }
        self.next.checked_sub(1)
    }
}

fn err(file: &str, kind: ImportErrorKind, m: String) -> ImportError {
    ImportError::new(file, kind, m)
}

fn vector(
    rec: &Recording,
    topic: &str,
    fields: &[String; 3],
    scale: f64,
    what: &str,
) -> Result<Channel<3>, ImportError> {
    let names: Vec<&str> = fields.iter().map(String::as_str).collect();
    let (t, cols) = rec.series(topic, &names)?;
    let mut v = Vec::with_capacity(t.len());
    for i in 0..t.len() {
        for (j, c) in cols.iter().enumerate() {
            if !c[i].is_finite() {
                return Err(not_finite(rec, topic, &fields[j], c[i], t[i], i, what));
            }
        }
        v.push([scale * cols[0][i], scale * cols[1][i], scale * cols[2][i]]);
    }
    Ok(Channel {
        what: format!("{what} (`{topic}`)"),
        t: t.to_vec(),
        v,
    })
}

/// A state field that is NaN or infinite: the topic, field, time and sample.
fn not_finite(rec: &Recording, topic: &str, field: &str, v: f64, t: f64, i: usize, what: &str) -> ImportError {
    err(
        &rec.file,
        ImportErrorKind::BadValue,
        format!(
            "topic `{topic}`, field `{field}` is {v} at t = {t} s (sample {i} of the topic): the {what} must be a finite number (a state is never skipped or invented)"
        ),
    )
}

/// Where an attitude (or attitude setpoint) is and how it is logged.
#[derive(Clone, Copy)]
struct AttitudeSpec<'a> {
    topic: &'a str,
    quaternion: Option<&'a [String; 4]>,
    euler: Option<&'a [String; 3]>,
    inertial: Inertial,
    body: Body,
    scale: f64,
    /// Euler angles negated first (a nose-up pitch in ENU/FLU).
    negate: &'a [Angle],
}

/// Attitude samples as ENU/FLU Euler angles with the yaw unwrapped.
/// `state`: the attitude itself, where a NaN is an error (a setpoint's NaN samples are skipped).
fn attitude_channel(rec: &Recording, spec: &AttitudeSpec, what: &str, state: bool) -> Result<Channel<3>, ImportError> {
    let AttitudeSpec {
        topic,
        quaternion,
        euler,
        inertial,
        body,
        scale,
        negate,
    } = *spec;
    let names: Vec<&str> = match (quaternion, euler) {
        (Some(q), _) => q.iter().map(String::as_str).collect(),
        (None, Some(e)) => e.iter().map(String::as_str).collect(),
        (None, None) => unreachable!("validated profile"),
    };
    let (t, cols) = rec.series(topic, &names)?;
    let mut v = Vec::with_capacity(t.len());
    let mut keep_t = Vec::with_capacity(t.len());
    for i in 0..t.len() {
        if state {
            if let Some(j) = (0..names.len()).find(|&j| !cols[j][i].is_finite()) {
                return Err(not_finite(rec, topic, names[j], cols[j][i], t[i], i, what));
            }
        }
        let e = if quaternion.is_some() {
            let q = [cols[0][i], cols[1][i], cols[2][i], cols[3][i]];
            if q.iter().any(|x| x.is_nan()) {
                continue; // an unset setpoint
            }
            frames::quat_to_euler_enu(q, inertial, body).ok_or_else(|| {
                err(
                    &rec.file,
                    ImportErrorKind::BadValue,
                    format!(
                        "topic `{topic}`, sample {i} (t = {} s): quaternion {q:?} has no rotation (zero or not finite)",
                        t[i]
                    ),
                )
            })?
        } else {
            let mut e = [cols[0][i] * scale, cols[1][i] * scale, cols[2][i] * scale];
            for a in negate {
                e[a.index()] = -e[a.index()];
            }
            if e.iter().any(|x| x.is_nan()) {
                continue;
            }
            frames::euler_to_euler_enu(e, inertial, body)
        };
        keep_t.push(t[i]);
        v.push(e);
    }
    let mut yaw: Vec<f64> = v.iter().map(|e| e[2]).collect();
    unwrap_angle(&mut yaw);
    for (e, y) in v.iter_mut().zip(yaw) {
        e[2] = y;
    }
    Ok(Channel {
        what: format!("{what} (`{topic}`)"),
        t: keep_t,
        v,
    })
}

/// Convert a recording into rows of the log contract.
pub fn assemble(rec: &Recording, profile: &Profile, grid: GridOptions) -> Result<(Vec<Row>, Summary), ImportError> {
    let file = rec.file.as_str();
    let (p, v) = (&profile.position, &profile.velocity);
    let position = vector(rec, &p.topic, &p.fields, p.scale, "position")?;
    let velocity = vector(rec, &v.topic, &v.fields, v.scale, "velocity")?;
    let a = &profile.attitude;
    let spec = AttitudeSpec {
        topic: &a.topic,
        quaternion: a.quaternion.as_ref(),
        euler: a.euler.as_ref(),
        inertial: a.inertial,
        body: a.body,
        scale: a.scale,
        negate: &a.negate,
    };
    let attitude = attitude_channel(rec, &spec, "attitude", true)?;
    let r = &profile.rates;
    let mut rates = vector(rec, &r.topic, &r.fields, r.scale, "rates")?;
    for v in rates.v.iter_mut() {
        for a in &r.negate {
            v[a.index()] = -v[a.index()];
        }
    }
    let mut summary = Summary::default();
    let mut inputs: Vec<Channel<1>> = Vec::new();
    for (k, (name, input)) in profile.inputs.all().into_iter().enumerate() {
        let mut c = if let Some(field) = &input.field {
            let (t, cols) = rec.series(&input.topic, &[field.as_str()])?;
            Channel {
                what: format!("{name} (`{}` `{field}`)", input.topic),
                t: t.to_vec(),
                v: cols[0].iter().map(|x| [input.scale * x + input.offset]).collect(),
            }
        } else if let Some(terms) = &input.terms {
            let names: Vec<&str> = terms.iter().map(|t| t.field.as_str()).collect();
            let (t, cols) = rec.series(&input.topic, &names)?;
            let sum = |i: usize| terms.iter().zip(&cols).map(|(term, c)| term.scale * c[i]).sum::<f64>();
            Channel {
                what: format!("{name} (`{}` {})", input.topic, names.join(" + ")),
                t: t.to_vec(),
                v: (0..t.len()).map(|i| [input.scale * sum(i) + input.offset]).collect(),
            }
        } else {
            let (Some(angle), Some(inertial), Some(body)) = (input.angle, input.inertial, input.body) else {
                unreachable!("validated profile");
            };
            let spec = AttitudeSpec {
                topic: &input.topic,
                quaternion: input.quaternion.as_ref(),
                euler: input.euler.as_ref(),
                inertial,
                body,
                scale: input.scale,
                negate: &input.negate,
            };
            let e = attitude_channel(rec, &spec, name, false)?;
            let mut v: Vec<[f64; 1]> = e.v.iter().map(|x| [x[angle.index()]]).collect();
            if angle.index() != 2 {
                // Roll and pitch are not unwrapped; wrap them back into (−π, π].
                v.iter_mut().for_each(|x| x[0] = frames::wrap(x[0]));
            }
            let raw = rec.series.get(&input.topic).map_or(0, |s| s.t.len());
            summary.nan_setpoints[k] += raw - e.t.len();
            Channel {
                what: e.what,
                t: e.t,
                v: v.iter().map(|x| [x[0] + input.offset]).collect(),
            }
        };
        // Skip NaN samples (unset setpoint axes).
        let before = c.t.len();
        let keep: Vec<bool> = c.v.iter().map(|x| !x[0].is_nan()).collect();
        if keep.iter().any(|k| !k) {
            let mut i = 0;
            c.t.retain(|_| {
                i += 1;
                keep[i - 1]
            });
            c.v.retain(|x| !x[0].is_nan());
            summary.nan_setpoints[k] += before - c.t.len();
        }
        if c.t.is_empty() {
            return Err(err(
                file,
                ImportErrorKind::NoData,
                format!(
                    "{}: every sample is NaN (the autopilot did not command this axis in this flight?)",
                    c.what
                ),
            ));
        }
        inputs.push(c);
    }
    // The battery voltage is optional in the log contract: a profile's battery topic that the
    // file does not have is noted, not an error.
    let battery = match &profile.battery_voltage {
        Some(b) => match rec.series(&b.topic, &[b.field.as_str()]) {
            Ok((t, cols)) => {
                // A voltage not measured (NaN) is held as a setpoint is, and counted.
                let keep: Vec<usize> = (0..t.len()).filter(|&i| cols[0][i].is_finite()).collect();
                if keep.len() < t.len() {
                    summary.notes.push(format!(
                        "battery_voltage: {} of {} samples of `{}` `{}` are not finite: skipped (the previous value held)",
                        t.len() - keep.len(),
                        t.len(),
                        b.topic,
                        b.field
                    ));
                }
                if keep.is_empty() {
                    summary.notes.push("no battery_voltage column: no finite sample".into());
                    None
                } else {
                    Some(Channel {
                        what: format!("battery_voltage (`{}` `{}`)", b.topic, b.field),
                        t: keep.iter().map(|&i| t[i]).collect(),
                        v: keep.iter().map(|&i| [b.scale * cols[0][i] + b.offset]).collect(),
                    })
                }
            }
            Err(e) => {
                summary.notes.push(format!("no battery_voltage column: {}", e.message));
                None
            }
        },
        None => None,
    };

    // The grid period (for tolerances and the minimum gap).
    let position_period = position.period();
    let period = match grid.rate_hz {
        Some(hz) => 1.0 / hz,
        None => position_period.unwrap_or(1.0),
    };
    let tol = 1e-3 * period;
    for c in [&position, &velocity, &attitude, &rates] {
        if let Some(p) = c.period() {
            summary.topic_rates.push((c.what.clone(), 1.0 / p));
        }
    }

    // Gaps of every channel, merged; the span every channel covers.
    let mut gaps: Vec<(f64, f64)> = Vec::new();
    let min_gap = GAP_PERIODS * period;
    let mut first = f64::NEG_INFINITY;
    let mut last = f64::INFINITY;
    let mut visit = |t: &[f64], g: Vec<(f64, f64)>| {
        gaps.extend(g);
        if let (Some(a), Some(b)) = (t.first(), t.last()) {
            first = first.max(*a);
            last = last.min(*b);
        }
    };
    for c in [&position, &velocity, &attitude, &rates] {
        visit(&c.t, c.gaps(min_gap));
    }
    for c in &inputs {
        visit(&c.t, c.gaps(min_gap));
    }
    if let Some(b) = &battery {
        visit(&b.t, b.gaps(min_gap));
    }
    if first > last + tol {
        return Err(err(
            file,
            ImportErrorKind::NoData,
            format!(
                "the mapped topics do not overlap in time: the last to start begins at t = {first} s, the first to end stops at t = {last} s"
            ),
        ));
    }
    gaps.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut merged: Vec<(f64, f64)> = Vec::new();
    for g in gaps {
        match merged.last_mut() {
            Some(m) if g.0 <= m.1 => m.1 = m.1.max(g.1),
            _ => merged.push(g),
        }
    }
    merged.retain(|g| g.1 > first && g.0 < last);
    summary.gaps = merged.clone();
    // Segment spans [start, end].
    let mut spans = Vec::new();
    let mut start = first;
    for g in &merged {
        spans.push((start, g.0));
        start = g.1;
    }
    spans.push((start, last));

    let all_t: Vec<&[f64]> = [&position, &velocity, &attitude, &rates]
        .iter()
        .map(|c| c.t.as_slice())
        .chain(inputs.iter().map(|c| c.t.as_slice()))
        .chain(battery.iter().map(|c| c.t.as_slice()))
        .collect();
    let mut rows = Vec::new();
    let mut segment = 0;
    let (mut hp, mut hv, mut ha, mut hr) = (Hold { next: 0 }, Hold { next: 0 }, Hold { next: 0 }, Hold { next: 0 });
    let mut hu: Vec<Hold> = (0..4).map(|_| Hold { next: 0 }).collect();
    let mut hb = Hold { next: 0 };
    for (s, e) in spans {
        // The segment starts when every channel has a sample at or after the span's start.
        let mut a = s;
        for t in &all_t {
            let i = t.partition_point(|x| *x < s - tol);
            match t.get(i) {
                Some(&x) => a = a.max(x),
                None => a = f64::INFINITY,
            }
        }
        if a > e + tol {
            summary.dropped_segments += 1;
            continue;
        }
        let times: Vec<f64> = match grid.rate_hz {
            None => {
                let i0 = position.t.partition_point(|x| *x < a - tol);
                let i1 = position.t.partition_point(|x| *x <= e + tol);
                let mut ts: Vec<f64> = position.t[i0..i1].to_vec();
                ts.dedup();
                ts
            }
            Some(hz) => {
                let n = ((e - a) / period + 1e-6).floor();
                if n > MAX_ROWS {
                    return Err(err(
                        file,
                        ImportErrorKind::NoData,
                        format!(
                            "--rate {hz} Hz over {} s would give {n} rows (at most {MAX_ROWS})",
                            e - a
                        ),
                    ));
                }
                let n = n as usize;
                (0..=n).map(|k| a + k as f64 * period).collect()
            }
        };
        if times.len() < 2 {
            summary.dropped_segments += 1;
            continue;
        }
        let mut previous: Option<[usize; 4]> = None;
        let mut previous_x: Option<[f64; 12]> = None;
        for &t in &times {
            let idx = [
                hp.at(&position, t, tol),
                hv.at(&velocity, t, tol),
                ha.at(&attitude, t, tol),
                hr.at(&rates, t, tol),
            ];
            let Some(idx) = idx.iter().copied().collect::<Option<Vec<usize>>>() else {
                continue; // cannot happen after the start rule; skip rather than invent
            };
            let idx = [idx[0], idx[1], idx[2], idx[3]];
            let mut u = [0.0; 4];
            let mut have_u = true;
            for (k, c) in inputs.iter().enumerate() {
                match hu[k].at(c, t, tol) {
                    Some(i) => u[k] = c.v[i][0],
                    None => have_u = false,
                }
            }
            let bat = battery.as_ref().and_then(|c| hb.at(c, t, tol).map(|i| c.v[i][0]));
            if !have_u || (battery.is_some() && bat.is_none()) {
                continue;
            }
            let euler = attitude.v[idx[2]];
            let p = frames::inertial_to_enu(position.v[idx[0]], inertial(profile.position.frame));
            let v = match profile.velocity.frame {
                VectorFrame::Enu | VectorFrame::Ned => {
                    frames::inertial_to_enu(velocity.v[idx[1]], inertial(profile.velocity.frame))
                }
                VectorFrame::Flu | VectorFrame::Frd => {
                    let body = if profile.velocity.frame == VectorFrame::Flu {
                        Body::Flu
                    } else {
                        Body::Frd
                    };
                    let b = frames::body_to_flu(velocity.v[idx[1]], body);
                    let r = frames::euler_to_matrix(euler);
                    [0, 1, 2].map(|i| (0..3).map(|k| r[i][k] * b[k]).sum::<f64>())
                }
            };
            let w = rates.v[idx[3]];
            let d = match profile.rates.kind {
                RatesKind::Euler => w,
                RatesKind::Body => frames::body_rates_to_euler_rates(frames::body_to_flu(w, profile.rates.body), euler)
                    .ok_or_else(|| {
                        err(
                            file,
                            ImportErrorKind::BadValue,
                            format!(
                                "t = {t} s: pitch is ±90° (gimbal lock): body rates of `{}` have no Euler-angle rates",
                                profile.rates.topic
                            ),
                        )
                    })?,
            };
            let x = [
                p[0], p[1], p[2], euler[0], euler[1], euler[2], v[0], v[1], v[2], d[0], d[1], d[2],
            ];
            let mut stale = 0u8;
            if let Some(prev) = previous {
                for g in 0..4 {
                    if idx[g] == prev[g] {
                        stale |= 1 << g;
                        summary.held[g] += 1;
                    }
                }
            }
            if previous_x == Some(x) {
                summary.stale_rows += 1;
            }
            previous = Some(idx);
            previous_x = Some(x);
            rows.push(Row {
                t,
                x,
                u,
                battery_voltage: bat,
                segment,
                stale,
            });
        }
        segment += 1;
    }
    // Segments that ended with fewer than two rows are not a flight.
    let mut counts = vec![0usize; segment];
    for r in &rows {
        counts[r.segment] += 1;
    }
    let keep: Vec<bool> = counts.iter().map(|c| *c >= 2).collect();
    summary.dropped_segments += counts.iter().filter(|c| **c > 0 && **c < 2).count();
    rows.retain(|r| keep[r.segment]);
    let mut renumber = vec![0usize; segment];
    let mut next = 0;
    for (i, k) in keep.iter().enumerate() {
        if *k {
            renumber[i] = next;
            next += 1;
        }
    }
    for r in rows.iter_mut() {
        r.segment = renumber[r.segment];
    }
    if rows.len() < 2 {
        return Err(err(
            file,
            ImportErrorKind::NoData,
            format!(
                "fewer than two rows where every mapped topic has data (t = {first} … {last} s, {} gap(s))",
                summary.gaps.len()
            ),
        ));
    }
    summary.rows = rows.len();
    summary.segments = next;
    Ok((rows, summary))
}

fn inertial(frame: VectorFrame) -> Inertial {
    match frame {
        VectorFrame::Ned => Inertial::Ned,
        _ => Inertial::Enu,
    }
}
