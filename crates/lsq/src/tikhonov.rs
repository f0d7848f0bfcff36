//! Linear least squares with Tikhonov regularisation,
//!
//! `x_λ = argmin |A x - b|² + λ |L x|²`, i.e. `(AᵀA + λ LᵀL) x_λ = Aᵀ b`,
//!
//! with `λ` fixed, or chosen by the discrepancy principle (known noise
//! `σ`: `|A x_λ - b| = sqrt(m) σ`) or by generalised cross-validation
//! (unknown noise: `λ` minimises `GCV(λ) = m |A x_λ - b|² / (m - tr H_λ)²`,
//! `H_λ = A (AᵀA + λ LᵀL)⁻¹ Aᵀ` the influence matrix).
//!
//! Dense method (for hundreds of unknowns and thousands of data): the pair
//! `(M, N) = (AᵀA, LᵀL)` is diagonalised once. With `μ = tr M / tr N` and the
//! Cholesky factor `M + μ N = C Cᵀ` (positive definite exactly when `A` and
//! `L` share no null direction), `C⁻¹ M C⁻ᵀ = W Θ Wᵀ` with `0 <= θ_i <= 1`
//! and `C⁻¹ μN C⁻ᵀ = W (I - Θ) Wᵀ`. With `ν = λ / μ`, `G = C⁻ᵀ W` and
//! `β = Gᵀ Aᵀ b`, every `λ` then costs `O(n²)`:
//!
//! `x_λ = G diag(1 / (θ_i + ν (1 - θ_i))) β`, `tr H_λ = Σ θ_i / (θ_i + ν (1 - θ_i))`,
//! `|A x_λ - b|² = |b|² - 2 fᵀβ + fᵀ Θ f` with `f_i = β_i / (θ_i + ν (1 - θ_i))`.
//!
//! Forming `AᵀA` squares the condition number of `A`, which is harmless here:
//! the regularisation term dominates exactly the directions it would spoil.

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use crate::error::LsqError;

/// How the regularisation weight `λ` is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum LambdaChoice {
    /// This `λ`.
    Fixed(f64),
    /// Discrepancy principle: residual norm `sqrt(m) σ` for a known noise
    /// standard deviation `σ` of each datum.
    Discrepancy {
        /// Noise standard deviation per datum.
        noise_sigma: f64,
    },
    /// Generalised cross-validation (noise unknown).
    GeneralisedCrossValidation,
}

/// A regularised solution and its diagnostics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TikhonovSolution {
    /// `x_λ`.
    pub x: DVector<f64>,
    /// The `λ` used.
    pub lambda: f64,
    /// `|A x_λ - b|`.
    pub residual_norm: f64,
    /// `|L x_λ|`.
    pub regulariser_norm: f64,
    /// `tr H_λ`: effective number of parameters the data determine.
    pub effective_parameters: f64,
    /// `GCV(λ)`.
    pub gcv: f64,
}

/// Solves `min |A x - b|² + λ |L x|²` with `λ` chosen by `choice`.
/// `regulariser` is `L` (`p × n`; e.g. the identity or
/// [`difference_operator`]).
pub fn tikhonov(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    regulariser: &DMatrix<f64>,
    choice: LambdaChoice,
) -> Result<TikhonovSolution, LsqError> {
    let pencil = Pencil::new(a, b, regulariser)?;
    let nu = match choice {
        LambdaChoice::Fixed(lambda) => {
            if !(lambda.is_finite() && lambda >= 0.0) {
                return Err(LsqError::InvalidOption {
                    field: "lambda",
                    reason: format!("{lambda} must be finite and non-negative"),
                });
            }
            lambda / pencil.mu
        }
        LambdaChoice::Discrepancy { noise_sigma } => {
            if !(noise_sigma.is_finite() && noise_sigma > 0.0) {
                return Err(LsqError::InvalidOption {
                    field: "noise_sigma",
                    reason: format!("{noise_sigma} must be finite and positive"),
                });
            }
            pencil.discrepancy((a.nrows() as f64).sqrt() * noise_sigma)?
        }
        LambdaChoice::GeneralisedCrossValidation => pencil.minimise_gcv(),
    };
    let x = pencil.solution(nu);
    let residual_norm = (a * &x - b).norm();
    let effective_parameters = pencil.trace(nu);
    let m = a.nrows() as f64;
    let gcv = m * residual_norm * residual_norm / (m - effective_parameters).powi(2);
    Ok(TikhonovSolution {
        regulariser_norm: (regulariser * &x).norm(),
        x,
        lambda: nu * pencil.mu,
        residual_norm,
        effective_parameters,
        gcv,
    })
}

