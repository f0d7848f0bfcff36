//! The paper's default geometry (75 x 75 x 7.5 mm, 21 x 21 markers, back
//! face fixed, E = 25.3 kPa, nu = 0.48) against a finer 3-D slab truth
//! (tip depths 5 to 70 mm): the figures quoted in
//! `docs/force-inversion.md`. Slow (minutes), so
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
        for frame in &noisy.frames {
            let d = estimator.estimate(&noisy, frame).unwrap();
            let e = distribution_error(&d, truth_density(20.0, d.length));
            println!(
                "  tip {:5.1} mm  inserted {:5.1} mm  F {:.4} +- {:.4} base {:.4}  integral err {:+.4}  density L2 err {:.3}  lambda {:.2e} {:?} rms {:.2e}",
                frame.tip[1] * 1e3,
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
