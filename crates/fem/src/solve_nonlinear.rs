//! The hyperelastic equilibrium problem $f_\text{int}(u) = f_\text{ext}$ with
//! the Dirichlet conditions and supports of a [`LinearProblem`], solved by
//! Newton's method or by the cheaper modified (initial-stiffness) Newton.
//!
//! With free dofs $f$ and constrained dofs $c$ (held at their prescribed
//! values), the residual is $r_f(u) = f_{\text{ext},f} - f_{\text{int},f}(u)$,
//! where $f_\text{int}$ includes the linear springs of the supports. An
//! iterate is accepted when
//!
//! $$\frac{\|r_f\|}{\max(\|f_{\text{ext},f}\|,\ \|f_\text{int}(u)\|)} \le \text{tol},$$
//!
//! the denominator being the load carried: applied loads or, in a
//! displacement-driven problem, the reactions (contained in the full
//! $f_\text{int}$). Iterations that stop above the tolerance are
//! [`NonlinearError::NotConverged`], never a returned displacement.
//!
//! - **Newton** ([`HyperelasticProblem::solve_newton`]):
//!   $K_{T,ff}(u)\,\delta = r_f(u)$, $u_f \leftarrow u_f + \alpha\delta$, with
//!   backtracking $\alpha = 1, \tfrac12, \dots$ until
//!   $\|r_f(u + \alpha\delta)\| \le (1 - 10^{-4}\alpha)\|r_f(u)\|$ and every
//!   element keeps $\det F > 0$ (Armijo on $\tfrac12\|r\|^2$, for which the
//!   Newton step is a descent direction). Loads and prescribed values may be
//!   applied in equal increments, each started from the linearised
//!   prediction $K_{T,ff}\,\delta_f = r_f - K_{T,fc}\,\delta_c$ for the
//!   increment $\delta_c$ of the prescribed values. Where $K_{T,ff}$ is
//!   not positive definite (an iterate far from equilibrium, e.g. the
//!   linear prediction of a nearly incompressible body at 20 % strain, or a
//!   real instability) the step uses the linear $K = K_T(0)$ instead, still
//!   subject to the line search. Each iteration assembles $K_T$ and
//!   factorises it numerically, reusing the linear problem's symbolic
//!   analysis.
//! - **Modified Newton** ([`HyperelasticProblem::solve_modified_newton`]):
//!   $u_f \leftarrow u_f + K_{ff}^{-1} r_f(u)$ with the linear problem's
//!   already factorised $K$; each iteration costs one $f_\text{int}$ assembly
//!   and two triangular solves, and many load cases share one blocked solve.
//!   It converges linearly, at a rate that worsens with strain.

use faer::Mat;
use faer::sparse::SparseColMat;

use crate::assemble::multiply;
use crate::assemble_nonlinear::HyperelasticAssembler;
use crate::error::FemError;
use crate::material::Materials;
use crate::nonlinear_error::NonlinearError;
use crate::solve::LinearProblem;

/// Stopping rules of the nonlinear solvers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NonlinearOptions {
    /// Relative residual to reach (see the module docs).
    pub tolerance: f64,
    /// Most iterations per load step (Newton) or in total (modified Newton).
    pub max_iterations: usize,
    /// Equal increments of loads and prescribed values (Newton only).
    pub load_steps: usize,
    /// Most step halvings of the line search (Newton only).
    pub line_search_halvings: usize,
}

impl Default for NonlinearOptions {
    fn default() -> Self {
        Self {
            tolerance: 1e-10,
            max_iterations: 50,
            load_steps: 1,
            line_search_halvings: 12,
        }
    }
}

/// The converged state of one load case.
#[derive(Debug, Clone, PartialEq)]
pub struct NonlinearSolution {
    /// Nodal displacements, interleaved $(u_x, u_y[, u_z])$ per node.
    pub displacement: Vec<f64>,
    /// Reactions $f_\text{int}(u) - f_\text{ext}$ at constrained dofs, zero
    /// elsewhere.
    pub reactions: Vec<f64>,
    /// Iterations done (over all load steps).
    pub iterations: usize,
    /// Relative residual of every iterate, the starting one of each load
    /// step included; the last entry is at most the tolerance.
    pub residual_history: Vec<f64>,
}

