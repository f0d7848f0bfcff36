//! The engine against problems with known minima (Moré, Garbow & Hillstrom
//! 1981), from their standard starting points, with analytic and with
//! finite-difference Jacobians.

mod mgh;

use mgh::Mgh;
use needle_lsq::{FitReport, LevenbergMarquardt, Options};

fn fit(problem: &Mgh) -> FitReport {
    LevenbergMarquardt::default()
        .minimize(problem, &problem.parameters())
        .unwrap_or_else(|e| panic!("{}: {e}", problem.name))
}

fn show(problem: &Mgh, report: &FitReport) -> String {
    format!(
        "{} (analytic {}): chi2 {:e} at {:?}, {:?} after {} residual / {} Jacobian evaluations",
        problem.name,
        problem.analytic,
        report.chi2,
        report.params.as_slice(),
        report.termination,
        report.evaluations.residuals,
        report.evaluations.jacobians
    )
}

/// Asserts convergence to `chi2` (below `ZERO` for zero-residual problems,
/// relative 1e-8 otherwise) at `params` (relative to max(|x*|, floor)).
fn assert_minimum(problem: &Mgh, chi2: f64, params: &[f64], floor: f64) {
    assert_minimum_within(problem, chi2, ZERO, params, floor);
}

/// Zero-residual threshold on chi2.
const ZERO: f64 = 1e-20;

fn assert_minimum_within(problem: &Mgh, chi2: f64, zero: f64, params: &[f64], floor: f64) {
    for variant in [*problem, problem.numerical()] {
        let report = fit(&variant);
        let summary = show(&variant, &report);
        eprintln!("{summary}");
        assert!(report.termination.is_converged(), "{summary}");
        if chi2 == 0.0 {
            assert!(report.chi2 < zero, "{summary}");
        } else {
            assert!(((report.chi2 - chi2) / chi2).abs() < 1e-8, "{summary}");
        }
        for (found, expected) in report.params.iter().zip(params) {
            assert!(
                (found - expected).abs() <= 1e-5 * expected.abs().max(floor),
                "{summary}: expected {params:?}"
            );
        }
    }
}

#[test]
fn rosenbrock_reaches_one_one() {
    assert_minimum(&mgh::ROSENBROCK, 0.0, &[1.0, 1.0], 1.0);
}

#[test]
fn brown_badly_scaled_reaches_its_minimum() {
    // x1 = 1e6 carries a rounding unit of 1.2e-10, so chi2 cannot go below
    // ~1e-20: the zero threshold is 1e-18 here.
    assert_minimum_within(&mgh::BROWN_BADLY_SCALED, 0.0, 1e-18, &[1e6, 2e-6], 0.0);
}

#[test]
fn beale_reaches_its_minimum() {
    assert_minimum(&mgh::BEALE, 0.0, &[3.0, 0.5], 1.0);
}

#[test]
fn helical_valley_reaches_its_minimum() {
    assert_minimum(&mgh::HELICAL_VALLEY, 0.0, &[1.0, 0.0, 0.0], 1.0);
}

#[test]
fn bard_reaches_its_minimum() {
    // chi2 = 8.21487...e-3 (MGH; More, Garbow & Hillstrom's f = chi2).
    assert_minimum(
        &mgh::BARD,
        8.214_877_306_578_5e-3,
        &[0.082_410_55, 1.133_036_1, 2.343_695_2],
        1.0,
    );
}

#[test]
fn box_3d_reaches_its_minimum() {
    assert_minimum(&mgh::BOX_3D, 0.0, &[1.0, 10.0, 1.0], 1.0);
}

#[test]
fn meyer_reaches_its_minimum_despite_the_scaling() {
    assert_minimum(
        &mgh::MEYER,
        87.945_855_170_395,
        &[5.609_636_471e-3, 6_181.346_346, 345.223_635_2],
        0.0,
    );
    // Badly scaled (parameters 1e-3 to 1e4) but identifiable: after column
    // equilibration it is well within the rank tolerance.
    let report = fit(&mgh::MEYER);
    assert!(!report.uncertainty.is_rank_deficient());
    assert_eq!(report.uncertainty.estimated, vec![0, 1, 2]);
}

