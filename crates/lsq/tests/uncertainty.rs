//! Covariance, confidence intervals, identifiability and profile
//! likelihood, against analytic results and Monte-Carlo.

use nalgebra::{DMatrix, DVector};
use needle_lsq::{
    CovarianceScaling, EvaluationError, LevenbergMarquardt, LsqError, Options, Parameter,
    ParameterStatus, Problem, ProfileOptions, ProfileSpan, chi_square_one_dof, normal_quantile,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Whitened residuals of a linear model `y = X p` with per-datum sigma.
struct Linear {
    design: DMatrix<f64>,
    y: DVector<f64>,
    sigma: DVector<f64>,
}

impl Problem for Linear {
    fn num_parameters(&self) -> usize {
        self.design.ncols()
    }
    fn num_residuals(&self) -> usize {
        self.y.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        let model = &self.design * DVector::from_column_slice(p);
        for i in 0..out.len() {
            out[i] = (model[i] - self.y[i]) / self.sigma[i];
        }
        Ok(())
    }
}

/// A quadratic in t with noisy data and unequal sigmas.
fn quadratic() -> Linear {
    let m = 25;
    let t = DVector::from_fn(m, |i, _| i as f64 / (m - 1) as f64 * 4.0 - 1.0);
    let design = DMatrix::from_fn(m, 3, |i, j| t[i].powi(j as i32));
    let sigma = DVector::from_fn(m, |i, _| 0.05 + 0.02 * (i % 3) as f64);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let noise = Normal::new(0.0, 1.0).unwrap();
    let truth = DVector::from_vec(vec![1.0, -0.5, 0.25]);
    let y = &design * &truth + DVector::from_fn(m, |i, _| sigma[i] * noise.sample(&mut rng));
    Linear { design, y, sigma }
}

fn start() -> Vec<Parameter> {
    vec![
        Parameter::new("c0", 0.0),
        Parameter::new("c1", 0.0),
        Parameter::new("c2", 0.0),
    ]
}

/// `(Xᵀ W X)⁻¹` with `W = diag(1/σ²)`.
fn analytic_covariance(problem: &Linear) -> DMatrix<f64> {
    let whitened = DMatrix::from_fn(problem.design.nrows(), problem.design.ncols(), |i, j| {
        problem.design[(i, j)] / problem.sigma[i]
    });
    (whitened.transpose() * whitened).try_inverse().unwrap()
}

#[test]
fn covariance_of_a_linear_model_is_the_analytic_one() {
    let problem = quadratic();
    let expected = analytic_covariance(&problem);
    for (scaling, scaled) in [
        (CovarianceScaling::KnownNoise, false),
        (CovarianceScaling::ReducedChiSquare, true),
    ] {
        let options = Options {
            covariance_scaling: scaling,
            ..Options::default()
        };
        let report = LevenbergMarquardt::new(options)
            .minimize(&problem, &start())
            .unwrap();
        let scale = if scaled {
            report.reduced_chi2().unwrap()
        } else {
            1.0
        };
        let covariance = &report.uncertainty.covariance;
        assert_eq!(report.uncertainty.estimated, vec![0, 1, 2]);
        for i in 0..3 {
            for j in 0..3 {
                let want = scale * expected[(i, j)];
                let tolerance = 1e-7 * (expected[(i, i)] * expected[(j, j)]).sqrt() * scale;
                assert!(
                    (covariance[(i, j)] - want).abs() < tolerance,
                    "{scaling:?} C[{i},{j}] = {} vs {want}",
                    covariance[(i, j)]
                );
            }
            assert!((report.uncertainty.correlation[(i, i)] - 1.0).abs() < 1e-12);
            let sigma = report.standard_error(i).unwrap();
            let (low, high) = report.confidence_interval(i, 0.95).unwrap();
            assert!((high - low - 2.0 * 1.959_963_985 * sigma).abs() < 1e-8 * sigma);
        }
        assert!(!report.uncertainty.is_rank_deficient());
        assert_eq!(report.uncertainty.rank, 3);
        assert!(report.uncertainty.condition_number.is_finite());
    }
}

#[test]
fn profile_interval_of_a_linear_model_is_the_wald_interval() {
    let problem = quadratic();
    let lm = LevenbergMarquardt::default();
    let parameters = start();
    let report = lm.minimize(&problem, &parameters).unwrap();
    for index in 0..3 {
        let options = ProfileOptions {
            level: 0.95,
            points: 30,
            span: ProfileSpan::StandardErrors(3.0),
        };
        let profile = lm
            .profile(&problem, &parameters, &report, index, &options)
            .unwrap();
        let (wald_low, wald_high) = report.confidence_interval(index, 0.95).unwrap();
        let sigma = report.standard_error(index).unwrap();
        let (low, high) = (profile.lower.unwrap(), profile.upper.unwrap());
        // Chord interpolation of the parabola between grid points (0.1 sigma
        // apart) errs by < 1e-3 sigma.
        assert!(
            (low - wald_low).abs() < 2e-3 * sigma,
            "{index}: {low} vs {wald_low}"
        );
        assert!(
            (high - wald_high).abs() < 2e-3 * sigma,
            "{index}: {high} vs {wald_high}"
        );
        // The profile is the parabola chi2_min + ((v - p)/sigma)^2.
        for (v, chi2) in profile.values.iter().zip(&profile.chi2) {
            let expected = report.chi2 + ((v - report.params[index]) / sigma).powi(2);
            assert!(
                (chi2 - expected).abs() < 1e-6 * expected,
                "{v}: {chi2} vs {expected}"
            );
        }
    }
}

/// `y = A exp(-k t)` with known noise, analytic Jacobian off (finite
/// differences), as a small nonlinear model.
struct Decay {
    t: Vec<f64>,
    y: Vec<f64>,
    sigma: f64,
}

impl Decay {
    const AMPLITUDE: f64 = 2.0;
    const RATE: f64 = 1.5;

    fn sample(rng: &mut ChaCha8Rng, sigma: f64) -> Self {
        let noise = Normal::new(0.0, sigma).unwrap();
        let t: Vec<f64> = (0..30).map(|i| f64::from(i) * 0.1).collect();
        let y = t
            .iter()
            .map(|t| Self::AMPLITUDE * (-Self::RATE * t).exp() + noise.sample(rng))
            .collect();
        Self { t, y, sigma }
    }
}

impl Problem for Decay {
    fn num_parameters(&self) -> usize {
        2
    }
    fn num_residuals(&self) -> usize {
        self.t.len()
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        for ((o, t), y) in out.iter_mut().zip(&self.t).zip(&self.y) {
            *o = (p[0] * (-p[1] * t).exp() - y) / self.sigma;
        }
        Ok(())
    }
}

fn decay_parameters() -> Vec<Parameter> {
    vec![
        Parameter::new("amplitude", 1.0),
        Parameter::new("rate", 1.0).with_lower(0.0),
    ]
}

#[test]
fn standard_errors_match_the_monte_carlo_spread() {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let replicates = 300;
    let lm = LevenbergMarquardt::default();
    let mut estimates = [Vec::new(), Vec::new()];
    let mut reported = [0.0, 0.0];
    for _ in 0..replicates {
        let problem = Decay::sample(&mut rng, 0.05);
        let report = lm.minimize(&problem, &decay_parameters()).unwrap();
        assert!(report.termination.is_converged());
        for j in 0..2 {
            estimates[j].push(report.params[j]);
            reported[j] += report.standard_error(j).unwrap() / f64::from(replicates);
        }
    }
    for j in 0..2 {
        let n = estimates[j].len() as f64;
        let mean = estimates[j].iter().sum::<f64>() / n;
        let spread =
            (estimates[j].iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let truth = [Decay::AMPLITUDE, Decay::RATE][j];
        eprintln!(
            "parameter {j}: mean {mean}, empirical sd {spread}, reported {}",
            reported[j]
        );
        // 300 replicates estimate a standard deviation to ~4 %.
        assert!(
            (spread / reported[j] - 1.0).abs() < 0.15,
            "{j}: {spread} vs {}",
            reported[j]
        );
        assert!((mean - truth).abs() < 4.0 * spread / n.sqrt());
    }
}

#[test]
fn profile_interval_of_a_nonlinear_model_brackets_the_estimate() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let problem = Decay::sample(&mut rng, 0.05);
    let lm = LevenbergMarquardt::default();
    let parameters = decay_parameters();
    let report = lm.minimize(&problem, &parameters).unwrap();
    let profile = lm
        .profile(
            &problem,
            &parameters,
            &report,
            1,
            &ProfileOptions::default(),
        )
        .unwrap();
    let (wald_low, wald_high) = report.confidence_interval(1, 0.95).unwrap();
    let (low, high) = (profile.lower.unwrap(), profile.upper.unwrap());
    assert!(low < report.params[1] && report.params[1] < high);
    // Mildly nonlinear at this noise: the two intervals agree to ~10 %.
    let width = wald_high - wald_low;
    assert!((low - wald_low).abs() < 0.1 * width && (high - wald_high).abs() < 0.1 * width);
    assert!((profile.threshold - 3.841_458_8).abs() < 1e-6);
    assert!(profile.chi2.iter().all(|&c| c >= profile.minimum_chi2));
}

/// `y = a b t`: only the product is determined; `c` has no effect at all.
struct Product;

impl Problem for Product {
    fn num_parameters(&self) -> usize {
        4
    }
    fn num_residuals(&self) -> usize {
        10
    }
    fn residuals(&self, p: &[f64], out: &mut [f64]) -> Result<(), EvaluationError> {
        for (i, o) in out.iter_mut().enumerate() {
            let t = i as f64;
            *o = p[0] * p[1] * t + p[3] * t * t
                - (6.0 * t + 0.5 * t * t + 0.1 * (-1f64).powi(i as i32));
        }
        Ok(())
    }
}

#[test]
fn unidentifiable_parameters_are_flagged_not_given_errors() {
    let parameters = [
        Parameter::new("a", 1.0),
        Parameter::new("b", 1.0),
        Parameter::new("c", 1.0),
        Parameter::new("d", 0.0).with_scale(1.0),
    ];
    let report = LevenbergMarquardt::default()
        .minimize(&Product, &parameters)
        .unwrap();
    assert!((report.params[0] * report.params[1] - 6.0).abs() < 1e-2);
    let uncertainty = &report.uncertainty;
    assert!(uncertainty.is_rank_deficient());
    assert_eq!(uncertainty.columns, 4);
    assert_eq!(uncertainty.rank, 2);
    assert_eq!(uncertainty.unidentifiable(), vec![0, 1, 2]);
    assert_eq!(uncertainty.estimated, vec![3]);
    assert!(report.standard_error(0).is_none() && report.standard_error(2).is_none());
    assert!(uncertainty.condition_number.is_infinite() || uncertainty.condition_number > 1e7);
    let error = report.confidence_interval(0, 0.95).unwrap_err();
    assert!(matches!(
        error,
        LsqError::NotEstimated {
            status: ParameterStatus::Unidentifiable,
            ..
        }
    ));
    // The identifiable parameter keeps a finite, positive error.
    let sigma = report.standard_error(3).unwrap();
    assert!(sigma.is_finite() && sigma > 0.0);
    for value in uncertainty
        .covariance
        .iter()
        .chain(uncertainty.correlation.iter())
    {
        assert!(value.is_finite());
    }
}

#[test]
fn quantiles_have_their_textbook_values() {
    assert!((chi_square_one_dof(0.95).unwrap() - 3.841_458_820_694_124).abs() < 1e-7);
    assert!((chi_square_one_dof(0.6826894921370859).unwrap() - 1.0).abs() < 1e-7);
    assert!((normal_quantile(0.975).unwrap() - 1.959_963_984_540_054).abs() < 1e-8);
    assert!((normal_quantile(0.001).unwrap() + 3.090_232_306_167_813_6).abs() < 1e-7);
    assert!(normal_quantile(1.0).is_err() && chi_square_one_dof(-0.1).is_err());
}

#[test]
fn scaling_by_reduced_chi_square_without_degrees_of_freedom_is_flagged() {
    // Three data, three parameters: an exact fit with dof = 0.
    let full = quadratic();
    let problem = Linear {
        design: full.design.rows(0, 3).into_owned(),
        y: full.y.rows(0, 3).into_owned(),
        sigma: full.sigma.rows(0, 3).into_owned(),
    };
    let options = Options {
        covariance_scaling: CovarianceScaling::ReducedChiSquare,
        ..Options::default()
    };
    let report = LevenbergMarquardt::new(options)
        .minimize(&problem, &start())
        .unwrap();
    assert_eq!(report.dof, 0);
    assert!(report.reduced_chi2().is_none());
    assert!(report.uncertainty.covariance_scale.is_none());
    assert_eq!(
        report
            .uncertainty
            .indices_with(ParameterStatus::NoDegreesOfFreedom),
        vec![0, 1, 2]
    );
    assert!(matches!(
        report.confidence_interval(1, 0.95),
        Err(LsqError::NotEstimated { .. })
    ));
    // With known noise the same fit has a perfectly good covariance.
    let report = LevenbergMarquardt::default()
        .minimize(&problem, &start())
        .unwrap();
    assert_eq!(report.uncertainty.estimated, vec![0, 1, 2]);
}
