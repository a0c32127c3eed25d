//! Data quality: stale (sample-and-hold) rows overall, per segment and their effect on the
//! residuals, and the log reader's notes.

use super::stats::moments;
use super::{Prepared, WhereInput};
use serde::Serialize;

/// Data-quality figures of the analysed samples.
#[derive(Clone, Debug, Serialize)]
pub struct DataQuality {
    pub rows: usize,
    /// Rows that repeat the previous row's states.
    pub stale_rows: usize,
    pub stale_fraction: f64,
    pub segments: Vec<SegmentStale>,
    /// Per channel, the one-step RMSE on stale and on fresh rows.
    pub stale_split: Vec<StaleSplit>,
    /// The log reader's findings (gaps, irregular sampling), verbatim.
    pub notes: Vec<String>,
}

/// Stale rows of one segment.
#[derive(Clone, Debug, Serialize)]
pub struct SegmentStale {
    pub segment: usize,
    /// Index of its first sample.
    pub start: usize,
    pub rows: usize,
    pub stale_rows: usize,
    pub stale_fraction: f64,
}

/// One channel's one-step residual on stale vs fresh rows.
#[derive(Clone, Debug, Serialize)]
pub struct StaleSplit {
    pub channel: String,
    pub n_stale: usize,
    pub n_fresh: usize,
    pub rmse_stale: Option<f64>,
    pub rmse_fresh: Option<f64>,
}

fn fraction(a: usize, b: usize) -> f64 {
    if b == 0 {
        0.0
    } else {
        a as f64 / b as f64
    }
}

pub(crate) fn quality(input: &WhereInput, p: &Prepared) -> DataQuality {
    let stale_rows = input.stale.iter().filter(|s| **s).count();
    let segments = p
        .ranges
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let stale = input.stale[r.clone()].iter().filter(|s| **s).count();
            SegmentStale {
                segment: i,
                start: r.start,
                rows: r.len(),
                stale_rows: stale,
                stale_fraction: fraction(stale, r.len()),
            }
        })
        .collect();
    let stale_split = input
        .channels
        .iter()
        .zip(&input.one_step)
        .map(|(name, r)| {
            let part = |want: bool| moments(r.iter().zip(&input.stale).filter(|(_, s)| **s == want).map(|(v, _)| *v));
            let (s, f) = (part(true), part(false));
            StaleSplit {
                channel: name.clone(),
                n_stale: s.n,
                n_fresh: f.n,
                rmse_stale: (s.n > 0).then_some(s.rms),
                rmse_fresh: (f.n > 0).then_some(f.rms),
            }
        })
        .collect();
    DataQuality {
        rows: input.len(),
        stale_rows,
        stale_fraction: fraction(stale_rows, input.len()),
        segments,
        stale_split,
        notes: input.quality_notes.clone(),
    }
}
