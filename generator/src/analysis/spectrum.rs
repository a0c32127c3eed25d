//! Welch spectra within segments: power spectral density, cross spectra and the magnitude-squared
//! coherence (Hann window, 50 % overlap, each window demeaned), as `scipy.signal.welch` /
//! `scipy.signal.coherence` with `window="hann"`, `detrend="constant"`, `scaling="density"`.

use std::ops::Range;

/// In-place radix-2 FFT (forward, e^{−2πi kn/N}) of `re` + i `im`; the length must be a power of 2.
pub fn fft(re: &mut [f64], im: &mut [f64]) {
    let n = re.len();
    assert!(
        n.is_power_of_two() && im.len() == n,
        "fft needs equal power-of-two lengths"
    );
    // Bit reversal.
    let mut j = 0;
    for i in 1..n {
        let mut bit = n >> 1;
        while j & bit != 0 {
            j ^= bit;
            bit >>= 1;
        }
        j |= bit;
        if i < j {
            re.swap(i, j);
            im.swap(i, j);
        }
    }
    let mut len = 2;
    while len <= n {
        let ang = -2.0 * std::f64::consts::PI / len as f64;
        for start in (0..n).step_by(len) {
            for k in 0..len / 2 {
                let (s, c) = (ang * k as f64).sin_cos();
                let (a, b) = (start + k, start + k + len / 2);
                let tr = re[b] * c - im[b] * s;
                let ti = re[b] * s + im[b] * c;
                re[b] = re[a] - tr;
                im[b] = im[a] - ti;
                re[a] += tr;
                im[a] += ti;
            }
        }
        len <<= 1;
    }
}

/// The periodic Hann window of length n (scipy `get_window("hann", n)`).
pub fn hann(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos())
        .collect()
}

/// The Welch window length actually used: the largest power of two ≤ min(`requested`, longest
/// segment), at least 8; `None` if no segment has 8 samples.
pub fn window_length(requested: usize, ranges: &[Range<usize>]) -> Option<usize> {
    let longest = ranges.iter().map(|r| r.len()).max().unwrap_or(0);
    let cap = requested.min(longest);
    if cap < 8 {
        return None;
    }
    Some(1usize << (usize::BITS - 1 - cap.leading_zeros()))
}

/// Start indices of the Welch windows: every nperseg/2 samples inside each segment, windows
/// entirely within the segment.
pub fn window_starts(ranges: &[Range<usize>], nperseg: usize) -> Vec<usize> {
    let step = (nperseg / 2).max(1);
    let mut starts = Vec::new();
    for r in ranges {
        let mut s = r.start;
        while s + nperseg <= r.end {
            starts.push(s);
            s += step;
        }
    }
    starts
}

/// The one-sided frequencies k·fs/N, k = 0 … N/2.
pub fn frequencies(nperseg: usize, fs: f64) -> Vec<f64> {
    (0..=nperseg / 2).map(|k| k as f64 * fs / nperseg as f64).collect()
}

/// Welch estimates for one primary series x and several secondary series yⱼ, over the windows
/// where x and every yⱼ are finite.
#[derive(Clone, Debug)]
pub struct CrossSpectra {
    pub nperseg: usize,
    pub frequencies: Vec<f64>,
    /// Windows averaged.
    pub windows: usize,
    /// One-sided PSD of x (unit² / Hz).
    pub pxx: Vec<f64>,
    /// Magnitude-squared coherence |Pxyⱼ|² / (Pxx Pyⱼyⱼ) per secondary series, in [0, 1].
    pub coherence: Vec<Vec<f64>>,
}

struct Windowed {
    re: Vec<f64>,
    im: Vec<f64>,
}

fn transform(x: &[f64], w: &[f64]) -> Windowed {
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    let mut re: Vec<f64> = x.iter().zip(w).map(|(v, w)| (v - mean) * w).collect();
    let mut im = vec![0.0; x.len()];
    fft(&mut re, &mut im);
    Windowed { re, im }
}