/// A neo-Hookean problem sharing constraints, supports, pattern and
/// symbolic factorisation with a [`LinearProblem`].
#[derive(Debug, Clone)]
pub struct HyperelasticProblem<const D: usize> {
    linear: LinearProblem<D>,
    assembler: HyperelasticAssembler<D>,
    /// Spring matrix of the supports, if any.
    springs: Option<SparseColMat<usize, f64>>,
    /// Per entry of the reduced lower triangle, its position in the full pattern.
    gather: Vec<usize>,
}

impl<const D: usize> HyperelasticProblem<D> {
    /// Wraps `linear` (factorised or not; only
    /// [`HyperelasticProblem::solve_modified_newton`] needs its factor).
    /// Its formulation must be plane strain or solid.
    pub fn new(linear: LinearProblem<D>) -> Result<Self, NonlinearError> {
        let assembler = HyperelasticAssembler::new(linear.assembler().clone())?;
        let mesh = linear.mesh();
        let pattern = linear.assembler().pattern();
        let springs = if linear.supports().is_empty() {
            None
        } else {
            let mut s = pattern.zeros();
            for support in linear.supports() {
                support.add_to(mesh, linear.assembler().formulation(), pattern, &mut s)?;
            }
            Some(s)
        };
        let reduced = linear.reduced_stiffness().symbolic();
        let free = linear.free_dofs();
        let mut gather = Vec::with_capacity(reduced.row_idx().len());
        for (jr, &j) in free.iter().enumerate() {
            for &ir in &reduced.row_idx()[reduced.col_ptr()[jr]..reduced.col_ptr()[jr + 1]] {
                let i = free[ir];
                let position = pattern
                    .position(i / D, i % D, j / D, j % D)
                    .unwrap_or_else(|| unreachable!("the reduced pattern is part of the full one"));
                gather.push(position);
            }
        }
        Ok(Self {
            linear,
            assembler,
            springs,
            gather,
        })
    }

    /// The linear problem (constraints, supports, factor of $K$).
    pub fn linear(&self) -> &LinearProblem<D> {
        &self.linear
    }

    /// Mutable access to the linear problem, e.g. to refactorise $K$ for new
    /// materials or change prescribed values.
    pub fn linear_mut(&mut self) -> &mut LinearProblem<D> {
        &mut self.linear
    }

    /// The hyperelastic assembler.
    pub fn assembler(&self) -> &HyperelasticAssembler<D> {
        &self.assembler
    }

    /// $f_\text{int}(u)$ including the supports' springs (full, no
    /// constraints applied).
    pub fn internal_force(
        &self,
        materials: &Materials,
        displacement: &[f64],
    ) -> Result<Vec<f64>, NonlinearError> {
        self.force_and_tangent(materials, displacement, None)
    }

    /// $f_\text{int}(u)$ and, if given, $K_T(u)$ into `tangent`, springs included.
    fn force_and_tangent(
        &self,
        materials: &Materials,
        displacement: &[f64],
        tangent: Option<&mut SparseColMat<usize, f64>>,
    ) -> Result<Vec<f64>, NonlinearError> {
        let mut force = vec![0.0; displacement.len()];
        let mut tangent = tangent;
        self.assembler.assemble_into(
            materials,
            displacement,
            &mut force,
            tangent.as_deref_mut(),
        )?;
        if let Some(springs) = &self.springs {
            for (f, s) in force.iter_mut().zip(multiply(springs, displacement)) {
                *f += s;
            }
            if let Some(k) = tangent {
                for (k, s) in k.val_mut().iter_mut().zip(springs.val()) {
                    *k += s;
                }
            }
        }
        Ok(force)
    }

    /// Free-dof residual $r_f = f_{\text{ext},f} - f_{\text{int},f}$ and its
    /// relative norm.
    fn residual(&self, external: &[f64], force: &[f64]) -> Result<(Vec<f64>, f64), FemError> {
        let free = self.linear.free_dofs();
        let residual: Vec<f64> = free.iter().map(|&d| external[d] - force[d]).collect();
        let load = norm(free.iter().map(|&d| external[d]));
        let scale = load.max(norm(force.iter().copied()));
        let absolute = norm(residual.iter().copied());
        let relative = if scale > 0.0 { absolute / scale } else { 0.0 };
        if !relative.is_finite() {
            return Err(FemError::NonFinite("nonlinear residual"));
        }
        Ok((residual, relative))
    }

