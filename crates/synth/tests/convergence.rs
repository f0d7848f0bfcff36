//! Discretisation error of the truth, behind `#[ignore]` (minutes in
//! debug). Run with
//! `cargo test -p needle-synth --release --test convergence -- --ignored --nocapture`.
//!
//! The 3-D null slab is solved for one 1 mm/s insertion to 50 mm at
//! increasing mesh refinement; the final marker displacements are compared
//! with the finest mesh. The test asserts that the default resolution is
//! within a tenth of the marker noise of the finest one, and prints the
//! table that `docs/truth-world.md` quotes.

use needle_synth::{EffectId, Effects, Scenario, respond};

fn slab(refinement: usize, layers: usize, depth_step: f64) -> Scenario {
    let mut s = Scenario::null();
    s.effects = Effects::none().with(EffectId::OutOfPlane);
    s.probes.clear();
    s.needles.velocities = vec![0.001];
    s.needles.days = vec![2.0];
    s.resolution.refinement = refinement;
    s.resolution.layers = layers;
    s.resolution.depth_step = depth_step;
    s
}

fn final_markers(s: &Scenario) -> Vec<[f64; 2]> {
    respond(s).unwrap()[0].markers.last().unwrap().clone()
}

fn largest_difference(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .fold(0.0, f64::max)
}

#[test]
#[ignore = "minutes: mesh convergence of the 3-D truth"]
fn discretisation_error_is_below_a_tenth_of_the_marker_noise() {
    let default = Scenario::paper_default();
    let sigma = default.sensors.marker_sigma;
    // Only the final state is compared, so coarse depth steps suffice.
    let step = 0.005;
    let reference = final_markers(&slab(3, 4, step));
    println!("| refinement | layers | max marker error (m) | / sigma |");
    println!("|---|---|---|---|");
    let mut at_default = f64::INFINITY;
    for (refinement, layers) in [(1, 2), (1, 4), (2, 2), (2, 4), (3, 2)] {
        let error = largest_difference(&final_markers(&slab(refinement, layers, step)), &reference);
        println!(
            "| {refinement} | {layers} | {error:.3e} | {:.3} |",
            error / sigma
        );
        if (refinement, layers) == (default.resolution.refinement, default.resolution.layers) {
            at_default = error;
        }
    }
    assert!(
        at_default < 0.1 * sigma,
        "default resolution error {at_default} vs sigma {sigma}"
    );
}

#[test]
#[ignore = "minutes: interpolation between solved needle states"]
fn interpolation_between_states_is_below_a_tenth_of_the_marker_noise() {
    let default = Scenario::paper_default();
    let sigma = default.sensors.marker_sigma;
    let r = default.resolution;
    // States at half the step: the odd ones are what interpolation
    // between the even ones would give at the default step.
    let fine = respond(&slab(r.refinement, r.layers, r.depth_step / 2.0)).unwrap();
    let markers = &fine[0].markers;
    let mut error = 0.0f64;
    for k in (1..markers.len() - 1).step_by(2) {
        for ((a, b), m) in markers[k - 1].iter().zip(&markers[k + 1]).zip(&markers[k]) {
            error = error.max((0.5 * (a[0] + b[0]) - m[0]).hypot(0.5 * (a[1] + b[1]) - m[1]));
        }
    }
    println!(
        "interpolation error at depth step {}: {error:.3e} m ({:.3} sigma)",
        r.depth_step,
        error / sigma
    );
    assert!(error < 0.1 * sigma);
}