/// Welch PSD of `x` and its coherence with each of `ys` (`None` when no segment holds a window
/// of `nperseg` samples with finite values).
pub fn cross_spectra(
    x: &[f64],
    ys: &[&[f64]],
    ranges: &[Range<usize>],
    fs: f64,
    nperseg: usize,
) -> Option<CrossSpectra> {
    assert!(nperseg.is_power_of_two(), "Welch window length must be a power of two");
    let w = hann(nperseg);
    let wss: f64 = w.iter().map(|v| v * v).sum();
    let nf = nperseg / 2 + 1;
    let mut pxx = vec![0.0; nf];
    let mut pyy = vec![vec![0.0; nf]; ys.len()];
    let mut pxy = vec![vec![(0.0, 0.0); nf]; ys.len()];
    let mut windows = 0;
    for s in window_starts(ranges, nperseg) {
        let seg = s..s + nperseg;
        if x[seg.clone()].iter().any(|v| !v.is_finite())
            || ys.iter().any(|y| y[seg.clone()].iter().any(|v| !v.is_finite()))
        {
            continue;
        }
        windows += 1;
        let fx = transform(&x[seg.clone()], &w);
        for k in 0..nf {
            pxx[k] += fx.re[k] * fx.re[k] + fx.im[k] * fx.im[k];
        }
        for (j, y) in ys.iter().enumerate() {
            let fy = transform(&y[seg.clone()], &w);
            for k in 0..nf {
                pyy[j][k] += fy.re[k] * fy.re[k] + fy.im[k] * fy.im[k];
                // X* Y
                pxy[j][k].0 += fx.re[k] * fy.re[k] + fx.im[k] * fy.im[k];
                pxy[j][k].1 += fx.re[k] * fy.im[k] - fx.im[k] * fy.re[k];
            }
        }
    }
    if windows == 0 {
        return None;
    }
    let scale = 1.0 / (fs * wss * windows as f64);
    let psd: Vec<f64> = pxx
        .iter()
        .enumerate()
        .map(|(k, p)| {
            // nperseg is a power of two: even, so bin N/2 is Nyquist and not doubled either.
            let one_sided = if k == 0 || k == nperseg / 2 { 1.0 } else { 2.0 };
            p * scale * one_sided
        })
        .collect();
    let coherence = (0..ys.len())
        .map(|j| {
            (0..nf)
                .map(|k| {
                    let den = pxx[k] * pyy[j][k];
                    let (a, b) = pxy[j][k];
                    if den > 0.0 {
                        ((a * a + b * b) / den).clamp(0.0, 1.0)
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    Some(CrossSpectra {
        nperseg,
        frequencies: frequencies(nperseg, fs),
        windows,
        pxx: psd,
        coherence,
    })
}

/// Welch PSD of one series: (frequencies, one-sided PSD, windows averaged).
pub fn welch_psd(x: &[f64], ranges: &[Range<usize>], fs: f64, nperseg: usize) -> Option<(Vec<f64>, Vec<f64>, usize)> {
    cross_spectra(x, &[], ranges, fs, nperseg).map(|c| (c.frequencies, c.pxx, c.windows))
}

/// Welch magnitude-squared coherence of two series: (frequencies, coherence, windows averaged).
pub fn coherence(
    x: &[f64],
    y: &[f64],
    ranges: &[Range<usize>],
    fs: f64,
    nperseg: usize,
) -> Option<(Vec<f64>, Vec<f64>, usize)> {
    cross_spectra(x, &[y], ranges, fs, nperseg).map(|mut c| (c.frequencies, c.coherence.remove(0), c.windows))
}

/// Equivalent number of independent windows of a Hann Welch average with 50 % overlap
/// (Welch 1967: the overlap correlation of adjacent Hann windows is c = 0.167, so K windows
/// count as K / (1 + 2c²)).
pub fn equivalent_windows(windows: usize) -> f64 {
    windows as f64 / (1.0 + 2.0 * 0.167 * 0.167)
}

/// The 95 % level of the coherence of two independent Gaussian series averaged over K windows:
/// P(C > c) = (1 − c)^{K−1}, so c = 1 − 0.05^{1/(K−1)} (with K the equivalent window count).
pub fn coherence_threshold(windows: usize) -> f64 {
    let k = equivalent_windows(windows);
    if k <= 1.0 {
        return 1.0;
    }
    1.0 - 0.05f64.powf(1.0 / (k - 1.0))
}

/// Power in [lo, hi) Hz (the last band, `hi` = ∞, includes Nyquist): Σ PSD · Δf.
pub fn band_power(freqs: &[f64], psd: &[f64], lo: f64, hi: f64) -> f64 {
    let df = if freqs.len() > 1 { freqs[1] - freqs[0] } else { 0.0 };
    freqs
        .iter()
        .zip(psd)
        .filter(|(f, _)| **f >= lo && **f < hi)
        .map(|(_, p)| p * df)
        .sum()
}

/// The mean of `values` over the frequencies in [lo, hi), DC excluded (`None` if no bin).
pub fn band_mean(freqs: &[f64], values: &[f64], lo: f64, hi: f64) -> Option<f64> {
    let v: Vec<f64> = freqs
        .iter()
        .zip(values)
        .filter(|(f, _)| **f > 0.0 && **f >= lo && **f < hi)
        .map(|(_, c)| *c)
        .collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fft_matches_the_dft() {
        let x: Vec<f64> = (0..16)
            .map(|i| ((i * 7 % 5) as f64 - 2.0) * 0.3 + (i as f64 * 0.4).sin())
            .collect();
        let (mut re, mut im) = (x.clone(), vec![0.0; 16]);
        fft(&mut re, &mut im);
        for k in 0..16 {
            let (mut a, mut b) = (0.0, 0.0);
            for (n, v) in x.iter().enumerate() {
                let ang = -2.0 * std::f64::consts::PI * (k * n) as f64 / 16.0;
                a += v * ang.cos();
                b += v * ang.sin();
            }
            assert!((re[k] - a).abs() < 1e-12 && (im[k] - b).abs() < 1e-12, "bin {k}");
        }
    }

    #[test]
    fn window_length_is_a_power_of_two_within_the_longest_segment() {
        let whole = |n| crate::analysis::stats::segment_ranges(&[0], n);
        assert_eq!(window_length(128, &whole(1000)), Some(128));
        assert_eq!(window_length(128, &[0..100, 100..150]), Some(64));
        assert_eq!(window_length(100, &whole(1000)), Some(64));
        assert_eq!(window_length(128, &whole(7)), None);
        assert_eq!(window_starts(&[0..10, 10..18], 4), vec![0, 2, 4, 6, 10, 12, 14]);
    }

    #[test]
    fn band_power_sums_bins_in_the_band() {
        let f = [0.0, 1.0, 2.0, 3.0];
        let p = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(band_power(&f, &p, 0.0, 2.0), 3.0);
        assert_eq!(band_power(&f, &p, 2.0, f64::INFINITY), 7.0);
        assert_eq!(band_mean(&f, &p, 0.0, 2.0), Some(2.0));
        assert_eq!(band_mean(&f, &p, 5.0, 6.0), None);
    }

    #[test]
    fn coherence_threshold_decreases_with_windows() {
        assert_eq!(coherence_threshold(1), 1.0);
        let (a, b) = (coherence_threshold(10), coherence_threshold(40));
        assert!(a > b && b > 0.0 && a < 1.0, "{a} {b}");
    }
}
