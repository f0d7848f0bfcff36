//! The paper's default geometry (75 x 75 x 7.5 mm, 21 x 21 markers, back
//! face fixed, E = 25.3 kPa, nu = 0.48) against a finer 3-D slab truth: the
//! figures quoted in `docs/force-inversion.md`. Slow (minutes), so
//! ignored by default; run with
//!
//! ```text
//! cargo test -p needle-force --test campaign -- --ignored --nocapture
//! ```

mod support;

use needle_force::{
    EstimatorOptions, Method, Model, ModelOptions, PlaneKind, Regularisation, ShaftEstimator,
    distribution_error, integrated_vs_base, paper_nodal_forces,
};
use support::{Truth, paper_material, phantom, truth_density, with_noise};

const NOISE: f64 = 4e-6;

#[test]
#[ignore = "default geometry; see the file doc"]
fn default_geometry_figures() {
    let material = paper_material();
    let start = std::time::Instant::now();
    let truth = Truth::new(phantom(0.075, 0.075, 0.0075), 21, 2, 4, &material);
    println!("truth built in {:.1} s", start.elapsed().as_secs_f64());
    let depths: Vec<f64> = (1..=14).map(|k| 5e-3 * k as f64).collect();
    let clean = truth.insertion(20.0, &depths, 1e-3);
    let noisy = with_noise(&clean, NOISE, 7);

    for kind in [PlaneKind::Strain, PlaneKind::Stress] {
        let series = integrated_vs_base(&clean, &material, Method::PaperNodal(kind)).unwrap();
        println!(
            "paper f = Ku {kind:?}: mean relative error past 10 mm {:+.3}",
            series.mean_relative_error(10e-3).unwrap()
        );
        for p in &series.points {
            println!(
                "  depth {:5.1} mm  F {:.4}  base {:.4}  err {:+.3}",
                p.depth * 1e3,
                p.integrated,
                p.base_force,
                p.relative_error()
            );
        }
        let last = paper_nodal_forces(&clean, depths.len() - 1, &material, kind).unwrap();
        println!(
            "  entry node force {:.4} N, shaft node forces {:?}",
            last.entry_node_force().unwrap(),
            last.shaft_axial_forces()
        );
    }

    for (name, options) in [
        (
            "slab",
            EstimatorOptions::slab(Regularisation::Discrepancy { sigma: NOISE }),
        ),
        ("slab gcv", EstimatorOptions::slab(Regularisation::Gcv)),
        (
            "slab refinement 2",
            EstimatorOptions {
                model: ModelOptions {
                    model: Model::Slab { layers: 2 },
                    refinement: 2,
                },
                ..EstimatorOptions::slab(Regularisation::Discrepancy { sigma: NOISE })
            },
        ),
        (
            "plane strain",
            EstimatorOptions::plane(Regularisation::Discrepancy { sigma: NOISE }),
        ),
    ] {
        let start = std::time::Instant::now();
        let estimator = ShaftEstimator::new(&noisy, &material, options).unwrap();
        println!(
            "{name}: model built in {:.1} s",
            start.elapsed().as_secs_f64()
        );
        for (frame, &depth) in noisy.frames.iter().zip(&depths) {
            let d = estimator.estimate(&noisy, frame).unwrap();
            let e = distribution_error(&d, truth_density(20.0, depth));
            println!(
                "  depth {:5.1} mm  F {:.4} +- {:.4} base {:.4}  integral err {:+.4}  density L2 err {:.3}  lambda {:.2e} {:?} rms {:.2e}",
                d.length * 1e3,
                d.integrated,
                d.integrated_sigma,
                d.base_force,
                e.integral,
                e.density,
                d.lambda,
                d.choice,
                d.residual_rms
            );
        }
    }
}

