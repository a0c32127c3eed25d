//! The residuals by frequency: Welch PSD per channel, power per band, and the coherence of each
//! residual with each input per band.

use super::spectrum::{band_mean, band_power, coherence_threshold, cross_spectra, equivalent_windows, window_length};
use super::{Prepared, WhereInput, WhereOptions, INPUT_COLUMNS};
use serde::Serialize;

/// Spectra of the one-step residuals.
#[derive(Clone, Debug, Serialize)]
pub struct SpectrumReport {
    /// Welch window length used (samples).
    pub nperseg: usize,
    /// Frequency resolution fs / nperseg (Hz).
    pub resolution: f64,
    /// fs / 2 (Hz).
    pub nyquist: f64,
    /// The one-sided frequency grid k · resolution, k = 0 … nperseg/2 (Hz).
    pub frequencies: Vec<f64>,
    /// [lo, hi] of each band (Hz); the last one ends at Nyquist.
    pub bands: Vec<[f64; 2]>,
    /// "0–0.5 Hz", …
    pub band_labels: Vec<String>,
    pub channels: Vec<ChannelSpectrum>,
    /// One entry per (input, channel) pair, input-major.
    pub coherence: Vec<CoherenceReport>,
}

/// The PSD of one residual channel.
#[derive(Clone, Debug, Serialize)]
pub struct ChannelSpectrum {
    pub channel: String,
    /// Welch windows averaged (windows containing a missing residual are skipped).
    pub windows: usize,
    /// One-sided PSD at `frequencies` (unit² / Hz; empty if no window).
    pub psd: Vec<f64>,
    /// Σ PSD · Δf: the residual variance seen by the windows.
    pub total_power: f64,
    /// Power per band (unit²).
    pub band_power: Vec<f64>,
    /// band_power / total_power.
    pub band_fraction: Vec<f64>,
    /// Index of the band with the most power.
    pub dominant_band: usize,
    /// Frequency of the largest PSD value above DC (Hz).
    pub peak_frequency: f64,
}

/// The magnitude-squared coherence of one residual with one input.
#[derive(Clone, Debug, Serialize)]
pub struct CoherenceReport {
    pub input: String,
    pub channel: String,
    pub windows: usize,
    /// The 95 % level of the coherence of independent series with this many windows.
    pub threshold: f64,
    /// The coherence expected by chance: 1 / equivalent windows.
    pub null_mean: f64,
    /// Mean coherence over each band's frequencies (DC excluded; `None` for a band with no bin).
    pub band_mean: Vec<Option<f64>>,
    /// Largest coherence above DC and its frequency.
    pub max: f64,
    pub max_frequency: f64,
}

fn format_hz(f: f64) -> String {
    let s = format!("{f:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// The bands [lo, hi] for the options' edges and a Nyquist frequency.
pub fn bands(edges: &[f64], nyquist: f64) -> Vec<[f64; 2]> {
    let mut cuts: Vec<f64> = edges.iter().copied().filter(|e| *e > 0.0 && *e < nyquist).collect();
    cuts.sort_by(f64::total_cmp);
    cuts.dedup();
    let mut lo = 0.0;
    let mut out = Vec::new();
    for c in cuts {
        out.push([lo, c]);
        lo = c;
    }
    out.push([lo, nyquist]);
    out
}

/// Spectra and coherences (`None` when no segment holds a Welch window of 8 samples).
pub(crate) fn spectrum(input: &WhereInput, p: &Prepared, options: &WhereOptions) -> Option<SpectrumReport> {
    let nperseg = window_length(options.welch_segment, &p.ranges)?;
    let fs = 1.0 / input.dt;
    let nyquist = fs / 2.0;
    let bands = bands(&options.band_edges, nyquist);
    // The last band includes Nyquist: its upper limit is open-ended for the sums.
    let hi = |b: usize| {
        if b + 1 == bands.len() {
            f64::INFINITY
        } else {
            bands[b][1]
        }
    };
    let inputs: Vec<Vec<f64>> = (0..4).map(|j| input.inputs.iter().map(|u| u[j]).collect()).collect();
    let input_refs: Vec<&[f64]> = inputs.iter().map(|v| v.as_slice()).collect();
    let frequencies = super::spectrum::frequencies(nperseg, fs);
    let mut channels = Vec::new();
    let mut coherence = vec![Vec::new(); 4];
    for (c, name) in input.channels.iter().enumerate() {
        let cs = cross_spectra(&input.one_step[c], &input_refs, &p.ranges, fs, nperseg);
        let (windows, psd, msc) = match cs {
            Some(cs) => (cs.windows, cs.pxx, cs.coherence),
            None => (0, Vec::new(), vec![Vec::new(); 4]),
        };
        let band_power: Vec<f64> = (0..bands.len())
            .map(|b| {
                if psd.is_empty() {
                    0.0
                } else {
                    band_power(&frequencies, &psd, bands[b][0], hi(b))
                }
            })
            .collect();
        let total_power: f64 = band_power.iter().sum();
        let peak = psd
            .iter()
            .enumerate()
            .skip(1)
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map_or(0.0, |(k, _)| frequencies[k]);
        channels.push(ChannelSpectrum {
            channel: name.clone(),
            windows,
            band_fraction: band_power
                .iter()
                .map(|b| if total_power > 0.0 { b / total_power } else { 0.0 })
                .collect(),
            dominant_band: (0..bands.len())
                .max_by(|a, b| band_power[*a].total_cmp(&band_power[*b]))
                .unwrap_or(0),
            peak_frequency: peak,
            total_power,
            band_power,
            psd,
        });
        for (j, m) in msc.into_iter().enumerate() {
            let (max_k, max) = m
                .iter()
                .enumerate()
                .skip(1)
                .max_by(|a, b| a.1.total_cmp(b.1))
                .map_or((0, 0.0), |(k, v)| (k, *v));
            coherence[j].push(CoherenceReport {
                input: INPUT_COLUMNS[j].to_string(),
                channel: name.clone(),
                windows,
                threshold: coherence_threshold(windows),
                null_mean: if windows > 0 {
                    (1.0 / equivalent_windows(windows)).min(1.0)
                } else {
                    1.0
                },
                band_mean: (0..bands.len())
                    .map(|b| {
                        if m.is_empty() {
                            None
                        } else {
                            band_mean(&frequencies, &m, bands[b][0], hi(b))
                        }
                    })
                    .collect(),
                max,
                max_frequency: frequencies[max_k],
            });
        }
    }
    Some(SpectrumReport {
        nperseg,
        resolution: fs / nperseg as f64,
        nyquist,
        band_labels: bands
            .iter()
            .map(|[lo, hi]| format!("{}–{} Hz", format_hz(*lo), format_hz(*hi)))
            .collect(),
        bands,
        frequencies,
        channels,
        coherence: coherence.into_iter().flatten().collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_end_at_nyquist() {
        assert_eq!(
            bands(&[0.5, 2.0, 5.0], 15.0),
            vec![[0.0, 0.5], [0.5, 2.0], [2.0, 5.0], [5.0, 15.0]]
        );
        assert_eq!(bands(&[0.5, 2.0, 5.0], 2.5), vec![[0.0, 0.5], [0.5, 2.0], [2.0, 2.5]]);
        assert_eq!(format_hz(0.5), "0.5");
        assert_eq!(format_hz(15.0), "15");
    }
}
