//! The training envelope: held-out samples are scored only where the training data have been.
//!
//! A base model is not trustworthy outside the states it was identified and is diagnosed on; its
//! errors there (a thrust direction that is right at small tilt and wrong at large tilt, say)
//! correlate with some candidates' regressors and would decide the held-out score by accident. So a
//! held-out sample counts in the candidates' scores only if each of these lies within the 0.1 … 99.9 %
//! quantiles of the training samples: tilt acos(cos φ cos θ), horizontal speed, vz, roll_rate,
//! pitch_rate, yaw_rate and the four inputs. (The shrink figures use every held-out sample.)

use super::data::SegData;

/// The variables that define the envelope at one sample.
fn variables(x: &[f64; 12], u: &[f64; 4]) -> [f64; 10] {
    let tilt = (x[3].cos() * x[4].cos()).clamp(-1.0, 1.0).acos();
    [tilt, x[6].hypot(x[7]), x[8], x[9], x[10], x[11], u[0], u[1], u[2], u[3]]
}

/// Lower and upper quantile of the envelope.
const QUANTILES: (f64, f64) = (0.001, 0.999);

/// Per segment, per interior sample: airborne and inside the envelope of the training segments
/// (training samples always are). Returns the masks and the fraction of airborne held-out samples
/// inside.
pub(crate) fn masks(segs: &[SegData]) -> (Vec<Vec<bool>>, f64) {
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); 10];
    for seg in segs.iter().filter(|s| !s.holdout) {
        for k in seg.interior().filter(|&k| seg.airborne[k - seg.h]) {
            for (c, v) in variables(&seg.x[k], &seg.u[k]).into_iter().enumerate() {
                columns[c].push(v);
            }
        }
    }
    let bounds: Vec<(f64, f64)> = columns
        .iter_mut()
        .map(|c| {
            c.sort_by(f64::total_cmp);
            if c.is_empty() {
                return (f64::NEG_INFINITY, f64::INFINITY);
            }
            let at = |q: f64| c[((c.len() - 1) as f64 * q).round() as usize];
            (at(QUANTILES.0), at(QUANTILES.1))
        })
        .collect();
    let (mut inside, mut total) = (0usize, 0usize);
    let masks = segs
        .iter()
        .map(|seg| {
            seg.interior()
                .map(|k| {
                    if !seg.airborne[k - seg.h] {
                        return false;
                    }
                    if !seg.holdout {
                        return true;
                    }
                    let v = variables(&seg.x[k], &seg.u[k]);
                    let ok = v.iter().zip(&bounds).all(|(v, (lo, hi))| v >= lo && v <= hi);
                    total += 1;
                    inside += ok as usize;
                    ok
                })
                .collect()
        })
        .collect();
    (masks, if total > 0 { inside as f64 / total as f64 } else { 1.0 })
}
