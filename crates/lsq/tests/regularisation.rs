//! Tikhonov-regularised linear least squares on a deconvolution with a
//! known answer.

use nalgebra::{DMatrix, DVector};
use needle_lsq::{LambdaChoice, LsqError, difference_operator, tikhonov};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Blurred samples of a smooth function: `b = A f + noise`, `A` a Gaussian
/// kernel (width 0.04) integrated on `n` cells of [0, 1], `m` data.
struct Deconvolution {
    a: DMatrix<f64>,
    b: DVector<f64>,
    truth: DVector<f64>,
    sigma: f64,
}

fn deconvolution(seed: u64) -> Deconvolution {
    let (m, n, width) = (150, 80, 0.04);
    let cell = 1.0 / n as f64;
    let centres = DVector::from_fn(n, |j, _| (j as f64 + 0.5) * cell);
    let truth = centres
        .map(|t| (std::f64::consts::PI * t).sin() + 0.5 * (3.0 * std::f64::consts::PI * t).sin());
    let a = DMatrix::from_fn(m, n, |i, j| {
        let s = (i as f64 + 0.5) / m as f64;
        let d = (s - centres[j]) / width;
        cell * (-0.5 * d * d).exp() / (width * (2.0 * std::f64::consts::PI).sqrt())
    });
    let clean = &a * &truth;
    let sigma = 1e-2 * clean.amax();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma).unwrap();
    let b = clean.map(|x| x + noise.sample(&mut rng));
    Deconvolution { a, b, truth, sigma }
}

fn relative_error(x: &DVector<f64>, truth: &DVector<f64>) -> f64 {
    (x - truth).norm() / truth.norm()
}

#[test]
fn fixed_lambda_matches_the_normal_equations() {
    let problem = deconvolution(1);
    let n = problem.a.ncols();
    for regulariser in [DMatrix::identity(n, n), difference_operator(n, 2)] {
        for lambda in [1e-6, 1e-3, 1.0] {
            let solution = tikhonov(
                &problem.a,
                &problem.b,
                &regulariser,
                LambdaChoice::Fixed(lambda),
            )
            .unwrap();
            let normal = problem.a.tr_mul(&problem.a) + regulariser.tr_mul(&regulariser) * lambda;
            let direct = normal
                .clone()
                .cholesky()
                .unwrap()
                .solve(&problem.a.tr_mul(&problem.b));
            let error = (&solution.x - &direct).norm() / direct.norm();
            assert!(error < 1e-8, "lambda {lambda}: {error:e}");
            assert!((solution.lambda - lambda).abs() < 1e-12 * lambda);
            let residual = (&problem.a * &direct - &problem.b).norm();
            assert!((solution.residual_norm - residual).abs() < 1e-10 * residual);
            // tr H against the explicit influence matrix.
            let influence = &problem.a * normal.try_inverse().unwrap() * problem.a.transpose();
            assert!(
                (solution.effective_parameters - influence.trace()).abs()
                    < 1e-6 * influence.trace()
            );
        }
    }
}

#[test]
fn discrepancy_principle_hits_the_noise_level() {
    let problem = deconvolution(2);
    let n = problem.a.ncols();
    let m = problem.a.nrows() as f64;
    for regulariser in [DMatrix::identity(n, n), difference_operator(n, 2)] {
        let solution = tikhonov(
            &problem.a,
            &problem.b,
            &regulariser,
            LambdaChoice::Discrepancy {
                noise_sigma: problem.sigma,
            },
        )
        .unwrap();
        let target = m.sqrt() * problem.sigma;
        assert!(
            (solution.residual_norm / target - 1.0).abs() < 1e-6,
            "{} vs {target}",
            solution.residual_norm
        );
        let error = relative_error(&solution.x, &problem.truth);
        eprintln!(
            "discrepancy: lambda {:e}, error {error:.4}",
            solution.lambda
        );
        assert!(error < 0.1, "relative error {error}");
    }
}

#[test]
fn generalised_cross_validation_is_close_to_the_best_lambda() {
    for seed in [3, 4, 5] {
        let problem = deconvolution(seed);
        let regulariser = difference_operator(problem.a.ncols(), 2);
        let gcv = tikhonov(
            &problem.a,
            &problem.b,
            &regulariser,
            LambdaChoice::GeneralisedCrossValidation,
        )
        .unwrap();
        // The error-optimal lambda by brute force over twelve decades.
        let (best_lambda, best_error) = (0..=120)
            .map(|k| 10f64.powf(-8.0 + 0.1 * f64::from(k)))
            .map(|lambda| {
                let x = tikhonov(
                    &problem.a,
                    &problem.b,
                    &regulariser,
                    LambdaChoice::Fixed(lambda),
                )
                .unwrap()
                .x;
                (lambda, relative_error(&x, &problem.truth))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        let error = relative_error(&gcv.x, &problem.truth);
        eprintln!(
            "seed {seed}: GCV lambda {:e} error {error:.4}; best lambda {best_lambda:e} error {best_error:.4}",
            gcv.lambda
        );
        assert!(
            error < 2.0 * best_error,
            "GCV error {error} vs best {best_error}"
        );
        assert!((gcv.lambda / best_lambda).log10().abs() < 2.0);
        // GCV's residual is close to the noise level it never saw.
        let noise_norm = (problem.a.nrows() as f64).sqrt() * problem.sigma;
        assert!((gcv.residual_norm / noise_norm - 1.0).abs() < 0.2);
    }
}

#[test]
fn unreachable_discrepancy_and_shared_null_space_are_errors() {
    let problem = deconvolution(6);
    let n = problem.a.ncols();
    let error = tikhonov(
        &problem.a,
        &problem.b,
        &DMatrix::identity(n, n),
        LambdaChoice::Discrepancy { noise_sigma: 1e3 },
    )
    .unwrap_err();
    assert!(
        matches!(error, LsqError::DiscrepancyUnreachable { .. }),
        "{error}"
    );

    // A data operator blind to constants and a smoothness regulariser that
    // does not penalise them: the constant offset is undetermined.
    let blind = difference_operator(n, 1);
    let data = DVector::zeros(n - 1);
    let error = tikhonov(
        &blind,
        &data,
        &difference_operator(n, 1),
        LambdaChoice::Fixed(1.0),
    )
    .unwrap_err();
    assert!(matches!(error, LsqError::SingularRegularisation), "{error}");

    let error = tikhonov(
        &problem.a,
        &DVector::zeros(3),
        &DMatrix::identity(n, n),
        LambdaChoice::Fixed(1.0),
    )
    .unwrap_err();
    assert!(matches!(error, LsqError::DimensionMismatch { .. }));
}

#[test]
fn difference_operators_annihilate_polynomials_of_lower_degree() {
    let n = 12;
    let t = DVector::from_fn(n, |i, _| i as f64);
    assert_eq!(difference_operator(n, 0), DMatrix::identity(n, n));
    let second = difference_operator(n, 2);
    assert_eq!(second.shape(), (n - 2, n));
    assert!((&second * t.map(|x| 3.0 - 2.0 * x)).amax() < 1e-12);
    assert!(((&second * t.map(|x| x * x)).add_scalar(-2.0)).amax() < 1e-12);
}