    /// Checks a load or displacement vector's length and values.
    fn check_vector(&self, context: &'static str, vector: &[f64]) -> Result<(), FemError> {
        let dof_count = self.linear.mesh().dof_count();
        if vector.len() != dof_count {
            return Err(FemError::DimensionMismatch {
                context,
                expected: dof_count,
                actual: vector.len(),
            });
        }
        if let Some(&value) = vector.iter().find(|v| !v.is_finite()) {
            return Err(FemError::InvalidValue {
                field: context,
                value,
                reason: "must be finite",
            });
        }
        Ok(())
    }

    /// Reactions at the constrained dofs.
    fn reactions(&self, external: &[f64], force: &[f64]) -> Vec<f64> {
        let mut reactions = vec![0.0; force.len()];
        for (d, _) in self.linear.dirichlet().iter() {
            reactions[d] = force[d] - external[d];
        }
        reactions
    }

    /// $\delta_f = K_{T,ff}^{-1} r_f$ with a fresh numeric factorisation of
    /// `tangent`'s free block (the symbolic analysis is the linear problem's).
    fn solve_tangent(
        &self,
        tangent: &SparseColMat<usize, f64>,
        residual: &[f64],
    ) -> Result<Mat<f64>, FemError> {
        let mut reduced = self.linear.reduced_stiffness().clone();
        let values = tangent.val();
        for (r, &p) in reduced.val_mut().iter_mut().zip(&self.gather) {
            *r = values[p];
        }
        let mut factor = self.linear.new_factor();
        factor
            .factorize(reduced.as_ref())
            .map_err(|e| FemError::Factorization(format!("tangent stiffness: {e}")))?;
        let mut solution = Mat::from_fn(residual.len(), 1, |k, _| residual[k]);
        factor.solve_in_place(solution.as_mut())?;
        Ok(solution)
    }

    /// Moves `u` (converged at the previous load step, constrained dofs at
    /// their previous values) to the linearised solution of the next step:
    /// $K_{T,ff}\,\delta_f = r_f(u) - K_{T,fc}\,\delta_c$ with $\delta_c$ the
    /// increment of the prescribed values. Jumping the constrained dofs alone
    /// would strain the boundary elements far beyond the final state. If the
    /// prediction inverts an element, falls back to that jump. Returns
    /// $f_\text{int}$ at the new `u` and leaves $K_T$ there in `tangent`.
    fn predict(
        &self,
        materials: &Materials,
        u: &mut [f64],
        tangent: &mut SparseColMat<usize, f64>,
        external: &[f64],
        fraction: f64,
    ) -> Result<Vec<f64>, NonlinearError> {
        let mut increment = vec![0.0; u.len()];
        for (d, v) in self.linear.dirichlet().iter() {
            increment[d] = fraction * v - u[d];
        }
        let force = self.force_and_tangent(materials, u, Some(tangent))?;
        let coupling = multiply(tangent, &increment);
        let free = self.linear.free_dofs();
        let rhs: Vec<f64> = free
            .iter()
            .map(|&d| external[d] - force[d] - coupling[d])
            .collect();
        let step = self.solve_tangent(tangent, &rhs)?;
        let mut predicted = u.to_vec();
        for (d, v) in self.linear.dirichlet().iter() {
            predicted[d] = fraction * v;
        }
        let jumped = predicted.clone();
        for (k, &d) in free.iter().enumerate() {
            predicted[d] += step[(k, 0)];
        }
        let (state, force) = match self.force_and_tangent(materials, &predicted, Some(tangent)) {
            Ok(force) => (predicted, force),
            Err(NonlinearError::InvertedElement { .. }) => {
                let force = self.force_and_tangent(materials, &jumped, Some(tangent))?;
                (jumped, force)
            }
            Err(other) => return Err(other),
        };
        u.copy_from_slice(&state);
        Ok(force)
    }

