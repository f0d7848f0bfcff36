//! Finite-difference Jacobians, one column per parameter, in parallel.
//!
//! Column `j` is `(r(p + h_j e_j) - r(p)) / h_j` (forward) or
//! `(r(p + h_j e_j) - r(p - h_j e_j)) / 2 h_j` (central), with the step
//! relative to the parameter's magnitude, `h_j = eta max(|p_j|, s_j)`,
//! `eta = sqrt(eps)` (forward) or `eps^{1/3}` (central), `s_j` the scale.
//! A step that would cross a bound, or whose evaluation fails, is taken on
//! the other side instead. Where the problem has a map of its own near the
//! base point ([`Problem::residuals_near`]), every column and the base
//! value come from that map. A column the problem gives as a multiple of
//! another ([`Problem::chained_column`]) is taken from that one.

use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::EvaluationError;
use crate::parameter::Parameter;
use crate::problem::Problem;

/// Finite-difference formula.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Differences {
    /// One extra evaluation per parameter; error `O(sqrt(eps))`.
    #[default]
    Forward,
    /// Two extra evaluations per parameter; error `O(eps^{2/3})`.
    Central,
}

/// What one finite-difference column needs to know about its parameter.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ColumnSpec {
    pub index: usize,
    pub scale: f64,
    pub lower: Option<f64>,
    pub upper: Option<f64>,
}

impl ColumnSpec {
    pub fn for_parameter(index: usize, parameter: &Parameter) -> Self {
        Self {
            index,
            scale: parameter.effective_scale(),
            lower: parameter.lower,
            upper: parameter.upper,
        }
    }

    fn admits(&self, value: f64) -> bool {
        self.lower.is_none_or(|lower| value >= lower)
            && self.upper.is_none_or(|upper| value <= upper)
    }
}

/// The finite-difference Jacobian of `problem` at `at` for every parameter
/// (fixed ones included), honouring each parameter's scale and bounds.
/// Useful to check an analytic Jacobian.
pub fn finite_difference_jacobian<P: Problem + ?Sized>(
    problem: &P,
    parameters: &[Parameter],
    at: &[f64],
    differences: Differences,
) -> Result<DMatrix<f64>, EvaluationError> {
    let mut base = vec![0.0; problem.num_residuals()];
    problem.residuals(at, &mut base)?;
    let columns: Vec<ColumnSpec> = parameters
        .iter()
        .enumerate()
        .map(|(index, parameter)| ColumnSpec::for_parameter(index, parameter))
        .collect();
    Ok(difference_columns(problem, at, &base, &columns, differences)?.0)
}

/// The columns `columns` of the finite-difference Jacobian at `at`, where
/// `base = r(at)`, and the number of residual evaluations spent.
pub(crate) fn difference_columns<P: Problem + ?Sized>(
    problem: &P,
    at: &[f64],
    base: &[f64],
    columns: &[ColumnSpec],
    differences: Differences,
) -> Result<(DMatrix<f64>, usize), EvaluationError> {
    let m = base.len();
    let mut jacobian = DMatrix::zeros(m, columns.len());
    if m == 0 {
        return Ok((jacobian, 0));
    }
    // A problem with its own map near `at` is differenced with itself.
    let mut local = vec![0.0; m];
    let (base, spent) = match problem.residuals_near(at, at, &mut local) {
        Some(result) => {
            result?;
            if local.iter().any(|r| !r.is_finite()) {
                return Err("the residuals near the base point are not finite".into());
            }
            (local.as_slice(), 1)
        }
        None => (base, 0),
    };
    let chains = chained(problem, at, columns, m);
    let evaluations: Vec<usize> = jacobian
        .as_mut_slice()
        .par_chunks_mut(m)
        .zip(columns.par_iter())
        .zip(&chains)
        .map(|((column, spec), chain)| match chain {
            Some(_) => Ok(0),
            None => difference_column(problem, at, base, spec, differences, column),
        })
        .collect::<Result<_, _>>()?;
    for (k, chain) in chains.iter().enumerate() {
        if let Some((source, factors)) = chain {
            let column: Vec<f64> = jacobian
                .column(*source)
                .iter()
                .zip(factors)
                .map(|(d, f)| f * d)
                .collect();
            jacobian.column_mut(k).copy_from_slice(&column);
        }
    }
    Ok((jacobian, spent + evaluations.iter().sum::<usize>()))
}

/// Per column, the position among `columns` of the column it is a
/// multiple of and the factors, where the problem gives one that is
/// differenced here: its source is among `columns` and not a multiple
/// itself.
fn chained<P: Problem + ?Sized>(
    problem: &P,
    at: &[f64],
    columns: &[ColumnSpec],
    m: usize,
) -> Vec<Option<(usize, Vec<f64>)>> {
    let declared: Vec<Option<(usize, Vec<f64>)>> = columns
        .iter()
        .map(|spec| {
            let (source, factors) = problem.chained_column(at, spec.index)?;
            let position = columns.iter().position(|c| c.index == source)?;
            (factors.len() == m && factors.iter().all(|f| f.is_finite()))
                .then_some((position, factors))
        })
        .collect();
    declared
        .iter()
        .map(|chain| {
            chain
                .as_ref()
                .filter(|(position, _)| declared[*position].is_none())
                .cloned()
        })
        .collect()
}

/// Fills one column; returns the number of evaluations spent.
fn difference_column<P: Problem + ?Sized>(
    problem: &P,
    at: &[f64],
    base: &[f64],
    spec: &ColumnSpec,
    differences: Differences,
    column: &mut [f64],
) -> Result<usize, EvaluationError> {
    let centre = at[spec.index];
    let eta = match differences {
        Differences::Forward => f64::EPSILON.sqrt(),
        Differences::Central => f64::EPSILON.cbrt(),
    };
    let step = eta * centre.abs().max(spec.scale);
    let mut params = at.to_vec();
    let mut evaluate = |offset: f64, out: &mut [f64]| -> Option<f64> {
        let value = centre + offset;
        if !spec.admits(value) {
            return None;
        }
        params[spec.index] = value;
        let result = problem
            .residuals_near(at, &params, out)
            .unwrap_or_else(|| problem.residuals(&params, out));
        let ok = result.is_ok() && out.iter().all(|r| r.is_finite());
        // The step actually taken, exact in floating point.
        ok.then_some(value - centre)
    };
    let mut plus = vec![0.0; base.len()];
    let mut evaluations = 0;
    if differences == Differences::Central {
        let mut minus = vec![0.0; base.len()];
        evaluations += 2;
        if let (Some(up), Some(down)) = (evaluate(step, &mut plus), evaluate(-step, &mut minus)) {
            let width = up - down;
            for ((c, p), q) in column.iter_mut().zip(&plus).zip(&minus) {
                *c = (p - q) / width;
            }
            return Ok(evaluations);
        }
    }
    for offset in [step, -step] {
        evaluations += 1;
        if let Some(taken) = evaluate(offset, &mut plus) {
            for ((c, p), b) in column.iter_mut().zip(&plus).zip(base) {
                *c = (p - b) / taken;
            }
            return Ok(evaluations);
        }
    }
    Err(format!(
        "finite difference for parameter {} failed on both sides of {centre} (step {step:e})",
        spec.index
    )
    .into())
}
