//! The floating-point type of a generated crate, as the runtime needs it.

use core::cmp::Ordering;
use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A floating-point type the runtime computes with: implemented for `f32` and `f64` (a generated
/// crate's `Real` is one of them). Transcendental functions go through `libm`, so they behave the
/// same on a host and on a `no_std` target.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialEq
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + Into<f64>
    + 'static
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// +∞.
    const INFINITY: Self;

    /// 0.
    fn zero() -> Self {
        Self::ZERO
    }
    /// 1.
    fn one() -> Self {
        Self::ONE
    }
    /// The nearest value to `v` (`as` conversion).
    fn from_f64(v: f64) -> Self;
    /// The value as `f64` (exact).
    fn to_f64(self) -> f64;
    /// The nearest value to `v` (`as` conversion).
    fn from_u32(v: u32) -> Self;
    /// Sine (radians).
    fn sin(self) -> Self;
    /// Cosine (radians).
    fn cos(self) -> Self;
    /// eˣ.
    fn exp(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Neither NaN nor infinite.
    fn is_finite(self) -> bool;
    /// NaN.
    fn is_nan(self) -> bool;
    /// `lo` if `self < lo`, `hi` if `self > hi`, else `self`. Unlike `f64::clamp` it never panics;
    /// NaN gives `lo`.
    fn clamp_to(self, lo: Self, hi: Self) -> Self {
        match (self.partial_cmp(&lo), self.partial_cmp(&hi)) {
            (Some(Ordering::Less) | None, _) => lo,
            (_, Some(Ordering::Greater)) => hi,
            _ => self,
        }
    }
}

macro_rules! impl_real {
    ($t:ident) => {
        impl Real for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const INFINITY: Self = $t::INFINITY;

            #[inline]
            fn from_f64(v: f64) -> Self {
                v as $t
            }
            #[inline]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline]
            fn from_u32(v: u32) -> Self {
                v as $t
            }
            #[inline]
            fn sin(self) -> Self {
                libm::Libm::<$t>::sin(self)
            }
            #[inline]
            fn cos(self) -> Self {
                libm::Libm::<$t>::cos(self)
            }
            #[inline]
            fn exp(self) -> Self {
                libm::Libm::<$t>::exp(self)
            }
            #[inline]
            fn sqrt(self) -> Self {
                libm::Libm::<$t>::sqrt(self)
            }
            #[inline]
            fn abs(self) -> Self {
                libm::Libm::<$t>::fabs(self)
            }
            #[inline]
            fn is_finite(self) -> bool {
                $t::is_finite(self)
            }
            #[inline]
            fn is_nan(self) -> bool {
                $t::is_nan(self)
            }
        }
    };
}

impl_real!(f32);
impl_real!(f64);
