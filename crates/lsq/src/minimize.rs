//! The Levenberg-Marquardt iteration (the algorithm is documented on
//! [`LevenbergMarquardt`]).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::differentiate::{ColumnSpec, Differences, difference_columns};
use crate::error::LsqError;
use crate::parameter::Parameter;
use crate::problem::Problem;
use crate::report::{Evaluations, FitReport, Termination};
use crate::transform::Transform;
use crate::uncertainty::{AtOptimum, CovarianceScaling, Uncertainty, estimate};

/// Stopping rules and numerical choices of [`LevenbergMarquardt`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Options {
    /// Stop when the actual and predicted relative cost reductions of a
    /// step are both below this. MINPACK also asks that the actual be at
    /// most twice the predicted; that is left out, as SciPy's trust-region
    /// solvers leave it out: at reductions this small the ratio of the two
    /// reflects the residuals' own rounding and inner tolerances (a model
    /// with an iterative inner solve), and the fits of needle-diagnose
    /// took two to four more Jacobians chasing ratios of 2 to 40 between
    /// reductions below $10^{-8}$ of the cost.
    pub function_tolerance: f64,
    /// Stop when the trust radius `Δ <= step_tolerance · |D u|`.
    pub step_tolerance: f64,
    /// Stop when `max_j |J_jᵀ r| / (|J_j| |r|) <= gradient_tolerance`.
    pub gradient_tolerance: f64,
    /// Maximum number of residual evaluations (finite differences excluded).
    pub max_evaluations: usize,
    /// Initial trust radius as a multiple of `|D u₀|` (or absolute when
    /// `u₀ = 0`); Moré's `factor`.
    pub initial_step_bound: f64,
    /// Finite-difference formula when the problem has no analytic Jacobian.
    pub differences: Differences,
    /// How the covariance is scaled.
    pub covariance_scaling: CovarianceScaling,
    /// Singular values of the column-equilibrated Jacobian below this
    /// fraction of the largest count as zero (rank deficiency). The default
    /// `1e-7` lies above the noise of forward differences (`~1e-8`).
    pub rank_tolerance: f64,
    /// A parameter within this fraction of its scale (or of its interval
    /// width) from a bound is reported as on the bound.
    pub bound_tolerance: f64,
    /// Whether the report carries the covariance at the optimum. A stop
    /// right after an accepted step then takes one more Jacobian, at the
    /// accepted point: as costly as one residual evaluation per free
    /// parameter when differenced. Off, that Jacobian is skipped and such a
    /// stop reports [`ParameterStatus::NotComputed`](crate::ParameterStatus)
    /// for every free parameter and a `gradient_norm` of NaN; a stop on a
    /// rejected step still has its Jacobian at the optimum and reports both.
    /// For fits whose optimum alone is wanted. Absent from a file, on.
    #[serde(default = "uncertainty_by_default")]
    pub uncertainty: bool,
    /// With `uncertainty` on, whether a stop for
    /// [`Termination::CostReduction`] right after an accepted step ends at
    /// the step's start, where the Jacobian (new, not updated) was taken,
    /// rather than at its end with one more Jacobian for the covariance.
    /// The step lowered the cost by at most
    /// `function_tolerance` of it, so the start is an optimum to that
    /// tolerance; its parameters differ from the end's by about
    /// $\sqrt{\epsilon\chi^2}$ standard errors or less ($\epsilon$ the
    /// tolerance; 0.03 for $10^{-8}$ and $\chi^2 = 84{,}000$), where a
    /// Gauss-Newton step would have converged them further. For fits whose
    /// Jacobian costs many evaluations; the report's
    /// [`jacobian`](crate::FitReport::jacobian) is then the one at the
    /// step's start. Absent from a file, off.
    #[serde(default)]
    pub end_at_last_jacobian: bool,
    /// Whether the Jacobian is differenced afresh after every accepted
    /// step or updated from the step's residuals. Absent from a file,
    /// afresh.
    #[serde(default)]
    pub jacobian_updates: JacobianUpdates,
}

