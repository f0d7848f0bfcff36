//! Unit tests: marker grids, the shaft basis, consistent line loads, the
//! regularised solver, the paper's f = K u, reading a bundle, bad input and
//! the figures.

mod support;

use nalgebra::{DMatrix, DVector};
use needle_data::{
    BundleBuilder, MarkerRest, ToolSample, Trial, TrialKind, WriteOptions, read_bundle,
};
use needle_force::{
    DISCREPANCY_SAFETY, ForceError, Frame, Insertion, LambdaChoice, MarkerLayout, MarkerMeshModel,
    Model, ModelOptions, PlaneKind, Regularisation, ShaftBasis, ShaftCurve, ShaftResponse,
    ShaftWindow, Smoothness, TipPrior, TipZone, density_vs_velocity, fit_with_tip_prior,
    observe_insertion, plot_density_vs_velocity, plot_integrated_vs_base, plot_nodal_forces,
    plot_shaft_distributions, solve_regularised,
};
use support::{layout, paper_material, phantom};

mod grid {
    use super::*;

    #[test]
    fn a_shuffled_grid_is_recognised() {
        let mut markers = layout(&phantom(0.03, 0.02, 0.003), 4);
        markers.ids.reverse();
        markers.rest.reverse();
        let grid = markers.grid().unwrap();
        assert_eq!(grid.x.len(), 4);
        assert_eq!(grid.y.len(), 4);
        for (slot, &k) in grid.marker.iter().enumerate() {
            let (i, j) = (slot % 4, slot / 4);
            assert_eq!(markers.rest[k], [grid.x[i], grid.y[j]]);
        }
        assert!((grid.spacing() - 0.02 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn scattered_markers_are_not_a_grid() {
        let mut markers = layout(&phantom(0.03, 0.03, 0.003), 3);
        markers.rest[4] = [0.012, 0.016];
        assert!(matches!(markers.grid(), Err(ForceError::NotAGrid { .. })));
        let few = MarkerLayout {
            ids: vec![0, 1, 2],
            rest: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
        };
        assert!(matches!(
            few.grid(),
            Err(ForceError::TooFewMarkers { found: 3, .. })
        ));
    }
}

mod shaft {
    use super::*;

    #[test]
    fn weights_integrate_and_differences_annihilate_polynomials() {
        let basis = ShaftBasis::new(0.0337, 1.5e-3).unwrap();
        assert!(basis.spacing() <= 1.5e-3);
        let total: f64 = basis.weights().iter().sum();
        assert!((total - 0.0337).abs() < 1e-15);
        let linear: Vec<f64> = basis.stations.iter().map(|s| 3.0 + 50.0 * s).collect();
        let first = basis.difference_operator(Smoothness::FirstDifference);
        let second = basis.difference_operator(Smoothness::SecondDifference);
        let constant = DVector::from_element(basis.len(), 2.0);
        assert!((&first * &constant).amax() < 1e-9);
        assert!((&second * DVector::from_vec(linear.clone())).amax() < 1e-6);
        // The interpolant reproduces the linear function between stations.
        assert!((basis.evaluate(&linear, 0.0211) - (3.0 + 50.0 * 0.0211)).abs() < 1e-12);
        assert_eq!(basis.evaluate(&linear, 0.04), 0.0);
    }

    #[test]
    fn the_tip_zone_relaxes_only_the_rows_centred_near_the_tip() {
        let basis = ShaftBasis::new(0.03, 1.5e-3).unwrap();
        let zone = TipZone {
            zone: 4e-3,
            relaxation: 0.01,
        };
        for smoothness in [Smoothness::FirstDifference, Smoothness::SecondDifference] {
            let uniform = basis.difference_operator(smoothness);
            let relaxed = zone.operator(&basis, smoothness);
            let scaled: Vec<usize> = (0..uniform.nrows())
                .filter(|&r| (relaxed.row(r) - uniform.row(r) * 0.1).amax() < 1e-9)
                .collect();
            let kept = (0..uniform.nrows())
                .filter(|&r| relaxed.row(r) == uniform.row(r))
                .count();
            // Element centres 0.75, 2.25, 3.75 mm from the tip (first
            // difference); stations 1.5 and 3 mm from it (second).
            let expected = match smoothness {
                Smoothness::FirstDifference => 3,
                Smoothness::SecondDifference => 2,
            };
            assert_eq!(scaled.len(), expected, "{smoothness:?}");
            assert!(scaled.iter().all(|&r| r + expected >= uniform.nrows()));
            assert_eq!(kept + expected, uniform.nrows());
        }
        assert_eq!(
            TipZone::UNIFORM.operator(&basis, Smoothness::FirstDifference),
            basis.difference_operator(Smoothness::FirstDifference)
        );
    }

    #[test]
    fn bad_spacing_or_length_is_an_error() {
        assert!(matches!(
            ShaftBasis::new(0.01, 0.0),
            Err(ForceError::InvalidValue { .. })
        ));
        assert!(matches!(
            ShaftBasis::new(-0.01, 1e-3),
            Err(ForceError::BadShaft { .. })
        ));
        assert!(matches!(
            ShaftBasis::new(f64::NAN, 1e-3),
            Err(ForceError::BadShaft { .. })
        ));
    }
}

mod line_load {
    use super::*;

    /// The consistent nodal loads of every hat function (computed by
    /// needle-fem's line load) sum to its integral, for quadratic triangles
    /// and tetrahedra, with the tip mid-element; and data made by the model
    /// itself are inverted back to the density they came from.
    #[test]
    fn consistent_loads_keep_the_force_and_the_model_inverts_itself() {
        let p = phantom(0.03, 0.03, 0.003);
        let markers = layout(&p, 7);
        let grid = markers.grid().unwrap();
        for options in [
            ModelOptions {
                model: Model::Plane(PlaneKind::Stress),
                refinement: 2,
            },
            ModelOptions {
                model: Model::Slab { layers: 2 },
                refinement: 1,
            },
        ] {
            let response = ShaftResponse::new(
                &p,
                &markers,
                &grid,
                &paper_material(),
                options,
                [0.015, 0.0],
                [0.0, 1.0],
            )
            .unwrap();
            let basis = ShaftBasis::new(0.0173, 1.1e-3).unwrap();
            let loads = response.consistent_loads(&basis).unwrap();
            for (j, w) in basis.weights().iter().enumerate() {
                assert!(
                    (loads.column(j).sum() - w).abs() < 1e-12,
                    "force of hat {j}"
                );
            }
            // Stations as far apart as the markers keep G well conditioned.
            let basis = ShaftBasis::new(0.0173, 5e-3).unwrap();
            let truth: Vec<f64> = basis.stations.iter().map(|s| 10.0 + 200.0 * s).collect();
            let u = DVector::from_vec(response.predict(&basis, &truth).unwrap());
            let g = response.response_matrix(&basis).unwrap();
            let l = basis.difference_operator(Smoothness::SecondDifference);
            let fit =
                solve_regularised(&g, &u, &l, Regularisation::Fixed { lambda: 1e-30 }).unwrap();
            let error = (fit.solution - DVector::from_vec(truth.clone())).amax() / 10.0;
            assert!(
                error < 1e-6,
                "{options:?}: max relative density error {error}"
            );
        }
    }

    /// The tip prior on data the slab model explains to the noise: a
    /// density with a tip peak, the markers' response plus seeded noise.
    /// The marginal likelihood relaxes the tip and recovers the density
    /// better than the discrepancy principle with the uniform prior.
    #[test]
    fn the_evidence_lets_a_tip_peak_through_that_the_uniform_prior_flattens() {
        let p = phantom(0.03, 0.03, 0.003);
        let markers = layout(&p, 11);
        let grid = markers.grid().unwrap();
        let response = ShaftResponse::new(
            &p,
            &markers,
            &grid,
            &paper_material(),
            ModelOptions::slab(),
            [0.015, 0.0],
            [0.0, 1.0],
        )
        .unwrap();
        let basis = ShaftBasis::new(0.021, 1.5e-3).unwrap();
        let length = basis.length();
        // 20 N/m and a peak of 20 N/m more, 3 mm half-width, 2 mm behind
        // the tip.
        let truth: Vec<f64> = basis
            .stations
            .iter()
            .map(|s| 20.0 * (1.0 + (1.0 - (s - (length - 2e-3)).abs() / 3e-3).max(0.0)))
            .collect();
        let sigma = 1e-6;
        let g = response.response_matrix(&basis).unwrap();
        let exact = DVector::from_vec(response.predict(&basis, &truth).unwrap());
        let u = {
            use rand::SeedableRng;
            use rand_distr::Distribution;
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
            let normal = rand_distr::Normal::new(0.0, sigma).unwrap();
            exact.map(|x| x + normal.sample(&mut rng))
        };
        let truth = DVector::from_vec(truth);
        let error = |regularisation, prior| {
            let (fit, zone) = fit_with_tip_prior(
                &g,
                &u,
                &basis,
                Smoothness::FirstDifference,
                regularisation,
                prior,
            )
            .unwrap();
            let e = (&fit.solution - &truth).norm() / truth.norm();
            println!(
                "{regularisation:?}, {prior:?}: {:?}, zone {zone:?}, error {e:.3}",
                fit.choice
            );
            (e, fit.choice, zone)
        };
        let (uniform, ..) = error(Regularisation::Discrepancy { sigma }, TipPrior::Uniform);
        let (evidence, choice, zone) = error(
            Regularisation::MarginalLikelihood { sigma },
            TipPrior::Evidence,
        );
        assert_eq!(choice, LambdaChoice::MarginalLikelihood);
        assert!(zone.relaxation < 1.0, "{zone:?}");
        assert!(evidence < 0.75 * uniform, "{evidence} against {uniform}");
    }

    /// A stiffer back layer (Fig. 15's layered phantom) makes the same
    /// shaft load move the markers less; a layer list that does not match its
    /// materials is an error.
    #[test]
    fn layered_material_stiffens_and_is_checked() {
        use needle_fem::material::Material;
        use needle_force::MaterialField;
        let p = phantom(0.03, 0.03, 0.003);
        let markers = layout(&p, 7);
        let grid = markers.grid().unwrap();
        let soft = Material::new(25.3e3, 0.48).unwrap();
        let stiff = Material::new(4.0 * 25.3e3, 0.48).unwrap();
        let options = ModelOptions {
            model: Model::Plane(PlaneKind::Stress),
            refinement: 1,
        };
        let basis = ShaftBasis::new(0.02, 1.5e-3).unwrap();
        let q = vec![20.0; basis.len()];
        let norm = |material: &MaterialField| {
            let r = ShaftResponse::new(
                &p,
                &markers,
                &grid,
                material,
                options,
                [0.015, 0.0],
                [0.0, 1.0],
            )
            .unwrap();
            r.predict(&basis, &q)
                .unwrap()
                .iter()
                .map(|u| u * u)
                .sum::<f64>()
                .sqrt()
        };
        let homogeneous = norm(&MaterialField::Homogeneous(soft));
        let layered = norm(&MaterialField::LayersInY {
            boundaries: vec![0.015],
            materials: vec![soft, stiff],
        });
        assert!(
            layered < 0.9 * homogeneous,
            "layered {layered} vs homogeneous {homogeneous}"
        );
        let bad = MaterialField::LayersInY {
            boundaries: vec![0.01, 0.02],
            materials: vec![soft, stiff],
        };
        let err = ShaftResponse::new(&p, &markers, &grid, &bad, options, [0.015, 0.0], [0.0, 1.0])
            .unwrap_err();
        assert!(matches!(err, ForceError::Mismatch(_)));
    }

    #[test]
    fn a_response_needs_a_fixed_face_and_an_even_layer_count() {
        let mut p = phantom(0.03, 0.03, 0.003);
        let markers = layout(&p, 5);
        let grid = markers.grid().unwrap();
        let slab = |layers| ModelOptions {
            model: Model::Slab { layers },
            refinement: 1,
        };
        let err = ShaftResponse::new(
            &p,
            &markers,
            &grid,
            &paper_material(),
            slab(3),
            [0.015, 0.0],
            [0.0, 1.0],
        )
        .unwrap_err();
        assert!(matches!(
            err,
            ForceError::InvalidValue {
                field: "slab layers",
                ..
            }
        ));
        let err = ShaftResponse::new(
            &p,
            &markers,
            &grid,
            &paper_material(),
            slab(2),
            [0.04, 0.0],
            [0.0, 1.0],
        )
        .unwrap_err();
        assert!(matches!(
            err,
            ForceError::InvalidValue {
                field: "needle entry x",
                ..
            }
        ));
        p.fixed.clear();
        let err = ShaftResponse::new(
            &p,
            &markers,
            &grid,
            &paper_material(),
            slab(2),
            [0.015, 0.0],
            [0.0, 1.0],
        )
        .unwrap_err();
        assert!(matches!(err, ForceError::NoFixedFace));
    }
}

mod regularised {
    use super::*;

    /// A smoothing kernel (a discrete deconvolution problem).
    fn blur(m: usize, n: usize) -> DMatrix<f64> {
        DMatrix::from_fn(m, n, |i, j| {
            let x = i as f64 / (m - 1) as f64;
            let y = j as f64 / (n - 1) as f64;
            (-((x - y) / 0.08).powi(2)).exp() / n as f64
        })
    }

    fn first_difference(n: usize) -> DMatrix<f64> {
        DMatrix::from_fn(n - 1, n, |r, c| {
            if c == r + 1 {
                1.0
            } else if c == r {
                -1.0
            } else {
                0.0
            }
        })
    }

    fn noisy_data(a: &DMatrix<f64>, truth: &DVector<f64>, sigma: f64) -> DVector<f64> {
        use rand::SeedableRng;
        use rand_distr::Distribution;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let normal = rand_distr::Normal::new(0.0, sigma).unwrap();
        a * truth + DVector::from_fn(a.nrows(), |_, _| normal.sample(&mut rng))
    }

    #[test]
    fn a_tiny_fixed_lambda_recovers_a_well_posed_solution() {
        let a = DMatrix::from_fn(12, 4, |i, j| {
            ((i + 1) as f64).powi(j as i32) / 10.0_f64.powi(j as i32)
        });
        let truth = DVector::from_vec(vec![1.0, -2.0, 0.5, 3.0]);
        let fit = solve_regularised(
            &a,
            &(&a * &truth),
            &first_difference(4),
            Regularisation::Fixed { lambda: 1e-14 },
        )
        .unwrap();
        assert!((fit.solution - truth).amax() < 1e-8);
        assert_eq!(fit.choice, LambdaChoice::Fixed);
    }

    #[test]
    fn discrepancy_meets_the_noise_and_gcv_lands_near_it() {
        let (m, n) = (120, 40);
        let a = blur(m, n);
        let truth = DVector::from_fn(n, |j, _| 1.0 + (j as f64 / 6.0).sin());
        let sigma = 1e-3;
        let b = noisy_data(&a, &truth, sigma);
        let whitened_a = &a / sigma;
        let whitened_b = &b / sigma;
        let l = first_difference(n);
        let d = solve_regularised(
            &whitened_a,
            &whitened_b,
            &l,
            Regularisation::Discrepancy { sigma: 1.0 },
        )
        .unwrap();
        assert_eq!(d.choice, LambdaChoice::Discrepancy);
        assert!((d.residual_squared / m as f64 - DISCREPANCY_SAFETY.powi(2)).abs() < 1e-6);
        let g = solve_regularised(&whitened_a, &whitened_b, &l, Regularisation::Gcv).unwrap();
        assert_eq!(g.choice, LambdaChoice::Gcv);
        let error = |x: &DVector<f64>| (x - &truth).norm() / truth.norm();
        assert!(
            error(&d.solution) < 0.1,
            "discrepancy error {}",
            error(&d.solution)
        );
        assert!(error(&g.solution) < 0.1, "gcv error {}", error(&g.solution));
        // Both far better than the unregularised solution of this
        // ill-conditioned problem.
        let raw = solve_regularised(
            &whitened_a,
            &whitened_b,
            &l,
            Regularisation::Fixed { lambda: 1e-12 },
        )
        .unwrap();
        assert!(error(&raw.solution) > 3.0 * error(&d.solution));
        assert!(g.effective_parameters > 1.0 && g.effective_parameters < n as f64);
    }

    /// A blurring problem with model error: every row twice with data
    /// 0.005 apart, a misfit far above a noise of 1e-4 that no solution
    /// removes. Returns the matrix, the data and the truth.
    fn problem_short_of_the_noise(
        m: usize,
        n: usize,
    ) -> (DMatrix<f64>, DVector<f64>, DVector<f64>) {
        let a = blur(m, n);
        let truth = DVector::from_fn(n, |j, _| 1.0 + (j as f64 / 6.0).sin());
        let exact = &a * &truth;
        let a = DMatrix::from_fn(2 * m, n, |i, j| a[(i % m, j)]);
        let b = DVector::from_fn(2 * m, |i, _| {
            exact[i % m] + if i < m { 0.005 } else { -0.005 }
        });
        (a, b, truth)
    }

    #[test]
    fn an_unreachable_discrepancy_uses_the_misfit_floor_and_is_flagged() {
        let (m, n) = (120, 40);
        let (a, b, truth) = problem_short_of_the_noise(m, n);
        let m = 2 * m;
        let l = first_difference(n);
        let fit =
            solve_regularised(&a, &b, &l, Regularisation::Discrepancy { sigma: 1e-4 }).unwrap();
        assert_eq!(fit.choice, LambdaChoice::DiscrepancyAtModelFloor);
        // The residual stays far above the stated noise, and the solution is
        // still a sensible smoothing of the truth (not an unregularised one).
        assert!(fit.residual_squared > DISCREPANCY_SAFETY.powi(2) * m as f64 * 1e-8);
        let error = (fit.solution - &truth).norm() / truth.norm();
        assert!(error < 0.1, "relative error {error}");
    }

    /// $-2\log p(b \mid \lambda)$ of the Gaussian model $b = Aq + e$, $e
    /// \sim N(0, I)$, $q \sim N(0, (\lambda L^TL)^{-1})$ for a square
    /// invertible $L$, computed directly from the data's covariance
    /// $S = I + A(\lambda L^TL)^{-1}A^T$ (up to $m\log 2\pi$).
    fn direct_neg2_log_evidence(
        a: &DMatrix<f64>,
        b: &DVector<f64>,
        l: &DMatrix<f64>,
        lambda: f64,
    ) -> f64 {
        let prior_covariance = (l.transpose() * l * lambda).try_inverse().unwrap();
        let s = DMatrix::identity(a.nrows(), a.nrows()) + a * prior_covariance * a.transpose();
        let factor = s.cholesky().unwrap();
        let log_det = 2.0 * factor.l().diagonal().map(f64::ln).sum();
        b.dot(&factor.solve(b)) + log_det
    }

    #[test]
    fn the_most_probable_lambda_maximises_the_gaussian_marginal_likelihood() {
        let (m, n) = (60, 30);
        let a = blur(m, n) / 1e-3;
        let truth = DVector::from_fn(n, |j, _| 1.0 + (j as f64 / 5.0).sin());
        let b = noisy_data(&a, &truth, 1.0);
        // A proper prior: the first difference and an anchor on q_0.
        let mut l = DMatrix::zeros(n, n);
        l[(0, 0)] = 1.0;
        l.view_mut((1, 0), (n - 1, n))
            .copy_from(&first_difference(n));
        let fit = solve_regularised(
            &a,
            &b,
            &l,
            Regularisation::MarginalLikelihood { sigma: 1.0 },
        )
        .unwrap();
        assert_eq!(fit.choice, LambdaChoice::MarginalLikelihood);
        // Golden-section search of the direct formula over log lambda.
        let f = |x: f64| direct_neg2_log_evidence(&a, &b, &l, 10f64.powf(x));
        let (mut lo, mut hi) = (-8.0, 8.0);
        let ratio = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..80 {
            let (x1, x2) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
            if f(x1) < f(x2) { hi = x2 } else { lo = x1 }
        }
        let direct = 10f64.powf(0.5 * (lo + hi));
        assert!(
            (fit.lambda / direct - 1.0).abs() < 0.02,
            "most probable lambda {} against the direct maximum {direct}",
            fit.lambda
        );
    }

    #[test]
    fn the_marginal_likelihood_recovers_the_weight_of_the_prior_that_drew_the_data() {
        use rand::SeedableRng;
        use rand_distr::Distribution;
        // Denoising a random walk: steps of standard deviation 0.3 are the
        // prior exp(-lambda |Lq|^2 / 2) with lambda = 1 / 0.3^2 on unit
        // noise.
        let n = 400;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let step = rand_distr::Normal::new(0.0, 0.3).unwrap();
        let mut q = DVector::zeros(n);
        for j in 1..n {
            q[j] = q[j - 1] + step.sample(&mut rng);
        }
        let sigma = 0.5;
        let a = DMatrix::identity(n, n);
        let b = noisy_data(&a, &q, sigma);
        let fit = solve_regularised(
            &a,
            &b,
            &first_difference(n),
            Regularisation::MarginalLikelihood { sigma },
        )
        .unwrap();
        // lambda of the unwhitened problem: sigma^2 / 0.3^2.
        let expected = sigma * sigma / 0.09;
        println!(
            "most probable lambda {} (drawn with {expected})",
            fit.lambda
        );
        assert!(
            (fit.lambda / expected).ln().abs() < 0.3f64.ln_1p(),
            "lambda {} against {expected}",
            fit.lambda
        );
    }

    #[test]
    fn a_model_short_of_the_noise_falls_back_to_the_flagged_discrepancy() {
        let n = 40;
        let (a, b, truth) = problem_short_of_the_noise(120, n);
        let l = first_difference(n);
        let fit = solve_regularised(
            &a,
            &b,
            &l,
            Regularisation::MarginalLikelihood { sigma: 1e-4 },
        )
        .unwrap();
        assert_eq!(fit.choice, LambdaChoice::DiscrepancyAtModelFloor);
        let error = (fit.solution - &truth).norm() / truth.norm();
        assert!(error < 0.1, "relative error {error}");
    }

    #[test]
    fn bad_sizes_and_values_are_errors() {
        let a = DMatrix::from_element(5, 3, 1.0);
        let b = DVector::from_element(4, 1.0);
        assert!(matches!(
            solve_regularised(&a, &b, &first_difference(3), Regularisation::Gcv),
            Err(ForceError::Lsq(_))
        ));
        let mut b = DVector::from_element(5, 1.0);
        b[2] = f64::NAN;
        assert!(matches!(
            solve_regularised(&a, &b, &first_difference(3), Regularisation::Gcv),
            Err(ForceError::Lsq(_))
        ));
        let short = DMatrix::from_element(2, 3, 1.0);
        assert!(matches!(
            solve_regularised(
                &short,
                &DVector::zeros(2),
                &first_difference(3),
                Regularisation::Gcv
            ),
            Err(ForceError::TooFewMarkers { .. })
        ));
        // A = 0 shares the constants with the null space of L: singular.
        let zero = DMatrix::zeros(5, 3);
        assert!(
            solve_regularised(
                &zero,
                &DVector::from_element(5, 1.0),
                &first_difference(3),
                Regularisation::Gcv
            )
            .is_err()
        );
    }
}

mod paper_method {
    use super::*;

    fn insertion_with(displacement: impl Fn([f64; 2]) -> [f64; 2]) -> Insertion {
        let p = phantom(0.03, 0.03, 0.003);
        let markers = layout(&p, 7);
        let frame = Frame {
            t: 0.0,
            tip: [0.015, 0.012],
            theta: 0.0,
            base_force: [0.0, 0.1],
            displacement: markers
                .rest
                .iter()
                .map(|&r| Some(displacement(r)))
                .collect(),
            sigma: None,
        };
        Insertion {
            trial: "t".into(),
            velocity: 1e-3,
            phantom: p,
            marker_sigma: None,
            layout: markers,
            frames: vec![frame],
        }
    }

    #[test]
    fn node_forces_balance_and_vanish_for_rigid_motion() {
        let material = paper_material();
        let rigid = insertion_with(|p| [1e-4 - 0.01 * p[1], 2e-4 + 0.01 * p[0]]);
        let model = MarkerMeshModel::new(&rigid, &material, PlaneKind::Strain).unwrap();
        let f = model.nodal_forces(&rigid, &rigid.frames[0]).unwrap();
        // A rotation of 0.01 rad is a rigid motion only to first order;
        // K annihilates the linearised rotation exactly.
        assert!(
            f.forces
                .iter()
                .all(|v| v[0].abs() < 1e-12 && v[1].abs() < 1e-12)
        );

        let bent = insertion_with(|p| {
            [
                1e-4 * (p[1] * 100.0).sin(),
                1e-4 * (p[0] * 80.0).cos() * p[1] * 30.0,
            ]
        });
        let f = model.nodal_forces(&bent, &bent.frames[0]).unwrap();
        let total = f
            .forces
            .iter()
            .fold([0.0, 0.0], |a, v| [a[0] + v[0], a[1] + v[1]]);
        let scale = f
            .forces
            .iter()
            .map(|v| v[0].abs() + v[1].abs())
            .sum::<f64>();
        assert!(total[0].abs() < 1e-12 * scale && total[1].abs() < 1e-12 * scale);
        // Shaft nodes: the column x = 15 mm from the entry to the tip (y <= 12 mm).
        assert_eq!(f.shaft_nodes.len(), 3);
        assert!(f.shaft_positions.windows(2).all(|w| w[0] < w[1]));
        // Reactions: the back row.
        assert_eq!(f.reaction_nodes.len(), 7);
        assert!(
            f.reaction_nodes
                .iter()
                .all(|&n| (f.nodes[n][1] - 0.03).abs() < 1e-12)
        );
    }

    #[test]
    fn uniform_strain_loads_only_the_boundary() {
        // The patch test: an affine field has no interior node force.
        let material = paper_material();
        let affine = insertion_with(|p| [1e-3 * p[0] + 2e-3 * p[1], -1e-3 * p[1]]);
        let model = MarkerMeshModel::new(&affine, &material, PlaneKind::Stress).unwrap();
        let f = model.nodal_forces(&affine, &affine.frames[0]).unwrap();
        for (n, p) in f.nodes.iter().enumerate() {
            let interior = p[0] > 1e-9 && p[0] < 0.03 - 1e-9 && p[1] > 1e-9 && p[1] < 0.03 - 1e-9;
            if interior {
                assert!(
                    f.forces[n][0].abs() < 1e-12 && f.forces[n][1].abs() < 1e-12,
                    "node {n}"
                );
            }
        }
    }

    #[test]
    fn a_missing_marker_is_an_error_for_f_ku() {
        let material = paper_material();
        let mut insertion = insertion_with(|_| [0.0, 1e-4]);
        insertion.frames[0].displacement[10] = None;
        let model = MarkerMeshModel::new(&insertion, &material, PlaneKind::Strain).unwrap();
        let err = model
            .nodal_forces(&insertion, &insertion.frames[0])
            .unwrap_err();
        assert!(matches!(err, ForceError::MissingMarker { id: 10, .. }));
    }

    #[test]
    fn node_force_figure_is_svg() {
        let material = paper_material();
        let insertion = insertion_with(|p| {
            [
                0.0,
                1e-4 * (1.0 - p[1] / 0.03) * (-(p[0] - 0.015).powi(2) / 1e-5).exp(),
            ]
        });
        let f = MarkerMeshModel::new(&insertion, &material, PlaneKind::Strain)
            .unwrap()
            .nodal_forces(&insertion, &insertion.frames[0])
            .unwrap();
        let svg = plot_nodal_forces(&f).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("Node forces"));
        let curve = ShaftCurve::from_nodal("t = 0", &f);
        assert_eq!(curve.values.len(), 3);
        let svg = plot_shaft_distributions("Fig. 10a", "node force (N)", &[curve]).unwrap();
        assert!(svg.contains("Fig. 10a"));
    }
}

mod bundle {
    use super::*;

    fn write(dir: &std::path::Path, tips: &[f64]) -> std::path::PathBuf {
        let p = phantom(0.03, 0.03, 0.003);
        let markers = layout(&p, 5);
        let mut builder = BundleBuilder::new("unit", p);
        builder.markers_rest(
            markers
                .rest
                .iter()
                .enumerate()
                .map(|(k, r)| MarkerRest {
                    id: k as u32,
                    x: r[0],
                    y: r[1],
                })
                .collect(),
        );
        let probe = builder.trial(Trial {
            id: "probe".into(),
            kind: TrialKind::Probe,
            velocity: 0.0,
            day: 0.0,
        });
        probe.tool.push(ToolSample {
            t: 0.0,
            tip_x: 0.015,
            tip_y: 0.0,
            theta: 0.0,
            fx: 0.0,
            fy: 0.0,
            mz: 0.0,
        });
        let trial = builder.trial(Trial {
            id: "needle".into(),
            kind: TrialKind::Needle,
            velocity: 1e-3,
            day: 0.0,
        });
        for (k, &tip) in tips.iter().enumerate() {
            let t = k as f64;
            trial.tool.push(ToolSample {
                t,
                tip_x: 0.015,
                tip_y: tip,
                theta: 0.0,
                fx: 0.0,
                fy: 0.1 * t,
                mz: 0.0,
            });
        }
        for k in 0..tips.len() {
            // Frames half-way between tool samples, one marker lost in frame 1.
            let t = k as f64 + 0.5;
            let rows = markers
                .rest
                .iter()
                .enumerate()
                .filter(|&(id, _)| !(k == 1 && id == 3))
                .map(|(id, r)| (id as u32, [r[0], r[1] + 1e-5 * t]));
            trial.markers_mut().push_frame(k as u64, t, rows).unwrap();
        }
        let path = dir.join("bundle");
        builder.write(&path, WriteOptions::default()).unwrap();
        path
    }

    #[test]
    fn frames_are_interpolated_to_the_tool_clock() {
        let dir = tempfile::tempdir().unwrap();
        let bundle = read_bundle(write(dir.path(), &[-0.001, 0.002, 0.004, 0.006])).unwrap();
        let insertion = observe_insertion(&bundle, "needle").unwrap();
        // Frames at 0.5 (tip 0.0005), 1.5, 2.5; frame 3.5 is past the tool samples.
        assert_eq!(insertion.frames.len(), 3);
        let f = &insertion.frames[0];
        assert!((f.tip[1] - 0.0005).abs() < 1e-15);
        assert!((f.base_force[1] - 0.05).abs() < 1e-15);
        assert!((f.displacement[0].unwrap()[1] - 0.5e-5).abs() < 1e-15);
        assert_eq!(insertion.frames[1].tracked(), 24);
        assert!(insertion.frames[1].displacement[3].is_none());
    }

    #[test]
    fn wrong_trials_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let bundle = read_bundle(write(dir.path(), &[-0.003, -0.002, -0.001, -0.0005])).unwrap();
        assert!(matches!(
            observe_insertion(&bundle, "needle"),
            Err(ForceError::NoFramesInContact { .. })
        ));
        assert!(matches!(
            observe_insertion(&bundle, "probe"),
            Err(ForceError::NotANeedleTrial { .. })
        ));
        assert!(matches!(
            observe_insertion(&bundle, "nope"),
            Err(ForceError::UnknownTrial { .. })
        ));
    }
}

mod figures {
    use super::*;
    use needle_force::{IntegratedPoint, IntegratedSeries, ShaftDistribution, VelocityPoint};

