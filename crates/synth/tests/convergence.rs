//! Discretisation error of the truth, behind `#[ignore]` (minutes). Run
//! with
//! `cargo test -p needle-synth --release --test convergence -- --ignored --nocapture --test-threads 1`.
//!
//! The 3-D null slab is solved for one 1 mm/s insertion to 50 mm; the final
//! marker displacements are compared between meshes. The error is taken
//! as the sum of an in-plane part and a through-thickness part, each
//! $e(h) \approx C h^p$, estimated by two separate refinement sequences
//! (in-plane refinement r at the default layer count, and the layer count
//! at the default in-plane size): from three levels the observed order
//! $p$ and, by Richardson extrapolation, the error of each level. The
//! test asserts that the default resolution is within a tenth of the
//! marker noise, and prints the tables that `docs/truth-world.md` quotes.
//! A third test compares the plane-strain truth of
//! `fixtures/scenarios/null.ron` (one probe, one insertion) with the same
//! at twice its refinement.

use needle_synth::{EffectId, Effects, Scenario, load_scenario, respond};

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

/// Observed order $p$ from the differences of three levels of sizes
/// $h_0 > h_1 > h_2$: solves
/// $d_{01}/d_{12} = (h_0^p - h_1^p)/(h_1^p - h_2^p)$ by bisection.
fn observed_order(h: [f64; 3], d01: f64, d12: f64) -> f64 {
    let ratio = |p: f64| (h[0].powf(p) - h[1].powf(p)) / (h[1].powf(p) - h[2].powf(p));
    let target = d01 / d12;
    let (mut lo, mut hi) = (1e-3, 12.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        // The ratio grows with p.
        if ratio(mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Refines one direction over `levels` (sizes `sizes`), printing the
/// differences to the finest level, the observed order from the last three
/// and the extrapolated error of each level; returns the error of the
/// first (coarsest) level.
fn study(name: &str, sizes: &[f64], solutions: &[Vec<[f64; 2]>], sigma: f64) -> f64 {
    let n = sizes.len();
    let d = |i: usize, j: usize| largest_difference(&solutions[i], &solutions[j]);
    let p = observed_order(
        [sizes[n - 3], sizes[n - 2], sizes[n - 1]],
        d(n - 3, n - 2),
        d(n - 2, n - 1),
    );
    // Richardson: the finest level's own error is C h^p with
    // C = d / (h_a^p - h_b^p) from the last pair.
    let c = d(n - 2, n - 1) / (sizes[n - 2].powf(p) - sizes[n - 1].powf(p));
    println!("{name}: observed order p = {p:.2}");
    println!("| level | vs finest (um) | extrapolated error (um) | / sigma |");
    println!("|---|---|---|---|");
    let mut first = 0.0;
    for i in 0..n {
        let error = c * sizes[i].powf(p);
        println!(
            "| {} | {:.2} | {:.2} | {:.3} |",
            sizes[i],
            d(i, n - 1) * 1e6,
            error * 1e6,
            error / sigma
        );
        if i == 0 {
            first = error;
        }
    }
    first
}

#[test]
#[ignore = "minutes: mesh convergence of the 3-D truth"]
fn discretisation_error_is_below_a_tenth_of_the_marker_noise() {
    let default = Scenario::paper_default();
    let sigma = default.sensors.marker_sigma;
    let r = default.resolution;
    // Only the final state is compared, so coarse depth steps suffice.
    let step = 0.005;
    let refinements = [r.refinement, 2 * r.refinement, 3 * r.refinement];
    let in_plane: Vec<_> = refinements
        .iter()
        .map(|&k| final_markers(&slab(k, r.layers, step)))
        .collect();
    let sizes: Vec<f64> = refinements.iter().map(|&k| 1.0 / k as f64).collect();
    let e_plane = study("in-plane (h / default h)", &sizes, &in_plane, sigma);
    let layers = [r.layers, 2 * r.layers, 4 * r.layers];
    let through: Vec<_> = layers
        .iter()
        .map(|&l| final_markers(&slab(r.refinement, l, step)))
        .collect();
    let sizes: Vec<f64> = layers.iter().map(|&l| r.layers as f64 / l as f64).collect();
    let e_layers = study("through thickness (h / default h)", &sizes, &through, sigma);
    let at_default = e_plane + e_layers;
    println!(
        "default resolution: {:.2} um ({:.3} sigma)",
        at_default * 1e6,
        at_default / sigma
    );
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

/// The null plane-strain truth of `fixtures/scenarios/null.ron` (the truth
/// that hides every effect but `out_of_plane`) with its in-plane
/// refinement multiplied by `factor`: its first probe and one 1 mm/s
/// insertion to 50 mm.
fn plane(factor: usize) -> Scenario {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/scenarios/null.ron"
    );
    let mut s = load_scenario(path).unwrap();
    s.probes.truncate(1);
    s.needles.velocities = vec![0.001];
    s.needles.days = vec![2.0];
    s.resolution.refinement *= factor;
    s.resolution.depth_step = 0.005;
    s
}

/// Largest and rms vector difference of the final marker displacements,
/// and the worst marker's column and row.
fn compare(a: &[[f64; 2]], b: &[[f64; 2]], columns: usize) -> (f64, f64, usize, usize) {
    let d: Vec<f64> = a
        .iter()
        .zip(b)
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .collect();
    let (worst, largest) =
        d.iter().enumerate().fold(
            (0, 0.0f64),
            |best, (k, &v)| if v > best.1 { (k, v) } else { best },
        );
    let rms = (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt();
    (largest, rms, worst % columns, worst / columns)
}

#[test]
#[ignore = "a minute: mesh convergence of the plane-strain truth"]
fn plane_truth_discretisation_error_is_below_a_tenth_of_the_marker_noise() {
    let default = plane(1);
    let sigma = default.sensors.marker_sigma;
    let columns = default.phantom.markers.0;
    let coarse = respond(&default).unwrap();
    let fine = respond(&plane(2)).unwrap();
    println!(
        "refinement {} against {} (um): largest / rms, worst marker column and row",
        default.resolution.refinement,
        2 * default.resolution.refinement
    );
    let mut largest = 0.0f64;
    for (trial, (a, b)) in coarse.iter().zip(&fine).enumerate() {
        let (max, rms, column, row) = compare(
            a.markers.last().unwrap(),
            b.markers.last().unwrap(),
            columns,
        );
        println!(
            "trial {trial}: {:.2} / {:.2}, column {column} row {row}",
            max * 1e6,
            rms * 1e6
        );
        largest = largest.max(max);
    }
    assert!(
        largest < 0.1 * sigma,
        "plane truth: {largest} m between refinements against sigma {sigma} m"
    );
}
