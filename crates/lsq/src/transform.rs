//! Bounds by transformation: each free parameter `p` is the image of an
//! unconstrained internal coordinate `u`, so the optimiser never sees a bound.
//!
//! With `s` the parameter scale,
//!
//! | bounds          | `p(u)`                                      | `dp/du`                          |
//! |-----------------|---------------------------------------------|----------------------------------|
//! | none            | `s u`                                       | `s`                              |
//! | `p >= lo`       | `lo + s (sqrt(u^2 + 1) - 1)`                | `s u / sqrt(u^2 + 1)`            |
//! | `p <= hi`       | `hi - s (sqrt(u^2 + 1) - 1)`                | `-s u / sqrt(u^2 + 1)`           |
//! | `lo <= p <= hi` | `lo + (hi - lo) (1 + sin u) / 2`            | `(hi - lo) cos(u) / 2`           |
//!
//! Each map is smooth and reaches its bound only at a stationary point of
//! `p(u)` (`u = 0` or `u = ±pi/2`), where `dp/du = 0`. A start exactly on a
//! bound would therefore never move; it is moved [`START_OFFSET`] internal
//! units inside, and so is one within [`ON_BOUND`] of it (rounding: a
//! fit that ended on the bound). A start further inside keeps its value:
//! the inverses are written so that `p(u(p))` returns it to rounding
//! (`d = sqrt(u^2 + 1) - 1` inverts as `u = sqrt(d (d + 2))`, and
//! `(1 + sin u) / 2 = a` as `u = 2 asin(sqrt(a)) - pi/2`).

use crate::parameter::Parameter;

/// How far (in internal units) a start lying on a bound is moved inside.
pub const START_OFFSET: f64 = 1e-2;

/// A start closer than this to a bound, relative to the interval's width
/// (one-sided: to the parameter's scale), is taken as lying on it: its
/// internal coordinate would sit within $2\sqrt{10^{-10}} = 2 \cdot 10^{-5}$
/// of the stationary point, where `dp/du` nearly vanishes.
pub const ON_BOUND: f64 = 1e-10;

/// The map from the internal coordinate of one free parameter to its value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Transform {
    /// No bound: `p = s u`.
    Unbounded {
        /// Parameter scale.
        scale: f64,
    },
    /// Lower bound only.
    Lower {
        /// The bound.
        lower: f64,
        /// Parameter scale.
        scale: f64,
    },
    /// Upper bound only.
    Upper {
        /// The bound.
        upper: f64,
        /// Parameter scale.
        scale: f64,
    },
    /// Both bounds.
    Interval {
        /// Lower bound.
        lower: f64,
        /// Upper bound.
        upper: f64,
    },
}

impl Transform {
    /// The transform for a (validated) parameter specification.
    pub fn for_parameter(parameter: &Parameter) -> Self {
        let scale = parameter.effective_scale();
        match (parameter.lower, parameter.upper) {
            (None, None) => Self::Unbounded { scale },
            (Some(lower), None) => Self::Lower { lower, scale },
            (None, Some(upper)) => Self::Upper { upper, scale },
            (Some(lower), Some(upper)) => Self::Interval { lower, upper },
        }
    }

    /// `p(u)`, clamped into the bounds against rounding.
    pub fn external(&self, u: f64) -> f64 {
        match *self {
            Self::Unbounded { scale } => scale * u,
            Self::Lower { lower, scale } => lower + scale * (u.hypot(1.0) - 1.0),
            Self::Upper { upper, scale } => upper - scale * (u.hypot(1.0) - 1.0),
            Self::Interval { lower, upper } => {
                (lower + (upper - lower) * 0.5 * (1.0 + u.sin())).clamp(lower, upper)
            }
        }
    }

    /// `dp/du`.
    pub fn derivative(&self, u: f64) -> f64 {
        match *self {
            Self::Unbounded { scale } => scale,
            Self::Lower { scale, .. } => scale * u / u.hypot(1.0),
            Self::Upper { scale, .. } => -scale * u / u.hypot(1.0),
            Self::Interval { lower, upper } => 0.5 * (upper - lower) * u.cos(),
        }
    }

    /// The internal coordinate of a value inside the bounds; values on a
    /// bound (within [`ON_BOUND`]) or beyond it map [`START_OFFSET`]
    /// inside it.
    pub fn internal(&self, p: f64) -> f64 {
        match *self {
            Self::Unbounded { scale } => p / scale,
            Self::Lower { lower, scale } => one_sided_inverse((p - lower) / scale),
            Self::Upper { upper, scale } => one_sided_inverse((upper - p) / scale),
            Self::Interval { lower, upper } => {
                use std::f64::consts::FRAC_PI_2;
                let share = (p - lower) / (upper - lower);
                if share <= ON_BOUND {
                    START_OFFSET - FRAC_PI_2
                } else if share >= 1.0 - ON_BOUND {
                    FRAC_PI_2 - START_OFFSET
                } else if share <= 0.5 {
                    2.0 * share.sqrt().asin() - FRAC_PI_2
                } else {
                    FRAC_PI_2 - 2.0 * (1.0 - share).sqrt().asin()
                }
            }
        }
    }

    /// Whether `p` lies within `tolerance` (relative to the scale, or to the
    /// interval width) of a bound.
    pub fn is_at_bound(&self, p: f64, tolerance: f64) -> bool {
        match *self {
            Self::Unbounded { .. } => false,
            Self::Lower { lower, scale } => p - lower <= tolerance * scale,
            Self::Upper { upper, scale } => upper - p <= tolerance * scale,
            Self::Interval { lower, upper } => {
                let width = upper - lower;
                p - lower <= tolerance * width || upper - p <= tolerance * width
            }
        }
    }
}

/// Inverse of `d = sqrt(u^2 + 1) - 1` on the branch `u > 0`, and
/// [`START_OFFSET`] for `d <= ON_BOUND` (on the bound, or beyond it).
fn one_sided_inverse(distance: f64) -> f64 {
    if distance > ON_BOUND {
        (distance * (distance + 2.0)).sqrt()
    } else {
        START_OFFSET
    }
}
