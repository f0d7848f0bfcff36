//! # needle-lsq: the one least-squares engine of the needle toolkit
//!
//! Every fit in the project goes through this crate: material parameters
//! and force distributions (needle-identify, needle-force), the parameters
//! of every diagnosed effect (needle-diagnose) and camera calibration
//! (needle-vision). It sits below all of them in the chain and knows nothing
//! about needles, meshes or cameras: it sees a residual vector.
//!
//! **Why hand-written.** No maintained Levenberg-Marquardt crate works with
//! nalgebra 0.35 and offers bounds, covariance with rank-deficiency
//! detection and profile likelihood together; this crate does that once,
//! tested on the Moré-Garbow-Hillstrom problems with known minima.
//!
//! ## The objective
//!
//! For parameters `p ∈ R^n` and residuals `r(p) ∈ R^m`, already whitened by
//! the caller (`r_i = (model_i(p) - y_i) / σ_i`),
//!
//! `cost(p) = ½ Σ_i r_i(p)²`,  `χ²(p) = Σ_i r_i(p)² = 2 cost(p)`.
//!
//! ## The Levenberg-Marquardt step
//!
//! With `J = ∂r/∂u` in the internal coordinates `u` and Moré's diagonal
//! scaling `D` (running maximum of the column norms of `J`), each trial step
//! solves
//!
//! `(JᵀJ + λ DᵀD) δ = -Jᵀ r`
//!
//! through QR factorisations (`J = QR` once per Jacobian, then a small QR of
//! `[R; sqrt(λ) D]` per λ), so `JᵀJ` is never formed. λ is chosen so that
//! the scaled step fills a trust region whose radius follows the ratio of
//! actual to predicted reduction (Moré 1978); a trial point where the
//! residuals fail (a singular FEM system, a NaN) is a rejected step, not a
//! crash. Jacobians are analytic
//! when the [`Problem`] provides them, else finite differences evaluated in
//! parallel over parameters (see [`Differences`]). Details on
//! [`LevenbergMarquardt`].
//!
//! Where a differenced Jacobian is costly (each column a finite-element
//! solve), it may instead be updated after a well-predicted step by
//! Broyden's rank-one formula `J ← J + (Δr - J δ) δᵀ / (δᵀ δ)`
//! ([`JacobianUpdates`]), and the first one may be given, column by
//! column, from an earlier fit nearby
//! ([`LevenbergMarquardt::minimize_with_columns`]). Either kind of
//! approximate Jacobian is replaced by a new one after a step it predicts
//! badly; the fit stops on one only when asked to, and then also after a
//! step whose predicted and actual reductions are both below the cost
//! tolerance, however poor their ratio (at that size, rounding).
//!
//! The report carries the Jacobian the covariance came from
//! ([`FitReport::jacobian`]), for later work at the same point; a fit
//! whose last step gains less than its cost tolerance may end at that
//! step's start, where its last Jacobian was taken, instead of taking one
//! more ([`Options::end_at_last_jacobian`]).
//!
//! ## Bounds by transformation
//!
//! A bounded parameter is `p = lo + (hi - lo)(1 + sin u)/2` (two-sided) or
//! `p = lo + s (sqrt(u² + 1) - 1)` (one-sided, `s` its scale); the optimiser
//! works on the unconstrained `u` and the Jacobian is chain-ruled,
//! `∂r/∂u = ∂r/∂p · dp/du` ([`transform`]). Fixed parameters are removed from
//! `u` altogether.
//!
//! ## Covariance and confidence intervals
//!
//! `C = s² (JᵀJ)⁻¹` with `J = ∂r/∂p` at the optimum, `s² = 1` for known
//! noise or `χ²/(m - n)` ([`CovarianceScaling`]). It is computed from the
//! SVD of the column-equilibrated `R`, so a rank-deficient fit is detected:
//! its unidentifiable parameters are listed and get no standard error
//! instead of an infinite or arbitrary one ([`Uncertainty`]). Wald
//! intervals are `p̂_k ± z_{(1+α)/2} sqrt(C_kk)`. A fit whose optimum
//! alone is wanted may skip the Jacobian that a stop after an accepted
//! step takes for it ([`Options::uncertainty`]).
//!
//! ## Profile likelihood
//!
//! `χ²_prof(v) = min_{p_k = v} χ²(p)`; the interval at level `α` is
//! `{v : χ²_prof(v) - χ²_min <= s² χ²_1(α)}` (3.84 at 95 %)
//! ([`LevenbergMarquardt::profile`]).
//!
//! ## Regularised linear least squares
//!
//! [`tikhonov`] solves `min |Ax - b|² + λ |Lx|²` with λ fixed, by the
//! discrepancy principle (`|Ax - b| = sqrt(m) σ`) or by generalised
//! cross-validation, for the force-inversion crate's shaft force
//! distributions.
//!
//! ## Use
//!
//! ```
//! use needle_lsq::{EvaluationError, LevenbergMarquardt, Parameter, Problem};
//!
//! /// y = a exp(-k t), unit noise.
//! struct Decay { t: Vec<f64>, y: Vec<f64> }
//! impl Problem for Decay {
//!     fn num_parameters(&self) -> usize { 2 }
//!     fn num_residuals(&self) -> usize { self.t.len() }
//!     fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
//!         for ((o, t), y) in out.iter_mut().zip(&self.t).zip(&self.y) {
//!             *o = p[0] * (-p[1] * t).exp() - y;
//!         }
//!         Ok(())
//!     }
//! }
//! let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.2).collect();
//! let y = t.iter().map(|t| 3.0 * (-0.7 * t).exp()).collect();
//! let parameters = [Parameter::new("a", 1.0), Parameter::new("k", 1.0).with_lower(0.0)];
//! let fit = LevenbergMarquardt::default().minimize(&Decay { t, y }, &parameters)?;
//! assert!(fit.termination.is_converged());
//! assert!((fit.params[1] - 0.7).abs() < 1e-8);
//! # Ok::<(), needle_lsq::LsqError>(())
//! ```
//!
//! ## What it does not do
//!
//! No global optimisation (a local minimum is reported as such: see the
//! Freudenstein-Roth test), no sparse Jacobians (dense `m × n`, fine for a
//! few hundred parameters), no robust loss functions (whiten or reweight
//! outside), no Student-t intervals (normal quantiles).

mod differentiate;
mod error;
mod minimize;
mod parameter;
mod problem;
mod profile;
mod quantile;
mod report;
mod tikhonov;
pub mod transform;
mod uncertainty;

pub use differentiate::{Differences, finite_difference_jacobian};
pub use error::{EvaluationError, LsqError};
pub use minimize::{JacobianUpdates, LevenbergMarquardt, Options};
pub use parameter::Parameter;
pub use problem::Problem;
pub use profile::{Profile, ProfileOptions, ProfileSpan};
pub use quantile::{chi_square_one_dof, normal_quantile, two_sided_normal};
pub use report::{Evaluations, FitReport, Termination};
pub use tikhonov::{LambdaChoice, TikhonovSolution, difference_operator, tikhonov};
pub use uncertainty::{CovarianceScaling, ParameterStatus, Uncertainty};
