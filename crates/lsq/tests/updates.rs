//! Broyden updates of the Jacobian against a new Jacobian after every
//! accepted step, on the problems of Moré, Garbow & Hillstrom (1981) with
//! finite-difference Jacobians: the same minima and covariances, for fewer
//! evaluations.

mod mgh;

use mgh::Mgh;
use needle_lsq::{FitReport, JacobianUpdates, LevenbergMarquardt, Options};

fn fit(problem: &Mgh, updates: JacobianUpdates) -> FitReport {
    let engine = LevenbergMarquardt::new(Options {
        jacobian_updates: updates,
        ..Options::default()
    });
    engine
        .minimize(problem, &problem.parameters())
        .unwrap_or_else(|e| panic!("{}: {e}", problem.name))
}

const UPDATED: [JacobianUpdates; 2] = [
    JacobianUpdates::Broyden,
    JacobianUpdates::BroydenStopOnUpdate,
];

fn problems() -> impl Iterator<Item = Mgh> {
    mgh::ALL.iter().map(|p| p.numerical())
}

/// `report` converged to the minimum of `reference`: chi-square to 1e-8
/// (both below 1e-20 where it is zero), parameters to 1e-5.
fn assert_same_minimum(report: &FitReport, reference: &FitReport, summary: &str) {
    assert!(report.termination.is_converged(), "{summary}");
    let zero = 1e-20;
    if reference.chi2 < zero {
        assert!(report.chi2 < zero, "{summary}");
    } else {
        let relative = (report.chi2 - reference.chi2).abs() / reference.chi2;
        assert!(relative < 1e-8, "{summary}");
    }
    for (a, b) in report.params.iter().zip(reference.params.iter()) {
        assert!((a - b).abs() <= 1e-5 * b.abs().max(1.0), "{summary}");
    }
}

#[test]
fn updated_jacobians_reach_the_minima_that_new_ones_reach() {
    for problem in problems() {
        let reference = fit(&problem, JacobianUpdates::Never);
        for updates in UPDATED {
            let report = fit(&problem, updates);
            let summary = format!(
                "{} {updates:?}: {:?}, chi2 {:e} at {:?}; new Jacobians: chi2 {:e} at {:?}",
                problem.name,
                report.termination,
                report.chi2,
                report.params.as_slice(),
                reference.chi2,
                reference.params.as_slice()
            );
            assert_same_minimum(&report, &reference, &summary);
        }
    }
}

/// Each fit ends on a new Jacobian at its optimum, so the standard errors
/// are those of the optimum whatever the updates before.
#[test]
fn the_standard_errors_after_updates_are_those_at_the_optimum() {
    let mut compared = 0;
    for problem in problems() {
        let reference = fit(&problem, JacobianUpdates::Never);
        for updates in UPDATED {
            let report = fit(&problem, updates);
            for j in 0..report.params.len() {
                let (Some(a), Some(b)) = (report.standard_error(j), reference.standard_error(j))
                else {
                    continue;
                };
                assert!(
                    (a - b).abs() <= 1e-5 * b,
                    "{} {updates:?} parameter {j}: {a} against {b}",
                    problem.name
                );
                compared += 1;
            }
        }
    }
    assert!(compared >= 20, "only {compared} standard errors compared");
}

/// What the updates are for: on these problems together, fewer residual
/// evaluations (trial points and finite differences) than with a new
/// Jacobian after every step.
#[test]
fn updated_jacobians_cost_fewer_evaluations_in_all() {
    let spent = |updates| -> usize {
        problems()
            .map(|p| {
                let e = fit(&p, updates).evaluations;
                e.residuals + e.finite_difference_residuals
            })
            .sum()
    };
    let (new, updated) = (
        spent(JacobianUpdates::Never),
        spent(JacobianUpdates::Broyden),
    );
    assert!(
        (updated as f64) < 0.8 * new as f64,
        "{updated} evaluations with updates, {new} without"
    );
}

fn fit_from(problem: &Mgh, updates: JacobianUpdates, columns: &[Option<&[f64]>]) -> FitReport {
    let engine = LevenbergMarquardt::new(Options {
        jacobian_updates: updates,
        ..Options::default()
    });
    engine
        .minimize_with_columns(problem, &problem.parameters(), columns)
        .unwrap_or_else(|e| panic!("{}: {e}", problem.name))
}