/// The `(n - order) × n` finite-difference operator of the given order
/// (0: identity, 1: `x_{i+1} - x_i`, 2: `x_{i+2} - 2 x_{i+1} + x_i`, ...),
/// the usual smoothness regulariser. Returns an empty matrix if `order >= n`.
pub fn difference_operator(n: usize, order: usize) -> DMatrix<f64> {
    let mut operator = DMatrix::identity(n, n);
    for _ in 0..order.min(n) {
        let rows = operator.nrows();
        operator = DMatrix::from_fn(rows - 1, n, |i, j| operator[(i + 1, j)] - operator[(i, j)]);
    }
    operator
}

/// The diagonalised pair `(AᵀA, LᵀL)` of the module doc.
struct Pencil {
    mu: f64,
    theta: DVector<f64>,
    beta: DVector<f64>,
    basis: DMatrix<f64>,
    data_norm_squared: f64,
    m: usize,
}

/// Smallest admissible ratio of Cholesky pivots of `M + μN`.
const SINGULAR_PIVOT_RATIO: f64 = 1e-7;
/// Log-spaced points in the coarse GCV scan.
const GCV_GRID: usize = 200;
/// Bisection / golden-section iterations (in log ν).
const REFINEMENT_STEPS: usize = 100;

impl Pencil {
    fn new(
        a: &DMatrix<f64>,
        b: &DVector<f64>,
        regulariser: &DMatrix<f64>,
    ) -> Result<Self, LsqError> {
        let (m, n) = a.shape();
        if b.len() != m {
            return Err(LsqError::DimensionMismatch {
                what: "data vector b (rows of A)",
                expected: m,
                found: b.len(),
            });
        }
        if regulariser.ncols() != n {
            return Err(LsqError::DimensionMismatch {
                what: "regulariser L columns (columns of A)",
                expected: n,
                found: regulariser.ncols(),
            });
        }
        if n == 0 {
            return Err(LsqError::DimensionMismatch {
                what: "unknowns (columns of A)",
                expected: 1,
                found: 0,
            });
        }
        if a.iter()
            .chain(b.iter())
            .chain(regulariser.iter())
            .any(|x| !x.is_finite())
        {
            return Err(LsqError::InvalidOption {
                field: "A, b, L",
                reason: "entries must be finite".into(),
            });
        }
        let data_gram = a.tr_mul(a);
        let regulariser_gram = regulariser.tr_mul(regulariser);
        let (data_trace, regulariser_trace) = (data_gram.trace(), regulariser_gram.trace());
        if regulariser_trace == 0.0 {
            return Err(LsqError::InvalidOption {
                field: "regulariser",
                reason: "L is zero: nothing regularises the problem".into(),
            });
        }
        let mu = if data_trace > 0.0 {
            data_trace / regulariser_trace
        } else {
            1.0
        };
        let sum = &data_gram + &regulariser_gram * mu;
        let cholesky = sum.cholesky().ok_or(LsqError::SingularRegularisation)?;
        let lower = cholesky.l();
        // Rounding lets a Cholesky factorisation of an exactly singular
        // `M + μN` succeed with a pivot ~ sqrt(eps); a pivot ratio below
        // SINGULAR_PIVOT_RATIO (condition > 1e14) is a shared null space.
        let pivots = lower.diagonal();
        if pivots.min() < SINGULAR_PIVOT_RATIO * pivots.max() {
            return Err(LsqError::SingularRegularisation);
        }
        let half = lower
            .solve_lower_triangular(&data_gram)
            .ok_or(LsqError::SingularRegularisation)?;
        let mut whitened = lower
            .solve_lower_triangular(&half.transpose())
            .ok_or(LsqError::SingularRegularisation)?;
        whitened = (&whitened + whitened.transpose()) * 0.5;
        let eigen = SymmetricEigen::new(whitened);
        let basis = lower
            .tr_solve_lower_triangular(&eigen.eigenvectors)
            .ok_or(LsqError::SingularRegularisation)?;
        let beta = basis.tr_mul(&a.tr_mul(b));
        Ok(Self {
            mu,
            theta: eigen.eigenvalues.map(|t| t.clamp(0.0, 1.0)),
            beta,
            basis,
            data_norm_squared: b.norm_squared(),
            m,
        })
    }