/// How the Jacobian follows the iteration (see [`LevenbergMarquardt`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum JacobianUpdates {
    /// A new Jacobian after every accepted step.
    #[default]
    Never,
    /// Broyden's rank-one update after an accepted step whose reduction the
    /// Jacobian predicted well; a new one after a step it predicted badly
    /// and before the fit stops, so the fit ends as it would with new
    /// Jacobians throughout. For Jacobians that cost many evaluations.
    Broyden,
    /// As `Broyden`, but the fit may stop on an updated Jacobian (with a
    /// new one at the optimum only when [`Options::uncertainty`] asks for
    /// the covariance): its optimum is then only as close as the update's
    /// gradient says. A step whose actual and predicted reductions are both
    /// below `function_tolerance` stops the fit even when their ratio is
    /// poor, which at that size is rounding, not a wrong Jacobian. For fits
    /// whose misfit may err on the high side.
    BroydenStopOnUpdate,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            function_tolerance: 1e-10,
            step_tolerance: 1e-10,
            gradient_tolerance: 1e-10,
            max_evaluations: 2000,
            initial_step_bound: 100.0,
            differences: Differences::Forward,
            covariance_scaling: CovarianceScaling::KnownNoise,
            rank_tolerance: 1e-7,
            bound_tolerance: 1e-6,
            uncertainty: true,
            end_at_last_jacobian: false,
            jacobian_updates: JacobianUpdates::Never,
        }
    }
}

fn uncertainty_by_default() -> bool {
    true
}

impl Options {
    fn validate(&self) -> Result<(), LsqError> {
        let positive = |field: &'static str, value: f64| {
            if value.is_finite() && value >= 0.0 {
                Ok(())
            } else {
                Err(LsqError::InvalidOption {
                    field,
                    reason: format!("{value} must be finite and non-negative"),
                })
            }
        };
        positive("function_tolerance", self.function_tolerance)?;
        positive("step_tolerance", self.step_tolerance)?;
        positive("gradient_tolerance", self.gradient_tolerance)?;
        positive("rank_tolerance", self.rank_tolerance)?;
        positive("bound_tolerance", self.bound_tolerance)?;
        if !(self.initial_step_bound.is_finite() && self.initial_step_bound > 0.0) {
            return Err(LsqError::InvalidOption {
                field: "initial_step_bound",
                reason: format!("{} must be finite and positive", self.initial_step_bound),
            });
        }
        if self.max_evaluations == 0 {
            return Err(LsqError::InvalidOption {
                field: "max_evaluations",
                reason: "must be at least 1".into(),
            });
        }
        Ok(())
    }
}

/// The bounded, scaled Levenberg-Marquardt minimiser.
///
/// In the internal coordinates `u` (see [`transform`](crate::transform)),
/// with `r` the residuals and `J = ∂r/∂u`, each trial step solves
///
/// `(Jᵀ J + λ Dᵀ D) δ = -Jᵀ r`
///
/// as the linear least-squares problem `min |[R; sqrt(λ) D] δ + [Qᵀ r; 0]|`
/// where `J = Q R` is factored once per Jacobian, so the condition number is
/// never squared and each new `λ` costs one small `(2n × n)` QR. `D` is
/// Moré's scaling: `D_jj` = the largest column norm `|J_j|` seen so far, which
/// makes the iteration invariant to the units of the parameters.
///
/// `λ` is not updated blindly but chosen, as in Moré (1978) "The
/// Levenberg-Marquardt algorithm: implementation and theory", so that the
/// scaled step fills a trust region: `λ = 0` if the Gauss-Newton step has
/// `|D δ| <= 1.1 Δ`, else `| |D δ(λ)| - Δ | <= 0.1 Δ` by safeguarded Newton
/// iterations on `φ(λ) = |D δ(λ)| - Δ`. The radius `Δ` follows the ratio `ρ`
/// of actual to predicted reduction: shrunk (by 0.1 to 0.5) when `ρ < 1/4`,
/// doubled when `ρ > 3/4`; the step is accepted when `ρ >= 1e-4`. A trial
/// point where the residuals fail or are not finite counts as `ρ = -∞`.
///
/// With [`JacobianUpdates::Broyden`], an accepted step `δ` with `ρ >= 1/4`
/// updates the Jacobian by Broyden's rank-one formula
/// `J ← J + (Δr - J δ) δᵀ / (δᵀ δ)`, `Δr` the change of the residuals
/// (Dennis & Schnabel, *Numerical Methods for Unconstrained Optimization*,
/// §8.1), instead of differencing it again. A step with `ρ < 1/4` on an
/// updated Jacobian leaves the radius alone (the Jacobian, not the radius,
/// is suspect) and the next Jacobian is new; so is the one before any stop.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LevenbergMarquardt {
    /// Its options.
    pub options: Options,
}

