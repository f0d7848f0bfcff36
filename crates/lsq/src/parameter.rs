//! The specification of one fitted parameter: name, start, scale, bounds.

use serde::{Deserialize, Serialize};

use crate::error::LsqError;

/// One parameter of a fit.
///
/// ```
/// use needle_lsq::Parameter;
/// let stiffness = Parameter::new("E", 30e3).with_bounds(1e3, 1e6);
/// let offset = Parameter::new("offset", 0.0).with_scale(1e-3);
/// let known = Parameter::new("poisson", 0.49).fix();
/// # let _ = (stiffness, offset, known);
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Parameter {
    /// Name used in reports and errors.
    pub name: String,
    /// Starting value (and the held value when `fixed`).
    pub initial: f64,
    /// Typical magnitude. Sets the finite-difference step and the unit of
    /// the internal (transformed) coordinate. Default: `|initial|`, or 1 if
    /// the start is zero.
    pub scale: Option<f64>,
    /// Lower bound, if any.
    pub lower: Option<f64>,
    /// Upper bound, if any.
    pub upper: Option<f64>,
    /// Held at `initial` and not fitted.
    pub fixed: bool,
}

impl Parameter {
    /// A free, unbounded parameter starting at `initial`.
    pub fn new(name: impl Into<String>, initial: f64) -> Self {
        Self {
            name: name.into(),
            initial,
            scale: None,
            lower: None,
            upper: None,
            fixed: false,
        }
    }

    /// Sets the typical magnitude.
    pub fn with_scale(mut self, scale: f64) -> Self {
        self.scale = Some(scale);
        self
    }

    /// Sets a lower bound.
    pub fn with_lower(mut self, lower: f64) -> Self {
        self.lower = Some(lower);
        self
    }

    /// Sets an upper bound.
    pub fn with_upper(mut self, upper: f64) -> Self {
        self.upper = Some(upper);
        self
    }

    /// Sets both bounds.
    pub fn with_bounds(self, lower: f64, upper: f64) -> Self {
        self.with_lower(lower).with_upper(upper)
    }

    /// Holds the parameter at its initial value.
    pub fn fix(mut self) -> Self {
        self.fixed = true;
        self
    }

    /// The scale actually used: the given one, else `|initial|`, else 1.
    pub fn effective_scale(&self) -> f64 {
        match self.scale {
            Some(scale) => scale,
            None if self.initial != 0.0 => self.initial.abs(),
            None => 1.0,
        }
    }

    /// Checks the specification: finite start inside finite, ordered bounds,
    /// positive finite scale.
    pub fn validate(&self) -> Result<(), LsqError> {
        let fail = |reason: String| {
            Err(LsqError::InvalidParameter {
                name: self.name.clone(),
                reason,
            })
        };
        if !self.initial.is_finite() {
            return fail(format!("initial value {} is not finite", self.initial));
        }
        if let Some(scale) = self.scale
            && !(scale.is_finite() && scale > 0.0)
        {
            return fail(format!("scale {scale} must be finite and positive"));
        }
        if let Some(lower) = self.lower {
            if !lower.is_finite() {
                return fail(format!(
                    "lower bound {lower} is not finite (omit it instead)"
                ));
            }
            if self.initial < lower {
                return fail(format!(
                    "initial value {} is below the lower bound {lower}",
                    self.initial
                ));
            }
        }
        if let Some(upper) = self.upper {
            if !upper.is_finite() {
                return fail(format!(
                    "upper bound {upper} is not finite (omit it instead)"
                ));
            }
            if self.initial > upper {
                return fail(format!(
                    "initial value {} is above the upper bound {upper}",
                    self.initial
                ));
            }
        }
        if let (Some(lower), Some(upper)) = (self.lower, self.upper)
            && lower >= upper
        {
            return fail(format!(
                "lower bound {lower} is not below upper bound {upper}"
            ));
        }
        Ok(())
    }
}
