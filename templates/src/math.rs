//! Elementary functions for `no_std` (libm), for `Real` = f64 or f32.

use crate::Real;
use libm::Libm;

/// sin x
#[inline]
pub fn sin(x: Real) -> Real {
    Libm::<Real>::sin(x)
}

/// cos x
#[inline]
pub fn cos(x: Real) -> Real {
    Libm::<Real>::cos(x)
}

/// (sin x, cos x) with one argument reduction: the same values as [`sin`] and [`cos`].
#[inline]
pub fn sincos(x: Real) -> (Real, Real) {
    Libm::<Real>::sincos(x)
}

/// √x
#[inline]
pub fn sqrt(x: Real) -> Real {
    Libm::<Real>::sqrt(x)
}

/// xⁿ by repeated squaring, n ≥ 0.
#[inline]
pub fn powi(x: Real, n: u32) -> Real {
    let (mut base, mut n, mut acc) = (x, n, 1.0);
    while n > 0 {
        if n & 1 == 1 {
            acc *= base;
        }
        base *= base;
        n >>= 1;
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn powi_matches_repeated_multiplication() {
        assert_eq!(powi(1.5, 0), 1.0);
        assert_eq!(powi(1.5, 1), 1.5);
        assert_eq!(powi(1.5, 5), 1.5 * 1.5 * 1.5 * 1.5 * 1.5);
        assert_eq!(powi(-2.0, 3), -8.0);
    }

    #[test]
    fn trig_is_libm() {
        assert!((sin(0.5) - 0.479_425_538_604_203).abs() < 1e-15);
        assert!((cos(0.5) - 0.877_582_561_890_372_8).abs() < 1e-15);
    }

    #[test]
    fn sincos_is_sin_and_cos() {
        // Tiny, small and reduced arguments, both signs: the same bits as sin and cos.
        let mut x: Real = 1e-12;
        while x < 1e4 {
            for v in [x, -x] {
                assert_eq!(sincos(v), (sin(v), cos(v)), "x = {v}");
            }
            x *= 1.013;
        }
        assert_eq!(sincos(0.0), (sin(0.0), cos(0.0)));
    }
}