/// Reduction ratio below which a step is rejected.
const ACCEPT_RATIO: f64 = 1e-4;
/// Relative accuracy of `|D δ| = Δ` in the choice of `λ`.
const RADIUS_ACCURACY: f64 = 0.1;
/// Newton iterations on `λ` per step.
const MAX_LAMBDA_ITERATIONS: usize = 10;

/// The map between the internal vector `u` (free parameters only) and the
/// full external parameter vector.
struct Coordinates {
    held: Vec<f64>,
    free: Vec<usize>,
    transforms: Vec<Transform>,
    columns: Vec<ColumnSpec>,
}

impl Coordinates {
    fn new(parameters: &[Parameter]) -> Result<Self, LsqError> {
        for parameter in parameters {
            parameter.validate()?;
        }
        let free: Vec<usize> = (0..parameters.len())
            .filter(|&j| !parameters[j].fixed)
            .collect();
        if free.is_empty() {
            return Err(LsqError::NoFreeParameters);
        }
        Ok(Self {
            held: parameters.iter().map(|p| p.initial).collect(),
            transforms: free
                .iter()
                .map(|&j| Transform::for_parameter(&parameters[j]))
                .collect(),
            columns: free
                .iter()
                .map(|&j| ColumnSpec::for_parameter(j, &parameters[j]))
                .collect(),
            free,
        })
    }

    fn initial(&self) -> DVector<f64> {
        DVector::from_iterator(
            self.free.len(),
            self.free
                .iter()
                .zip(&self.transforms)
                .map(|(&j, t)| t.internal(self.held[j])),
        )
    }

    fn external(&self, u: &DVector<f64>) -> Vec<f64> {
        let mut p = self.held.clone();
        for ((&j, t), &uj) in self.free.iter().zip(&self.transforms).zip(u.iter()) {
            p[j] = t.external(uj);
        }
        p
    }

    fn derivatives(&self, u: &DVector<f64>) -> Vec<f64> {
        self.transforms
            .iter()
            .zip(u.iter())
            .map(|(t, &uj)| t.derivative(uj))
            .collect()
    }
}

/// The Jacobian factored at one point: `J = Q R` and `Qᵀ r`.
struct Factored {
    /// `J` in the internal coordinates.
    jacobian: DMatrix<f64>,
    /// Whether `J` was evaluated here rather than updated.
    fresh: bool,
    r_factor: DMatrix<f64>,
    q_t_residual: DVector<f64>,
    gradient: DVector<f64>,
    column_norms: Vec<f64>,
}

impl Factored {
    /// `jacobian` (internal coordinates) factored with the residuals `r`.
    fn new(jacobian: DMatrix<f64>, r: &[f64], fresh: bool) -> Self {
        let residual = DVector::from_column_slice(r);
        let gradient = jacobian.tr_mul(&residual);
        let column_norms = jacobian.column_iter().map(|c| c.norm()).collect();
        let rows = jacobian.nrows().min(jacobian.ncols());
        let qr = jacobian.clone().qr();
        let mut rotated = residual;
        qr.q_tr_mul(&mut rotated);
        Self {
            jacobian,
            fresh,
            r_factor: qr.r(),
            q_t_residual: rotated.rows(0, rows).into_owned(),
            gradient,
            column_norms,
        }
    }