/// Where the density error of the slab estimator comes from: the error at
/// every regularisation weight of a grid (the best one is the most any rule
/// for lambda could reach), for both smoothness priors and two model
/// refinements, against the discrepancy principle's choice (at the
/// discrepancy fit's material length). Run with
/// `cargo test -p needle-force --test campaign -- --ignored density_error_against_lambda --nocapture`.
#[test]
#[ignore = "default geometry, minutes; prints the lambda study of docs/force-inversion.md"]
fn density_error_against_lambda() {
    use nalgebra::{DMatrix, DVector};
    use needle_force::{ShaftBasis, Smoothness, solve_regularised};
    let material = paper_material();
    let truth = Truth::new(phantom(0.075, 0.075, 0.0075), 21, 2, 4, &material);
    let depths = [0.02, 0.04, 0.06];
    let noisy = with_noise(&truth.insertion(20.0, &depths, 1e-3), NOISE, 7);
    let lambdas: Vec<f64> = (-6..=6).map(|k| 10f64.powi(k)).collect();
    for refinement in [1, 2] {
        for smoothness in [Smoothness::FirstDifference, Smoothness::SecondDifference] {
            let estimator = ShaftEstimator::new(
                &noisy,
                &material,
                EstimatorOptions {
                    model: ModelOptions {
                        model: Model::Slab { layers: 2 },
                        refinement,
                    },
                    smoothness,
                    ..EstimatorOptions::slab(Regularisation::Discrepancy { sigma: NOISE })
                },
            )
            .unwrap();
            for (frame, &depth) in noisy.frames.iter().zip(&depths) {
                let d = estimator.estimate(&noisy, frame).unwrap();
                let e = distribution_error(&d, truth_density(20.0, depth));
                let mut line = format!(
                    "r{refinement} {smoothness:?} depth {:.0} mm: discrepancy lambda {:.1e} err {:.3} integral {:+.4} (rms {:.2e}); grid:",
                    depth * 1e3,
                    d.lambda,
                    e.density,
                    e.integral,
                    d.residual_rms
                );
                let basis = ShaftBasis::new(d.length, 1.5e-3).unwrap();
                let g = estimator.response().response_matrix(&basis).unwrap();
                let u: Vec<f64> = frame.displacement.iter().flat_map(|m| m.unwrap()).collect();
                let a = DMatrix::from_fn(g.nrows(), g.ncols(), |r, c| g[(r, c)] / NOISE);
                let b = DVector::from_fn(u.len(), |r, _| u[r] / NOISE);
                let l = basis.difference_operator(smoothness);
                for &lambda in &lambdas {
                    let fit =
                        solve_regularised(&a, &b, &l, Regularisation::Fixed { lambda }).unwrap();
                    let mut fixed = d.clone();
                    fixed.stations = basis.stations.clone();
                    fixed.density = fit.solution.iter().copied().collect();
                    let e = distribution_error(&fixed, truth_density(20.0, depth));
                    line += &format!(" {lambda:.0e}:{:.3}", e.density);
                }
                println!("{line}");
            }
        }
    }
}