    /// Solves $f_\text{int}(u) = f_\text{ext}$ (`loads`, full and interleaved;
    /// entries at constrained dofs are ignored) by Newton's method with line
    /// search. Each load step starts from the linearised prediction at the
    /// previous step's state (zero for the first), except that a given
    /// `start` is the first step's initial guess as it is (e.g. the linear
    /// solution; its constrained dofs are set to their prescribed values).
    pub fn solve_newton(
        &self,
        materials: &Materials,
        loads: &[f64],
        start: Option<&[f64]>,
        options: &NonlinearOptions,
    ) -> Result<NonlinearSolution, NonlinearError> {
        self.check_vector("load vector", loads)?;
        let mut u = match start {
            Some(s) => {
                self.check_vector("starting displacement", s)?;
                s.to_vec()
            }
            None => vec![0.0; loads.len()],
        };
        let free = self.linear.free_dofs();
        let steps = options.load_steps.max(1);
        let pattern = self.linear.assembler().pattern();
        let (mut tangent, mut trial_tangent) = (pattern.zeros(), pattern.zeros());
        let mut rest_tangent = None;
        let mut history = Vec::new();
        let mut total_iterations = 0;
        let mut external = loads.to_vec();
        let mut force = Vec::new();
        for step in 1..=steps {
            let fraction = step as f64 / steps as f64;
            for (e, &f) in external.iter_mut().zip(loads) {
                *e = fraction * f;
            }
            if step == 1 && start.is_some() {
                for (d, v) in self.linear.dirichlet().iter() {
                    u[d] = fraction * v;
                }
                force = self.force_and_tangent(materials, &u, Some(&mut tangent))?;
            } else {
                force = self.predict(materials, &mut u, &mut tangent, &external, fraction)?;
            }
            let mut iteration = 0;
            loop {
                let (residual, relative) = self.residual(&external, &force)?;
                history.push(relative);
                if relative <= options.tolerance {
                    break;
                }
                if iteration == options.max_iterations {
                    return Err(NonlinearError::NotConverged {
                        load_case: 0,
                        load_step: step,
                        iterations: iteration,
                        relative_residual: relative,
                        tolerance: options.tolerance,
                    });
                }
                iteration += 1;
                total_iterations += 1;
                let direction = match self.solve_tangent(&tangent, &residual) {
                    Ok(direction) => direction,
                    // An indefinite K_T (an iterate far from equilibrium, or
                    // a real instability): step with the positive definite
                    // K_T(0) = K instead; the line search still has to
                    // reduce the residual.
                    Err(FemError::Factorization(_)) => {
                        if rest_tangent.is_none() {
                            let mut k = pattern.zeros();
                            self.force_and_tangent(materials, &vec![0.0; u.len()], Some(&mut k))?;
                            rest_tangent = Some(k);
                        }
                        let k = rest_tangent
                            .as_ref()
                            .unwrap_or_else(|| unreachable!("just set"));
                        self.solve_tangent(k, &residual)?
                    }
                    Err(other) => return Err(other.into()),
                };
                let start_norm = norm(residual.iter().copied());
                let mut alpha = 1.0;
                let mut accepted = false;
                for _ in 0..=options.line_search_halvings {
                    let mut trial = u.clone();
                    for (k, &d) in free.iter().enumerate() {
                        trial[d] += alpha * direction[(k, 0)];
                    }
                    match self.force_and_tangent(materials, &trial, Some(&mut trial_tangent)) {
                        Ok(trial_force) => {
                            let (trial_residual, _) = self.residual(&external, &trial_force)?;
                            if norm(trial_residual.iter().copied())
                                <= (1.0 - 1e-4 * alpha) * start_norm
                            {
                                u = trial;
                                force = trial_force;
                                std::mem::swap(&mut tangent, &mut trial_tangent);
                                accepted = true;
                                break;
                            }
                        }
                        // Too long a step inverts an element: shorten it.
                        Err(NonlinearError::InvertedElement { .. }) => {}
                        Err(other) => return Err(other),
                    }
                    alpha *= 0.5;
                }
                if !accepted {
                    return Err(NonlinearError::LineSearchFailed {
                        load_step: step,
                        iteration,
                        relative_residual: relative,
                    });
                }
            }
        }
        Ok(NonlinearSolution {
            reactions: self.reactions(&external, &force),
            displacement: u,
            iterations: total_iterations,
            residual_history: history,
        })
    }