    /// Broyden's update after the step `step` changed the residuals from
    /// `before` to `after`, factored with `after`.
    fn updated(self, step: &DVector<f64>, before: &[f64], after: &[f64]) -> Self {
        let mut jacobian = self.jacobian;
        let predicted = &jacobian * step;
        let change = DVector::from_iterator(
            after.len(),
            after
                .iter()
                .zip(before)
                .zip(predicted.iter())
                .map(|((a, b), p)| a - b - p),
        );
        jacobian.ger(1.0 / step.norm_squared(), &change, step, 1.0);
        Self::new(jacobian, after, false)
    }
}

impl LevenbergMarquardt {
    /// A minimiser with the given options.
    pub fn new(options: Options) -> Self {
        Self { options }
    }

    /// Minimises `½ Σ r_i(p)²` from the parameters' initial values.
    pub fn minimize<P: Problem + ?Sized>(
        &self,
        problem: &P,
        parameters: &[Parameter],
    ) -> Result<FitReport, LsqError> {
        self.minimize_with_columns(problem, parameters, &[])
    }

    /// [`minimize`](Self::minimize) with the first Jacobian's columns taken
    /// from `start_columns` where given: per parameter, $\partial r/\partial p_j$
    /// at or near the initial point (from an earlier fit nearby), `None`
    /// to difference it. An empty slice gives none. The given columns count
    /// as an updated Jacobian (see [`JacobianUpdates`]): a step they predict
    /// badly is followed by a new Jacobian.
    pub fn minimize_with_columns<P: Problem + ?Sized>(
        &self,
        problem: &P,
        parameters: &[Parameter],
        start_columns: &[Option<&[f64]>],
    ) -> Result<FitReport, LsqError> {
        self.options.validate()?;
        if problem.num_parameters() != parameters.len() {
            return Err(LsqError::ParameterCount {
                expected: problem.num_parameters(),
                given: parameters.len(),
            });
        }
        let coordinates = Coordinates::new(parameters)?;
        let m = problem.num_residuals();
        if m == 0 {
            return Err(LsqError::DimensionMismatch {
                what: "residuals (Problem::num_residuals)",
                expected: 1,
                found: 0,
            });
        }
        if !start_columns.is_empty() && start_columns.len() != parameters.len() {
            return Err(LsqError::DimensionMismatch {
                what: "start columns (one per parameter)",
                expected: parameters.len(),
                found: start_columns.len(),
            });
        }
        for column in start_columns.iter().flatten() {
            if column.len() != m {
                return Err(LsqError::DimensionMismatch {
                    what: "a start column (one value per residual)",
                    expected: m,
                    found: column.len(),
                });
            }
            if column.iter().any(|v| !v.is_finite()) {
                return Err(LsqError::InvalidOption {
                    field: "start_columns",
                    reason: "a start column has a value that is not finite".into(),
                });
            }
        }
        let seeded = coordinates
            .columns
            .iter()
            .any(|c| start_columns.get(c.index).is_some_and(Option::is_some));
        let k = coordinates.free.len();
        let options = &self.options;

        let mut u = coordinates.initial();
        let mut p = coordinates.external(&u);
        let mut r = vec![0.0; m];
        problem
            .residuals(&p, &mut r)
            .map_err(|source| LsqError::InitialEvaluation { source })?;
        if let Some(index) = r.iter().position(|x| !x.is_finite()) {
            return Err(LsqError::NonFiniteResidual {
                index,
                value: r[index],
            });
        }
        let mut evaluations = Evaluations {
            residuals: 1,
            ..Evaluations::default()
        };
        let mut cost = half_sum_of_squares(&r);
        let mut lambda = 0.0;
        let mut radius = 0.0;
        let mut scaling = DVector::<f64>::zeros(k);
        let mut iterations = 0;
        let mut trial_r = vec![0.0; m];

        // `factored` is the Jacobian at the optimum unless `false` here.
        let updates = options.jacobian_updates;
        let mut carried: Option<Factored> = None;
        let (termination, factored, at_optimum) = 'outer: loop {
            let factored = match carried.take() {
                Some(updated) => updated,
                None if seeded && iterations == 0 => self.seeded(
                    problem,
                    &coordinates,
                    (&u, &p, &r),
                    start_columns,
                    &mut evaluations,
                )?,
                None => self.factor(problem, &coordinates, &u, &p, &r, &mut evaluations)?,
            };
            iterations += 1;
            // A stop judged on an updated Jacobian is confirmed on a new one.
            let confirm = !factored.fresh && updates != JacobianUpdates::BroydenStopOnUpdate;
            if cost == 0.0 {
                break (Termination::ZeroCost, factored, true);
            }
            for (d, &norm) in scaling.iter_mut().zip(&factored.column_norms) {
                *d = d.max(norm);
                if *d == 0.0 {
                    *d = 1.0;
                }
            }
            if iterations == 1 {
                let scaled_start = scaling.component_mul(&u).norm();
                radius = options.initial_step_bound
                    * if scaled_start > 0.0 {
                        scaled_start
                    } else {
                        1.0
                    };
            }
            let residual_norm = (2.0 * cost).sqrt();
            let scaled_gradient = factored
                .gradient
                .iter()
                .zip(&factored.column_norms)
                .filter(|&(_, &norm)| norm > 0.0)
                .map(|(g, norm)| g.abs() / (norm * residual_norm))
                .fold(0.0, f64::max);
            if scaled_gradient <= options.gradient_tolerance {
                if confirm {
                    continue 'outer;
                }
                if factored.fresh {
                    break (Termination::Gradient, factored, true);
                }
                if options.uncertainty {
                    let factored =
                        self.factor(problem, &coordinates, &u, &p, &r, &mut evaluations)?;
                    break (Termination::Gradient, factored, true);
                }
                break (Termination::Gradient, factored, false);
            }

            // The accepted step and the residuals before it, when the next
            // Jacobian is to be updated rather than evaluated.
            let update = loop {
                let (chosen, step) = trust_region_step(&factored, &scaling, radius, lambda);
                let scaled_step = scaling.component_mul(&step).norm();
                if iterations == 1 {
                    radius = radius.min(scaled_step);
                }
                let trial_u = &u + &step;
                let trial_p = coordinates.external(&trial_u);
                evaluations.residuals += 1;
                let evaluated = problem.residuals(&trial_p, &mut trial_r).is_ok()
                    && trial_r.iter().all(|x| x.is_finite());
                let trial_cost = if evaluated {
                    half_sum_of_squares(&trial_r)
                } else {
                    f64::INFINITY
                };
                // Reductions relative to the cost (Moré's actred, prered).
                let actual = if trial_cost < 100.0 * cost {
                    1.0 - trial_cost / cost
                } else {
                    -1.0
                };
                let linear = (&factored.r_factor * &step).norm_squared() / (2.0 * cost);
                let damping_term = chosen * scaled_step * scaled_step / (2.0 * cost);
                let predicted = linear + 2.0 * damping_term;
                let directional = -(linear + damping_term);
                let ratio = if predicted > 0.0 {
                    actual / predicted
                } else {
                    0.0
                };
                let accepted = ratio >= ACCEPT_RATIO;
                let badly_predicted = !factored.fresh && ratio <= 0.25;
                if !badly_predicted {
                    lambda = chosen;
                    if ratio <= 0.25 {
                        let mut shrink = if actual >= 0.0 {
                            0.5
                        } else {
                            0.5 * directional / (directional + 0.5 * actual)
                        };
                        if !evaluated || trial_cost >= 100.0 * cost || shrink < 0.1 {
                            shrink = 0.1;
                        }
                        radius = shrink * radius.min(scaled_step / 0.1);
                        lambda /= shrink;
                    } else if lambda == 0.0 || ratio >= 0.75 {
                        radius = 2.0 * scaled_step;
                        lambda *= 0.5;
                    }
                }
                // Where the step started, which a negligible step returns to.
                let mut before = None;
                if accepted {
                    before = Some((std::mem::replace(&mut u, trial_u), cost));
                    p = trial_p;
                    std::mem::swap(&mut r, &mut trial_r);
                    cost = trial_cost;
                }
                let scaled_position = scaling.component_mul(&u).norm();
                let out_of_evaluations = evaluations.residuals >= options.max_evaluations;
                let negligible = actual.abs() <= options.function_tolerance
                    && predicted <= options.function_tolerance;
                let stop = if badly_predicted {
                    if negligible && updates == JacobianUpdates::BroydenStopOnUpdate {
                        // At reductions below the tolerance the ratio is
                        // rounding; the updated Jacobian sees no more to
                        // gain, which is all this mode asks.
                        Some(Termination::CostReduction)
                    } else if !out_of_evaluations {
                        // A new Jacobian at the current point first.
                        continue 'outer;
                    } else {
                        Some(Termination::MaxEvaluations)
                    }
                } else if cost == 0.0 {
                    Some(Termination::ZeroCost)
                } else if negligible {
                    Some(Termination::CostReduction)
                } else if radius <= options.step_tolerance * scaled_position {
                    Some(Termination::StepSize)
                } else if out_of_evaluations {
                    Some(Termination::MaxEvaluations)
                } else if radius <= f64::EPSILON * scaled_position || radius <= f64::MIN_POSITIVE {
                    Some(Termination::DampingExhausted)
                } else {
                    None
                };
                if let Some(termination) = stop {
                    if confirm && termination != Termination::MaxEvaluations {
                        if accepted {
                            break None;
                        }
                        continue 'outer;
                    }
                    if accepted || !factored.fresh {
                        let at_last_jacobian = options.uncertainty
                            && options.end_at_last_jacobian
                            && factored.fresh
                            && termination == Termination::CostReduction;
                        if let (true, Some((start, start_cost))) = (at_last_jacobian, before) {
                            u = start;
                            p = coordinates.external(&u);
                            std::mem::swap(&mut r, &mut trial_r);
                            cost = start_cost;
                            break 'outer (termination, factored, true);
                        }
                        if options.uncertainty {
                            let factored =
                                self.factor(problem, &coordinates, &u, &p, &r, &mut evaluations)?;
                            break 'outer (termination, factored, true);
                        }
                        break 'outer (termination, factored, false);
                    }
                    break 'outer (termination, factored, true);
                }
                if accepted {
                    break (updates != JacobianUpdates::Never).then_some(step);
                }
            };
            // `trial_r` holds the residuals before the accepted step.
            carried = update.map(|step| factored.updated(&step, &trial_r, &r));
        };