/// Columns given for the start, right (the Jacobian there) or wrong (twice
/// it, and a zero column), lead to the minimum the plain fit finds: a fit
/// never stops on them unasked, and a step they predict badly brings a new
/// Jacobian.
#[test]
fn a_fit_from_given_columns_reaches_the_same_minimum() {
    for problem in problems() {
        let parameters = problem.parameters();
        let start: Vec<f64> = parameters.iter().map(|p| p.initial).collect();
        let jacobian = needle_lsq::finite_difference_jacobian(
            &problem,
            &parameters,
            &start,
            needle_lsq::Differences::Forward,
        )
        .unwrap();
        let reference = fit(&problem, JacobianUpdates::Never);
        let doubled = &jacobian * 2.0;
        let zero = vec![0.0; jacobian.nrows()];
        let columns = |matrix: &nalgebra::DMatrix<f64>, zeroed: bool| -> Vec<Vec<f64>> {
            (0..matrix.ncols())
                .map(|j| {
                    if zeroed && j == 0 {
                        zero.clone()
                    } else {
                        matrix.column(j).iter().copied().collect()
                    }
                })
                .collect()
        };
        for (what, given) in [
            ("right", columns(&jacobian, false)),
            ("wrong", columns(&doubled, true)),
        ] {
            let given: Vec<Option<&[f64]>> = given.iter().map(|c| Some(c.as_slice())).collect();
            for updates in [JacobianUpdates::Never, JacobianUpdates::Broyden] {
                let report = fit_from(&problem, updates, &given);
                let summary = format!(
                    "{} {what} columns {updates:?}: {:?}, chi2 {:e}; plain: {:e}",
                    problem.name, report.termination, report.chi2, reference.chi2
                );
                assert_same_minimum(&report, &reference, &summary);
            }
        }
    }
}

#[test]
fn given_columns_of_the_wrong_shape_or_not_finite_are_refused() {
    let problem = mgh::BARD.numerical();
    let parameters = problem.parameters();
    let m = 15;
    let short = vec![0.0; m - 1];
    let good = vec![1.0; m];
    let nan = {
        let mut c = good.clone();
        c[3] = f64::NAN;
        c
    };
    let engine = LevenbergMarquardt::default();
    let attempt = |columns: &[Option<&[f64]>]| {
        engine
            .minimize_with_columns(&problem, &parameters, columns)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    };
    let one_short = attempt(&[Some(&good), None]);
    assert!(one_short.contains("start columns"), "{one_short}");
    let short_column = attempt(&[Some(&good), Some(&short), None]);
    assert!(short_column.contains("a start column"), "{short_column}");
    let not_finite = attempt(&[None, None, Some(&nan)]);
    assert!(not_finite.contains("not finite"), "{not_finite}");
}

/// At the minimum with its Jacobian slightly off, the first step gains
/// nothing and its ratio is rounding: with `BroydenStopOnUpdate` the fit
/// stops there, since both reductions are below the tolerance, rather than
/// differencing a new Jacobian; `Broyden` confirms the stop on a new one.
#[test]
fn a_negligible_step_on_given_columns_ends_a_fit_that_may_stop_on_them() {
    let problem = mgh::BARD.numerical();
    let optimum = fit(&problem, JacobianUpdates::Never);
    let columns: Vec<Vec<f64>> = optimum
        .jacobian
        .iter()
        .enumerate()
        .map(|(j, column)| {
            let column = column.as_ref().expect("an interior optimum");
            let off = if j == 0 { 1.0 + 1e-3 } else { 1.0 };
            column.iter().map(|v| v * off).collect()
        })
        .collect();
    let given: Vec<Option<&[f64]>> = columns.iter().map(|c| Some(c.as_slice())).collect();
    let parameters: Vec<needle_lsq::Parameter> = problem
        .parameters()
        .into_iter()
        .zip(optimum.params.iter())
        .map(|(p, &x)| needle_lsq::Parameter { initial: x, ..p })
        .collect();
    let from_the_optimum = |updates| {
        LevenbergMarquardt::new(Options {
            jacobian_updates: updates,
            function_tolerance: 1e-4,
            uncertainty: false,
            ..Options::default()
        })
        .minimize_with_columns(&problem, &parameters, &given)
        .unwrap()
    };
    let stopped = from_the_optimum(JacobianUpdates::BroydenStopOnUpdate);
    assert_eq!(stopped.termination, needle_lsq::Termination::CostReduction);
    assert_eq!(
        stopped.evaluations.jacobians, 0,
        "{:?}",
        stopped.evaluations
    );
    assert!(stopped.chi2 <= optimum.chi2 * (1.0 + 1e-4));
    let confirmed = from_the_optimum(JacobianUpdates::Broyden);
    assert!(
        confirmed.evaluations.jacobians >= 1,
        "{:?}",
        confirmed.evaluations
    );
}