#[test]
fn freudenstein_roth_stops_at_the_known_local_minimum() {
    // From the standard start, descent methods fall into the local minimum
    // chi2 = 48.98425368 at (11.4128, -0.896805); the global one is 0 at (5, 4).
    for variant in [mgh::FREUDENSTEIN_ROTH, mgh::FREUDENSTEIN_ROTH.numerical()] {
        let report = fit(&variant);
        let summary = show(&variant, &report);
        eprintln!("{summary}");
        assert!(report.termination.is_converged(), "{summary}");
        let local = ((report.chi2 - 48.984_253_679_8) / 48.984_253_679_8).abs() < 1e-8
            && (report.params[0] - 11.412_779_2).abs() < 1e-5
            && (report.params[1] + 0.896_805_2).abs() < 1e-6;
        let global = report.chi2 < 1e-20;
        assert!(local || global, "{summary}");
        // At a local minimum the gradient vanishes although the cost does not.
        assert!(report.gradient_norm < 1e-5 * report.cost, "{summary}");
    }
}

#[test]
fn powell_singular_converges_to_the_singular_origin() {
    // The Jacobian is singular at the minimum, so convergence is linear, not
    // quadratic: the parameters approach 0 slowly while chi2 ~ |x|^4.
    for variant in [mgh::POWELL_SINGULAR, mgh::POWELL_SINGULAR.numerical()] {
        let report = fit(&variant);
        let summary = show(&variant, &report);
        eprintln!("{summary}");
        assert!(report.termination.is_converged(), "{summary}");
        assert!(report.chi2 < 1e-20, "{summary}");
        assert!(report.params.amax() < 1e-4, "{summary}");
        // At the origin the last two residuals have zero gradient: the
        // Jacobian has rank 2 and the fit must say so.
        assert_eq!(report.uncertainty.rank, 2, "{summary}");
        assert!(report.uncertainty.is_rank_deficient(), "{summary}");
    }
}

#[test]
fn tight_evaluation_budget_is_reported_as_not_converged() {
    let options = Options {
        max_evaluations: 5,
        ..Options::default()
    };
    let report = LevenbergMarquardt::new(options)
        .minimize(&mgh::MEYER, &mgh::MEYER.parameters())
        .unwrap();
    assert_eq!(report.termination, needle_lsq::Termination::MaxEvaluations);
    assert!(!report.termination.is_converged());
    assert_eq!(report.evaluations.residuals, 5);
}

#[test]
fn no_report_carries_a_nan_or_an_unflagged_infinite_error() {
    for problem in mgh::ALL.iter().flat_map(|p| [*p, p.numerical()]) {
        let report = fit(&problem);
        let summary = show(&problem, &report);
        let uncertainty = &report.uncertainty;
        assert!(
            report.cost.is_finite() && report.gradient_norm.is_finite(),
            "{summary}"
        );
        assert!(!uncertainty.condition_number.is_nan(), "{summary}");
        for error in uncertainty.standard_errors.iter().flatten() {
            assert!(error.is_finite() && *error >= 0.0, "{summary}: {error}");
        }
        assert!(
            uncertainty.covariance.iter().all(|c| c.is_finite()),
            "{summary}"
        );
        assert!(
            uncertainty.correlation.iter().all(|c| c.is_finite()),
            "{summary}"
        );
        // Every free parameter is either estimated or flagged.
        assert_eq!(
            uncertainty.estimated.len() + uncertainty.unidentifiable().len(),
            problem.n,
            "{summary}"
        );
        // A numerically infinite condition number comes with a flag.
        if uncertainty.condition_number.is_infinite() {
            assert!(uncertainty.is_rank_deficient(), "{summary}");
        }
    }
}