        let derivatives = coordinates.derivatives(&u);
        let at_bound: Vec<bool> = coordinates
            .transforms
            .iter()
            .zip(&coordinates.free)
            .map(|(t, &j)| t.is_at_bound(p[j], options.bound_tolerance))
            .collect();
        let chi2 = 2.0 * cost;
        let dof = m.saturating_sub(k);
        let jacobian = if at_optimum && factored.fresh {
            external_columns(&factored.jacobian, &coordinates, &derivatives, &at_bound)
        } else {
            Vec::new()
        };
        let (uncertainty, gradient_norm) = if at_optimum {
            let uncertainty = estimate(
                &AtOptimum {
                    r_factor: &factored.r_factor,
                    derivatives: &derivatives,
                    free: &coordinates.free,
                    at_bound: &at_bound,
                    total: parameters.len(),
                    dof,
                    chi2,
                },
                options.covariance_scaling,
                options.rank_tolerance,
            );
            (uncertainty, factored.gradient.amax())
        } else {
            let uncertainty = Uncertainty::not_computed(&coordinates.free, parameters.len());
            (uncertainty, f64::NAN)
        };
        Ok(FitReport {
            names: parameters.iter().map(|p| p.name.clone()).collect(),
            params: DVector::from_vec(p),
            cost,
            chi2,
            dof,
            iterations,
            evaluations,
            termination,
            gradient_norm,
            uncertainty,
            jacobian,
        })
    }

    /// The first Jacobian from the given columns, the others differenced
    /// at `p`, factored as an updated one.
    fn seeded<P: Problem + ?Sized>(
        &self,
        problem: &P,
        coordinates: &Coordinates,
        (u, p, r): (&DVector<f64>, &[f64], &[f64]),
        start_columns: &[Option<&[f64]>],
        evaluations: &mut Evaluations,
    ) -> Result<Factored, LsqError> {
        let given = |spec: &ColumnSpec| start_columns[spec.index];
        let missing: Vec<ColumnSpec> = coordinates
            .columns
            .iter()
            .filter(|spec| given(spec).is_none())
            .copied()
            .collect();
        let mut differenced = DMatrix::zeros(r.len(), 0);
        if !missing.is_empty() {
            let (columns, spent) =
                difference_columns(problem, p, r, &missing, self.options.differences).map_err(
                    |source| LsqError::JacobianEvaluation {
                        params: p.to_vec(),
                        source,
                    },
                )?;
            evaluations.jacobians += 1;
            evaluations.finite_difference_residuals += spent;
            differenced = columns;
        }
        let mut jacobian = DMatrix::zeros(r.len(), coordinates.columns.len());
        let mut next = 0;
        for (j, spec) in coordinates.columns.iter().enumerate() {
            match given(spec) {
                Some(column) => jacobian.column_mut(j).copy_from_slice(column),
                None => {
                    jacobian.set_column(j, &differenced.column(next));
                    next += 1;
                }
            }
        }
        for (mut column, derivative) in jacobian.column_iter_mut().zip(coordinates.derivatives(u)) {
            column *= derivative;
        }
        Ok(Factored::new(jacobian, r, false))
    }

    /// Evaluates the Jacobian at `p` (with respect to `u`) and factors it.
    fn factor<P: Problem + ?Sized>(
        &self,
        problem: &P,
        coordinates: &Coordinates,
        u: &DVector<f64>,
        p: &[f64],
        r: &[f64],
        evaluations: &mut Evaluations,
    ) -> Result<Factored, LsqError> {
        let m = r.len();
        let failure = |source| LsqError::JacobianEvaluation {
            params: p.to_vec(),
            source,
        };
        let mut full = DMatrix::zeros(m, p.len());
        let mut jacobian = match problem.jacobian(p, &mut full) {
            Some(result) => {
                result.map_err(failure)?;
                if full.iter().any(|x| !x.is_finite()) {
                    return Err(failure("the analytic Jacobian is not finite".into()));
                }
                if coordinates.free.len() == p.len() {
                    full
                } else {
                    full.select_columns(&coordinates.free)
                }
            }
            None => {
                drop(full);
                let (columns, spent) = difference_columns(
                    problem,
                    p,
                    r,
                    &coordinates.columns,
                    self.options.differences,
                )
                .map_err(failure)?;
                evaluations.finite_difference_residuals += spent;
                columns
            }
        };
        evaluations.jacobians += 1;
        for (mut column, derivative) in jacobian.column_iter_mut().zip(coordinates.derivatives(u)) {
            column *= derivative;
        }
        Ok(Factored::new(jacobian, r, true))
    }
}