    fn distribution(length: f64, q: f64) -> ShaftDistribution {
        let basis = ShaftBasis::new(length, 1e-3).unwrap();
        ShaftDistribution {
            t: 0.0,
            entry: [0.0, 0.0],
            entry_offset: 0.0,
            material_tip: [0.0, length],
            placement_change: 0.0,
            length,
            stations: basis.stations.clone(),
            density: vec![q; basis.len()],
            density_sigma: vec![0.0; basis.len()],
            integrated: q * length,
            integrated_sigma: 0.0,
            base_force: q * length,
            lambda: 1.0,
            choice: LambdaChoice::Gcv,
            tip_zone: TipZone::UNIFORM,
            residual_rms: 0.0,
            data_count: 100,
        }
    }

    #[test]
    fn density_against_velocity_pools_trials_and_skips_short_shafts() {
        let trials = vec![
            (
                1e-3,
                vec![distribution(0.02, 9.0), distribution(0.05, 10.0)],
            ),
            (1e-3, vec![distribution(0.06, 12.0)]),
            (5e-3, vec![distribution(0.05, 20.0)]),
            (9e-3, vec![distribution(0.01, 30.0)]),
        ];
        let points = density_vs_velocity(&trials, ShaftWindow::default()).unwrap();
        assert_eq!(points.len(), 2);
        assert_eq!(points[0].trials, 2);
        assert!((points[0].density - 11.0).abs() < 1e-9);
        assert!((points[0].spread - 2.0_f64.sqrt()).abs() < 1e-9);
        assert!((points[1].density - 20.0).abs() < 1e-9);
        let svg = plot_density_vs_velocity(&points).unwrap();
        assert!(svg.starts_with("<svg"));
        let none = vec![(1e-3, vec![distribution(0.01, 1.0)])];
        assert!(matches!(
            density_vs_velocity(&none, ShaftWindow::default()),
            Err(ForceError::Empty(_))
        ));
        let empty: Vec<VelocityPoint> = Vec::new();
        assert!(plot_density_vs_velocity(&empty).is_err());
    }

    #[test]
    fn integrated_figure_marks_flagged_points() {
        let point = |depth: f64, flagged| IntegratedPoint {
            t: depth,
            depth,
            integrated: 10.0 * depth,
            integrated_sigma: 0.0,
            base_force: 11.0 * depth,
            flagged,
        };
        let series = IntegratedSeries {
            trial: "a".into(),
            method: "m".into(),
            points: vec![point(0.01, false), point(0.02, true)],
        };
        let svg = plot_integrated_vs_base("Fig. 11", &[series]).unwrap();
        assert!(svg.contains("measured base force"));
        assert!(plot_integrated_vs_base("empty", &[]).is_err());
    }
}