    /// Solves $f_\text{int}(u) = f_\text{ext}$ for each of `loads` by the
    /// modified Newton iteration $u_f \leftarrow u_f + K_{ff}^{-1} r_f(u)$
    /// with the linear problem's current factor (call
    /// [`LinearProblem::factorize`] first, typically with the same
    /// materials), from `starts` (one per load case, e.g. the linear
    /// solutions; constrained dofs are set to their prescribed values) or
    /// from zero. All unconverged cases share one blocked solve per
    /// iteration. A case fails with [`NonlinearError::NotConverged`] after
    /// `max_iterations`, or earlier when its residual grows three iterations
    /// in a row (the iteration diverges); `load_steps` and the line search do
    /// not apply.
    pub fn solve_modified_newton(
        &self,
        materials: &Materials,
        loads: &[&[f64]],
        starts: Option<&[&[f64]]>,
        options: &NonlinearOptions,
    ) -> Result<Vec<NonlinearSolution>, NonlinearError> {
        for f in loads {
            self.check_vector("load vector", f)?;
        }
        let mut states: Vec<Vec<f64>> = match starts {
            Some(starts) => {
                if starts.len() != loads.len() {
                    return Err(FemError::DimensionMismatch {
                        context: "starting displacements (one per load case)",
                        expected: loads.len(),
                        actual: starts.len(),
                    }
                    .into());
                }
                for s in starts {
                    self.check_vector("starting displacement", s)?;
                }
                starts.iter().map(|s| s.to_vec()).collect()
            }
            None => vec![vec![0.0; self.linear.mesh().dof_count()]; loads.len()],
        };
        for u in &mut states {
            for (d, v) in self.linear.dirichlet().iter() {
                u[d] = v;
            }
        }
        let free = self.linear.free_dofs();
        let mut histories = vec![Vec::new(); loads.len()];
        let mut iterations = vec![0; loads.len()];
        let mut final_forces: Vec<Option<Vec<f64>>> = vec![None; loads.len()];
        loop {
            let mut active = Vec::new();
            for (case, (u, external)) in states.iter().zip(loads).enumerate() {
                if final_forces[case].is_some() {
                    continue;
                }
                let force = self.internal_force(materials, u)?;
                let (residual, relative) = self.residual(external, &force)?;
                let history = &mut histories[case];
                history.push(relative);
                if relative <= options.tolerance {
                    final_forces[case] = Some(force);
                    continue;
                }
                if iterations[case] >= options.max_iterations || grows_three_times(history) {
                    return Err(NonlinearError::NotConverged {
                        load_case: case,
                        load_step: 1,
                        iterations: iterations[case],
                        relative_residual: relative,
                        tolerance: options.tolerance,
                    });
                }
                active.push((case, residual));
            }
            if active.is_empty() {
                break;
            }
            let mut corrections = Mat::from_fn(free.len(), active.len(), |k, j| active[j].1[k]);
            self.linear.solve_reduced_in_place(corrections.as_mut())?;
            for (j, (case, _)) in active.iter().enumerate() {
                for (k, &d) in free.iter().enumerate() {
                    states[*case][d] += corrections[(k, j)];
                }
                iterations[*case] += 1;
            }
        }
        Ok(states
            .into_iter()
            .zip(final_forces)
            .zip(histories)
            .zip(iterations)
            .zip(loads)
            .map(|((((u, force), history), iterations), external)| {
                let force = force.unwrap_or_else(|| unreachable!("every case converged"));
                NonlinearSolution {
                    reactions: self.reactions(external, &force),
                    displacement: u,
                    iterations,
                    residual_history: history,
                }
            })
            .collect())
    }
}

/// Whether the last three iterations each increased the residual.
fn grows_three_times(history: &[f64]) -> bool {
    history.len() >= 4 && history.windows(2).rev().take(3).all(|w| w[1] > w[0])
}

fn norm(values: impl Iterator<Item = f64>) -> f64 {
    values.map(|v| v * v).sum::<f64>().sqrt()
}