    fn filter(&self, nu: f64) -> DVector<f64> {
        DVector::from_fn(self.theta.len(), |i, _| {
            let t = self.theta[i];
            self.beta[i] / (t + nu * (1.0 - t))
        })
    }

    fn solution(&self, nu: f64) -> DVector<f64> {
        &self.basis * self.filter(nu)
    }

    fn trace(&self, nu: f64) -> f64 {
        self.theta.iter().map(|&t| t / (t + nu * (1.0 - t))).sum()
    }

    fn residual_squared(&self, nu: f64) -> f64 {
        let f = self.filter(nu);
        let quadratic: f64 = f
            .iter()
            .zip(self.theta.iter())
            .map(|(fi, t)| t * fi * fi)
            .sum();
        (self.data_norm_squared - 2.0 * f.dot(&self.beta) + quadratic).max(0.0)
    }

    fn gcv(&self, nu: f64) -> f64 {
        let m = self.m as f64;
        let free = m - self.trace(nu);
        if free <= 0.0 {
            f64::INFINITY
        } else {
            m * self.residual_squared(nu) / (free * free)
        }
    }

    /// The `ν` range over which the filter factors go from 1 to 0.
    fn nu_range(&self) -> (f64, f64) {
        let ratios: Vec<f64> = self
            .theta
            .iter()
            .filter(|&&t| t > 1e-15 && t < 1.0 - 1e-15)
            .map(|&t| t / (1.0 - t))
            .collect();
        let largest = ratios.iter().copied().fold(0.0, f64::max);
        if largest == 0.0 {
            return (1e-12, 1e12);
        }
        let smallest = ratios
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
            .max(1e-16 * largest);
        (0.1 * smallest, 10.0 * largest)
    }

    fn minimise_gcv(&self) -> f64 {
        let (low, high) = self.nu_range();
        let (log_low, log_high) = (low.ln(), high.ln());
        let at = |i: usize| log_low + (log_high - log_low) * i as f64 / (GCV_GRID - 1) as f64;
        let best = (0..GCV_GRID)
            .min_by(|&i, &j| self.gcv(at(i).exp()).total_cmp(&self.gcv(at(j).exp())))
            .unwrap_or(0);
        let (mut left, mut right) = (at(best.saturating_sub(1)), at((best + 1).min(GCV_GRID - 1)));
        let golden = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..REFINEMENT_STEPS {
            let inner_left = right - golden * (right - left);
            let inner_right = left + golden * (right - left);
            if self.gcv(inner_left.exp()) <= self.gcv(inner_right.exp()) {
                right = inner_right;
            } else {
                left = inner_left;
            }
        }
        (0.5 * (left + right)).exp()
    }

    fn discrepancy(&self, target: f64) -> Result<f64, LsqError> {
        let (low, high) = self.nu_range();
        let norm = |nu: f64| self.residual_squared(nu).sqrt();
        let (smallest, largest) = (norm(low), norm(high));
        if !(smallest <= target && target <= largest) {
            return Err(LsqError::DiscrepancyUnreachable {
                target,
                smallest,
                largest,
            });
        }
        // The residual norm increases with λ: bisect in log λ.
        let (mut left, mut right) = (low.ln(), high.ln());
        for _ in 0..REFINEMENT_STEPS {
            let middle = 0.5 * (left + right);
            if norm(middle.exp()) < target {
                left = middle;
            } else {
                right = middle;
            }
        }
        Ok((0.5 * (left + right)).exp())
    }
}
