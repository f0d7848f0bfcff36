//! The tip prior: the smoothness penalty relaxed near the tip, where the
//! needle cuts and the density peaks, with the extent and the strength of
//! the relaxation chosen by the data.
//!
//! The uniform prior $\lambda|Lq|^2 \approx \lambda\int q'^2\,ds$ pulls the
//! density towards a constant and flattens the tip peak. The tip prior
//! weighs the rows of $L$ (the differences over the elements, or the second
//! differences at the stations) whose centre $c_r$ lies within a zone $k$
//! of the tip by a relaxation $\rho < 1$:
//!
//! $$|L_{k,\rho}\,q|^2 = \sum_r w_r (Lq)_r^2,\qquad
//! w_r = \begin{cases}\rho & L - c_r < k\\ 1 & \text{otherwise.}\end{cases}$$
//!
//! [`TipPrior::Evidence`] takes $(k, \rho)$ from a small grid
//! ([`TIP_ZONES`] x [`TIP_RELAXATIONS`], and the uniform prior) together
//! with $\lambda$, by the marginal likelihood of the data
//! ([`crate::evidence`], [`Regularisation::MarginalLikelihood`]): a relaxed
//! zone is chosen only when the data determine the extra freedom it gives
//! the tip. Nothing in the grid or the rule refers to a particular peak.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::ForceError;
use crate::regularise::{Regularisation, RegularisedFit, solve_most_probable, solve_regularised};
use crate::shaft::{ShaftBasis, Smoothness};

/// How the smoothness penalty treats the tip.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum TipPrior {
    /// The same penalty along the whole shaft.
    Uniform,
    /// The penalty times `relaxation` within `zone` (m) of the tip.
    Fixed {
        /// Extent of the relaxed zone behind the tip (m).
        zone: f64,
        /// Factor on the penalty inside it, in $(0, 1]$.
        relaxation: f64,
    },
    /// The zone and relaxation of largest marginal likelihood among
    /// [`TIP_ZONES`] x [`TIP_RELAXATIONS`] and the uniform prior; needs
    /// [`Regularisation::MarginalLikelihood`].
    Evidence,
}

/// Relaxed zones tried by [`TipPrior::Evidence`] (m behind the tip): one
/// to six stations of the default 1.5 mm spacing (the marker spacing of the
/// paper's grid is 3.75 mm).
pub const TIP_ZONES: [f64; 5] = [1.5e-3, 3e-3, 4.5e-3, 6e-3, 9e-3];

/// Penalty factors tried by [`TipPrior::Evidence`] inside the zone: from a
/// tenth of the shaft's penalty to a nearly free tip.
pub const TIP_RELAXATIONS: [f64; 4] = [1e-1, 1e-2, 1e-3, 1e-4];

/// The tip zone of the smoothness prior a fit used.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TipZone {
    /// Extent behind the tip (m); 0 for the uniform prior.
    pub zone: f64,
    /// Factor on the penalty inside the zone; 1 for the uniform prior.
    pub relaxation: f64,
}

impl TipZone {
    /// The uniform prior.
    pub const UNIFORM: Self = Self {
        zone: 0.0,
        relaxation: 1.0,
    };

    /// The difference operator of `smoothness` on `basis` with the rows
    /// centred within the zone scaled by $\sqrt\rho$.
    pub fn operator(&self, basis: &ShaftBasis, smoothness: Smoothness) -> DMatrix<f64> {
        let mut l = basis.difference_operator(smoothness);
        let (length, s) = (basis.length(), &basis.stations);
        let scale = self.relaxation.sqrt();
        for r in 0..l.nrows() {
            let centre = match smoothness {
                Smoothness::FirstDifference => 0.5 * (s[r] + s[r + 1]),
                Smoothness::SecondDifference => s[r + 1],
            };
            if length - centre < self.zone {
                l.row_mut(r).scale_mut(scale);
            }
        }
        l
    }
}

impl TipPrior {
    /// The zones this prior tries, the uniform prior first.
    pub(crate) fn candidates(&self) -> Result<Vec<TipZone>, ForceError> {
        Ok(match *self {
            Self::Uniform => vec![TipZone::UNIFORM],
            Self::Fixed { zone, relaxation } => {
                crate::error::positive("tip zone", zone)?;
                if !(relaxation > 0.0 && relaxation <= 1.0) {
                    return Err(ForceError::InvalidValue {
                        field: "tip relaxation",
                        value: relaxation,
                        reason: "must lie in (0, 1]",
                    });
                }
                vec![TipZone { zone, relaxation }]
            }
            Self::Evidence => std::iter::once(TipZone::UNIFORM)
                .chain(TIP_ZONES.iter().flat_map(|&zone| {
                    TIP_RELAXATIONS
                        .iter()
                        .map(move |&relaxation| TipZone { zone, relaxation })
                }))
                .collect(),
        })
    }
}

/// The regularised fit of the density's station values on `basis` to the
/// data `(a, b)` (`a` maps station values to data, as $G$ does) with the
/// tip prior `prior` and the weight by `regularisation`; returns the fit
/// and the zone used.
///
/// Errors: [`TipPrior::Evidence`] with a rule other than
/// [`Regularisation::MarginalLikelihood`] (only the evidence can weigh one
/// prior against another), and those of [`solve_regularised`].
pub fn fit_with_tip_prior(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    basis: &ShaftBasis,
    smoothness: Smoothness,
    regularisation: Regularisation,
    prior: TipPrior,
) -> Result<(RegularisedFit, TipZone), ForceError> {
    let zones = prior.candidates()?;
    let operators: Vec<DMatrix<f64>> = zones
        .iter()
        .map(|z| z.operator(basis, smoothness))
        .collect();
    match regularisation {
        Regularisation::MarginalLikelihood { sigma } => {
            let (fit, k) = solve_most_probable(a, b, &operators, sigma)?;
            Ok((fit, zones[k]))
        }
        _ if zones.len() > 1 => Err(ForceError::Mismatch(
            "the evidence tip prior needs Regularisation::MarginalLikelihood".into(),
        )),
        other => Ok((solve_regularised(a, b, &operators[0], other)?, zones[0])),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Only the marginal likelihood weighs one prior against another: the
    /// evidence tip prior with another rule is an error, not a silent
    /// uniform prior.
    #[test]
    fn the_evidence_prior_needs_the_marginal_likelihood() {
        let basis = ShaftBasis::new(0.01, 1.5e-3).unwrap();
        let n = basis.len();
        let a = DMatrix::from_fn(3 * n, n, |i, j| if i % n == j { 1.0 } else { 0.1 });
        let b = DVector::from_element(3 * n, 1.0);
        let fit = |regularisation, prior| {
            fit_with_tip_prior(
                &a,
                &b,
                &basis,
                Smoothness::FirstDifference,
                regularisation,
                prior,
            )
        };
        assert!(matches!(
            fit(Regularisation::Gcv, TipPrior::Evidence),
            Err(ForceError::Mismatch(_))
        ));
        let (_, zone) = fit(Regularisation::Gcv, TipPrior::Uniform).unwrap();
        assert_eq!(zone, TipZone::UNIFORM);
        let (_, zone) = fit(
            Regularisation::MarginalLikelihood { sigma: 0.01 },
            TipPrior::Evidence,
        )
        .unwrap();
        assert!(zone == TipZone::UNIFORM || TIP_ZONES.contains(&zone.zone));
        assert!(matches!(
            fit(
                Regularisation::Gcv,
                TipPrior::Fixed {
                    zone: 3e-3,
                    relaxation: 2.0
                }
            ),
            Err(ForceError::InvalidValue { .. })
        ));
    }
}