/// The columns $\partial r/\partial p_j$ of `jacobian`, which is taken in
/// the internal coordinates ($\partial r/\partial u_j = \partial r/\partial p_j
/// \, dp_j/du_j$, `derivatives`), one per parameter: `None` for held ones
/// and for free ones `at_bound`.
fn external_columns(
    jacobian: &DMatrix<f64>,
    coordinates: &Coordinates,
    derivatives: &[f64],
    at_bound: &[bool],
) -> Vec<Option<DVector<f64>>> {
    let mut columns = vec![None; coordinates.held.len()];
    for (position, &j) in coordinates.free.iter().enumerate() {
        let derivative = derivatives[position];
        if !at_bound[position] && derivative != 0.0 {
            columns[j] = Some(jacobian.column(position) / derivative);
        }
    }
    columns
}

/// Solves `min |[R; sqrt(λ) D] δ + [Qᵀ r; 0]|` by a second, small QR;
/// returns `δ` and the triangular factor `R_λ` (`R_λᵀ R_λ = Rᵀ R + λ DᵀD`),
/// or `None` if that system is singular (only possible for `λ = 0`).
fn damped_step(
    factored: &Factored,
    scaling: &DVector<f64>,
    lambda: f64,
) -> Option<(DVector<f64>, DMatrix<f64>)> {
    let k = scaling.len();
    let rows = factored.r_factor.nrows();
    let mut stacked = DMatrix::zeros(rows + k, k);
    stacked.rows_mut(0, rows).copy_from(&factored.r_factor);
    let root = lambda.sqrt();
    for j in 0..k {
        stacked[(rows + j, j)] = root * scaling[j];
    }
    let mut rhs = DVector::zeros(rows + k);
    rhs.rows_mut(0, rows).copy_from(&(-&factored.q_t_residual));
    let qr = stacked.qr();
    qr.q_tr_mul(&mut rhs);
    let triangular = qr.r();
    let diagonal = triangular.diagonal().abs();
    if diagonal.min() <= 1e-14 * diagonal.max() {
        return None;
    }
    let step = triangular.solve_upper_triangular(&rhs.rows(0, k))?;
    step.iter()
        .all(|x| x.is_finite())
        .then_some((step, triangular))
}

