//! The Jacobian a fit reports at its optimum (`FitReport::jacobian`), and
//! the fits that end at their last Jacobian (`Options::end_at_last_jacobian`),
//! on the problems of Moré, Garbow & Hillstrom (1981).

mod mgh;

use mgh::Mgh;
use nalgebra::DMatrix;
use needle_lsq::{EvaluationError, FitReport, LevenbergMarquardt, Options, Parameter, Problem};

fn engine(end_at_last_jacobian: bool) -> LevenbergMarquardt {
    LevenbergMarquardt::new(Options {
        function_tolerance: 1e-8,
        end_at_last_jacobian,
        ..Options::default()
    })
}

/// Each parameter bounded on both sides of its start and of the unbounded
/// optimum, unevenly, so that its internal coordinate has a slope other
/// than one there.
fn bounded(problem: &Mgh) -> Vec<Parameter> {
    let optimum = engine(false)
        .minimize(problem, &problem.parameters())
        .unwrap();
    problem
        .parameters()
        .into_iter()
        .zip(optimum.params.iter())
        .map(|(p, &x)| {
            let start = p.initial;
            let width = x.abs() + start.abs() + 1.0;
            p.with_bounds(x.min(start) - 2.0 * width, x.max(start) + 3.0 * width)
        })
        .collect()
}

/// The largest difference between a reported column and `exact`'s, relative
/// to that column's norm.
fn largest_gap(report: &FitReport, exact: &DMatrix<f64>) -> f64 {
    report
        .jacobian
        .iter()
        .enumerate()
        .map(|(j, column)| {
            let column = column.as_ref().expect("every parameter is free and inside");
            let exact = exact.column(j);
            (column - exact).norm() / exact.norm().max(f64::MIN_POSITIVE)
        })
        .fold(0.0, f64::max)
}

fn analytic_jacobian(problem: &Mgh, p: &[f64]) -> DMatrix<f64> {
    let mut exact = DMatrix::zeros(problem.m, problem.n);
    (problem.jacobian)(p, &mut exact);
    exact
}

/// With an analytic Jacobian the report's columns are the problem's own at
/// the parameters returned, to rounding: at the end of the last step or,
/// ending at the last Jacobian, at its start; differenced, to the
/// differences' accuracy.
#[test]
fn the_reported_jacobian_is_the_problem_s_own_at_the_returned_parameters() {
    for problem in mgh::ALL {
        let parameters = bounded(&problem);
        for end_at_last_jacobian in [false, true] {
            for (problem, tolerance) in [(problem, 1e-12), (problem.numerical(), 1e-5)] {
                let report = engine(end_at_last_jacobian)
                    .minimize(&problem, &parameters)
                    .unwrap();
                let exact = analytic_jacobian(&problem, report.params.as_slice());
                let gap = largest_gap(&report, &exact);
                assert!(
                    gap <= tolerance,
                    "{} (analytic {}, ending at the last Jacobian {end_at_last_jacobian}): {gap:e}",
                    problem.name,
                    problem.analytic
                );
            }
        }
    }
}

/// $r = (p_0 - 2, p_1 - 3, p_2 - 1)$.
struct Offsets;

impl Problem for Offsets {
    fn num_parameters(&self) -> usize {
        3
    }
    fn num_residuals(&self) -> usize {
        3
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        for ((r, x), target) in out.iter_mut().zip(p).zip([2.0, 3.0, 1.0]) {
            *r = x - target;
        }
        Ok(())
    }
}

#[test]
fn held_parameters_and_those_on_a_bound_have_no_column() {
    let parameters = [
        Parameter::new("on_the_bound", 0.0).with_upper(1.0),
        Parameter::new("free", 0.0),
        Parameter::new("held", 0.5).fix(),
    ];
    let report = engine(false).minimize(&Offsets, &parameters).unwrap();
    assert!(
        (report.params[0] - 1.0).abs() < 1e-6,
        "{}",
        report.params[0]
    );
    assert_eq!(report.jacobian.len(), 3);
    assert!(report.jacobian[0].is_none());
    assert!(report.jacobian[2].is_none());
    let free = report.jacobian[1]
        .as_ref()
        .expect("a free parameter's column");
    assert!((free - nalgebra::DVector::from_vec(vec![0.0, 1.0, 0.0])).norm() < 1e-6);
}

/// A fit that skips the Jacobian at its optimum reports none rather than
/// one taken elsewhere.
#[test]
fn a_fit_without_a_jacobian_at_its_optimum_reports_none() {
    let mut without = 0;
    for problem in mgh::ALL {
        let report = LevenbergMarquardt::new(Options {
            uncertainty: false,
            ..Options::default()
        })
        .minimize(&problem, &problem.parameters())
        .unwrap();
        if report.jacobian.is_empty() {
            without += 1;
            continue;
        }
        let exact = analytic_jacobian(&problem, report.params.as_slice());
        let gap = largest_gap(&report, &exact);
        assert!(gap <= 1e-12, "{}: {gap:e}", problem.name);
    }
    assert!(without > 0, "every fit ended on a Jacobian at its optimum");
}

/// Ending at the last Jacobian saves the one after a negligible last step
/// and costs at most the tolerance in the cost.
#[test]
fn ending_at_the_last_jacobian_saves_jacobians_within_the_tolerance() {
    let (mut saved, mut ended_early) = (0, 0);
    for problem in mgh::ALL.iter().map(|p| p.numerical()) {
        let parameters = problem.parameters();
        let at_the_end = engine(false).minimize(&problem, &parameters).unwrap();
        let at_the_jacobian = engine(true).minimize(&problem, &parameters).unwrap();
        let summary = format!(
            "{}: chi2 {:e} against {:e}, Jacobians {} against {}",
            problem.name,
            at_the_jacobian.chi2,
            at_the_end.chi2,
            at_the_jacobian.evaluations.jacobians,
            at_the_end.evaluations.jacobians
        );
        assert!(
            at_the_jacobian.chi2 <= at_the_end.chi2 * (1.0 + 1.01e-8) + 1e-30,
            "{summary}"
        );
        assert!(
            at_the_jacobian.evaluations.jacobians <= at_the_end.evaluations.jacobians,
            "{summary}"
        );
        saved += at_the_end.evaluations.jacobians - at_the_jacobian.evaluations.jacobians;
        ended_early += usize::from(at_the_jacobian.params != at_the_end.params);
    }
    assert!(saved >= 3, "{saved} Jacobians saved");
    assert_eq!(saved, ended_early);
}