/// Diagnostics of the density error: the material length found against the
/// truth's, the density at the stations against the truth at the best
/// lambda of the grid, and the error when the smoothness penalty is relaxed
/// by `relax` over the last `window` of the shaft (the tip region). Run with
/// `cargo test -p needle-force --test campaign -- --ignored density_error_diagnostics --nocapture`.
#[test]
#[ignore = "default geometry, minutes; diagnostics behind docs/force-inversion.md"]
fn density_error_diagnostics() {
    use nalgebra::{DMatrix, DVector};
    use needle_force::{ShaftBasis, Smoothness, solve_regularised};
    let material = paper_material();
    let truth = Truth::new(phantom(0.075, 0.075, 0.0075), 21, 2, 4, &material);
    let depths = [0.02, 0.04, 0.06];
    let noisy = with_noise(&truth.insertion(20.0, &depths, 1e-3), NOISE, 7);
    let lambdas: Vec<f64> = (-5..=1).map(|k| 10f64.powi(k)).collect();
    for refinement in [1, 2] {
        let estimator = ShaftEstimator::new(
            &noisy,
            &material,
            EstimatorOptions {
                model: ModelOptions {
                    model: Model::Slab { layers: 2 },
                    refinement,
                },
                ..EstimatorOptions::slab(Regularisation::Discrepancy { sigma: NOISE })
            },
        )
        .unwrap();
        for (frame, &depth) in noisy.frames.iter().zip(&depths) {
            let d = estimator.estimate(&noisy, frame).unwrap();
            println!(
                "r{refinement} depth {:.1} mm: material length found {:.3} mm",
                depth * 1e3,
                d.length * 1e3
            );
            // The whitened residual against the material length: does the
            // data pin the tip where the truth has it?
            {
                let u: Vec<f64> = frame.displacement.iter().flat_map(|m| m.unwrap()).collect();
                let b = DVector::from_fn(u.len(), |r, _| u[r] / NOISE);
                let mut line =
                    String::from("  residual^2 (lambda 1e-2) against length - true (mm):");
                for k in -8..=6 {
                    let length = depth + 1e-4 * k as f64;
                    let basis = ShaftBasis::new(length, 1.5e-3).unwrap();
                    let g = estimator.response().response_matrix(&basis).unwrap();
                    let a = DMatrix::from_fn(g.nrows(), g.ncols(), |r, c| g[(r, c)] / NOISE);
                    let l = basis.difference_operator(Smoothness::FirstDifference);
                    let fit = solve_regularised(&a, &b, &l, Regularisation::Fixed { lambda: 1e-2 })
                        .unwrap();
                    line += &format!(
                        " {:+.1}:{:.0}",
                        1e3 * (length - depth),
                        fit.residual_squared
                    );
                }
                println!("{line}");
            }
            for (label, length) in [("found length", d.length), ("true length", depth)] {
                let basis = ShaftBasis::new(length, 1.5e-3).unwrap();
                let g = estimator.response().response_matrix(&basis).unwrap();
                let u: Vec<f64> = frame.displacement.iter().flat_map(|m| m.unwrap()).collect();
                let a = DMatrix::from_fn(g.nrows(), g.ncols(), |r, c| g[(r, c)] / NOISE);
                let b = DVector::from_fn(u.len(), |r, _| u[r] / NOISE);
                for (window, relax) in [(0.0, 1.0), (6e-3, 0.1), (6e-3, 0.01), (9e-3, 0.01)] {
                    let mut l = basis.difference_operator(Smoothness::FirstDifference);
                    for r in 0..l.nrows() {
                        let middle = 0.5 * (basis.stations[r] + basis.stations[r + 1]);
                        if middle > length - window {
                            l.row_mut(r).scale_mut(relax);
                        }
                    }
                    let mut best = (f64::INFINITY, 0.0, Vec::new());
                    let mut line =
                        format!("  {label}, tip window {:.0} mm x {relax}:", window * 1e3);
                    for &lambda in &lambdas {
                        let fit = solve_regularised(&a, &b, &l, Regularisation::Fixed { lambda })
                            .unwrap();
                        let mut fixed = d.clone();
                        fixed.length = length;
                        fixed.stations = basis.stations.clone();
                        fixed.density = fit.solution.iter().copied().collect();
                        let e = distribution_error(&fixed, truth_density(20.0, depth));
                        line += &format!(" {lambda:.0e}:{:.3}", e.density);
                        if e.density < best.0 {
                            best = (e.density, lambda, fixed.density.clone());
                        }
                    }
                    println!("{line}");
                    if window == 0.0 || relax == 0.01 && window == 6e-3 {
                        let t = truth_density(20.0, depth);
                        let pairs: Vec<String> = basis
                            .stations
                            .iter()
                            .zip(&best.2)
                            .map(|(s, q)| format!("{:.1}:{:.1}/{:.1}", s * 1e3, q, t(*s)))
                            .collect();
                        println!(
                            "    best lambda {:.0e}: s(mm):est/true {}",
                            best.1,
                            pairs.join(" ")
                        );
                    }
                }
            }
        }
    }
}