/// Moré's choice of `λ` for the trust radius `Δ` (`radius`), starting from
/// the previous `λ`: returns `(λ, δ(λ))` with `λ = 0` and `|D δ| <= 1.1 Δ`,
/// or `| |D δ| - Δ | <= 0.1 Δ`, or the last Newton iterate.
fn trust_region_step(
    factored: &Factored,
    scaling: &DVector<f64>,
    radius: f64,
    previous_lambda: f64,
) -> (f64, DVector<f64>) {
    // φ'(λ)/|Dδ| from R_λ: y solves R_λᵀ y = D (D δ) / |D δ|.
    let newton_denominator = |triangular: &DMatrix<f64>, step: &DVector<f64>, norm: f64| {
        let direction = scaling.component_mul(&scaling.component_mul(step)) / norm;
        triangular
            .tr_solve_upper_triangular(&direction)
            .map_or(f64::INFINITY, |y| radius * y.norm_squared())
    };
    let mut lower = 0.0;
    let gauss_newton = damped_step(factored, scaling, 0.0);
    if let Some((step, triangular)) = &gauss_newton {
        let norm = scaling.component_mul(step).norm();
        let excess = norm - radius;
        if excess <= RADIUS_ACCURACY * radius {
            return (0.0, step.clone());
        }
        lower = excess / newton_denominator(triangular, step, norm);
    }
    let gradient_norm = factored.gradient.component_div(scaling).norm();
    let mut upper = gradient_norm / radius;
    if upper == 0.0 {
        upper = f64::MIN_POSITIVE / radius.min(0.1);
    }
    let mut lambda = previous_lambda.max(lower).min(upper);
    if lambda == 0.0 {
        lambda = gauss_newton.as_ref().map_or(upper, |(step, _)| {
            gradient_norm / scaling.component_mul(step).norm()
        });
    }
    let mut previous_excess = f64::NEG_INFINITY;
    let mut last = None;
    for iteration in 0..MAX_LAMBDA_ITERATIONS {
        if lambda == 0.0 {
            lambda = f64::MIN_POSITIVE.max(1e-3 * upper);
        }
        let Some((step, triangular)) = damped_step(factored, scaling, lambda) else {
            lambda = (10.0 * lambda).max(upper);
            continue;
        };
        let norm = scaling.component_mul(&step).norm();
        let excess = norm - radius;
        if excess.abs() <= RADIUS_ACCURACY * radius
            || (lower == 0.0 && excess <= previous_excess && previous_excess < 0.0)
            || iteration + 1 == MAX_LAMBDA_ITERATIONS
        {
            return (lambda, step);
        }
        let correction = excess / newton_denominator(&triangular, &step, norm);
        if excess > 0.0 {
            lower = lower.max(lambda);
        } else if excess < 0.0 {
            upper = upper.min(lambda);
        }
        lambda = lower.max(lambda + correction);
        previous_excess = excess;
        last = Some((lambda, step));
    }
    last.unwrap_or_else(|| (lambda, DVector::zeros(scaling.len())))
}

fn half_sum_of_squares(r: &[f64]) -> f64 {
    0.5 * r.iter().map(|x| x * x).sum::<f64>()
}
