//! Discretisation error of the truth, behind `#[ignore]` (minutes). Run
//! with
//! `cargo test -p needle-synth --release --test convergence -- --ignored --nocapture --test-threads 1`.
//!
//! The 3-D null slab is solved for one 1 mm/s insertion to 50 mm; the final
//! marker displacements are compared between meshes, graded by
//! `SlabGrading`, all on four layers. Two sequences of three levels each
//! give an observed order $p$ and, by Richardson extrapolation
//! ($e(h) \approx C h^p$), the error of each level: through the thickness
//! (on the finest plan, 5 levels towards the faces and sides and 4
//! towards the needle line: 1, 2 and 3 levels towards the mid-plane and
//! the top face, the last the reference) and in the plane (2 levels
//! through the thickness: one level more towards the faces, sides and
//! needle line each time). The test asserts the requirement itself, the
//! default mesh within a tenth of the marker noise of the reference, and
//! prints the tables that `docs/truth-world.md` quotes. It fails: the
//! default is some 4.5 µm away.
//! A second test solves that insertion, and one with the paper default's
//! tip peak and velocity friction at 9 mm/s on another line, as the fine
//! paper default did up to session 40 (the needle placed on a slab
//! graded once more towards the needle lines, then settled on the finer
//! tensor slab `TENSOR_MARKER_SLAB`), and asserts both within a tenth of
//! the noise of their references at every state. It passes
//! (0.45 and 0.52 µm at worst; before the needle was settled on the finer
//! mesh, 0.66 µm and 1.8 µm just after the entry). Another does the same
//! for each of the campaign's ten insertions (its line, velocity, day and
//! effects) and passes (0.66 µm at worst; the paper default's mesh 2.9 to
//! 9.5 µm). All these compare meshes at in-plane refinement 1; one more
//! test solves the last insertion at refinement 2 and asserts the
//! reference within a tenth of the noise of it. It fails: 7.2 µm.
//! Another refines the in-plane size alone (refinements 1, 2 and 4, the
//! thickness graded once) and asserts the extrapolated in-plane error of
//! the fine paper default's plan within a tenth of the noise. It fails:
//! refinement 4 is 5.2 µm away, the observed order 1.2. One more does
//! the same for the first probe on the tensor probe slab the fine paper
//! default used up to session 41 (refinements 1, 2 and 3) and fails:
//! refinement 3 is 7.5 µm away.
//! Since session 41 the fine paper default settles each insertion on a
//! slab of its own refined locally along its material path
//! (`SlabGrading::local`); one test settles the last insertion so and on
//! six slabs each refined one way more (path, entry and tip, back face,
//! far field, grading, layers) and asserts the markers within a tenth of
//! the noise of each; another does it for every insertion of the
//! campaign against the far field one level finer.
//! Another presses each of the paper default's four probes alone, on
//! the paper default's slab and on that tensor probe slab, against slabs
//! graded once more towards the faces, the top face and the probe's
//! edges, and asserts the tensor probe slab within a tenth of the noise
//! (it passes: 0.61 µm at worst; the paper default's slab is 39 to 77
//! µm away). Since session 42 the fine paper default presses each probe
//! on a slab refined in the plan (`LocalRefinement::plan_only`); one
//! test presses the first probe so and on six slabs each refined one
//! way more (edges, back face, far field, grading, top face, layers),
//! another every probe against the far field one level finer and a
//! finer grading, and two more every probe against two slabs refined
//! several ways at once, each asserting the markers within a tenth of the
//! noise.
//! A third test measures the interpolation between needle states. A
//! fourth compares the plane-strain truth of `fixtures/scenarios/null.ron`
//! (one probe, one insertion; its grid graded towards the probe edges,
//! sides and faces) with the same at twice its refinement, where every
//! element, the graded ones included, is halved. A fifth compares the
//! neo-Hookean plane truth of `fixtures/scenarios/material-nonlinearity.ron`
//! (its first probe) with refinement 12 graded one level less, the finest
//! mesh on which that probe solves. A sixth presses that probe with
//! rounded edges 1 mm deep on refinement 6 and 12.

use needle_data::TrialKind;
use needle_synth::interpolate::stencil;
use needle_synth::sensor::stated_force_sigma;
use needle_synth::{
    EffectId, Effects, LocalRefinement, Scenario, SlabGrading, TrialResponse, load_scenario,
    respond,
};

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
/// last (finest) level.
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
    for i in 0..n {
        let error = c * sizes[i].powf(p);
        println!(
            "| {} | {:.2} | {:.2} | {:.3} |",
            sizes[i],
            d(i, n - 1) * 1e6,
            error * 1e6,
            error / sigma
        );
    }
    c * sizes[n - 1].powf(p)
}

/// The 3-D null slab at refinement 1 with `layers` layers and `grading`.
fn graded(layers: usize, grading: SlabGrading) -> Vec<[f64; 2]> {
    let mut s = slab(1, layers, 0.005);
    s.resolution.slab_grading = Some(grading);
    final_markers(&s)
}

#[test]
#[ignore = "minutes: mesh convergence of the 3-D truth"]
fn discretisation_error_is_below_a_tenth_of_the_marker_noise() {
    let default = Scenario::paper_default();
    let sigma = default.sensors.marker_sigma;
    let r = default.resolution;
    assert_eq!(r.refinement, 1, "the sequences below are at refinement 1");
    assert_eq!(r.layers, 4, "the sequences below refine four layers");
    let grading = |faces: usize, needle_lines: usize, through: usize| SlabGrading {
        faces,
        needle_lines,
        mid_plane: through,
        top_face: through,
        probe_edges: 0,
        local: None,
    };
    // Through the thickness, on the finest plan: 1, 2 and 3 levels towards
    // the mid-plane and the top face, the finest layer t/8, t/16, t/32.
    // The last is the reference.
    let through: Vec<_> = [1, 2, 3]
        .iter()
        .map(|&l| graded(4, grading(5, 4, l)))
        .collect();
    let e_through = study(
        "through the thickness, towards the mid-plane and the top face (finest layer / t)",
        &[0.125, 0.0625, 0.03125],
        &through,
        sigma,
    );
    // In the plane, two levels through the thickness: each level one more
    // towards the faces and sides and towards the needle lines, the finest
    // element at the faces h/8, h/16, h/32.
    let in_plane: Vec<_> = [(3, 1), (4, 2), (5, 3)]
        .iter()
        .map(|&(faces, needle_lines)| graded(4, grading(faces, needle_lines, 2)))
        .collect();
    let e_plane = study(
        "in the plane, towards the faces, sides and needle lines (finest at the faces / h)",
        &[0.125, 0.0625, 0.03125],
        &in_plane,
        sigma,
    );
    let reference = &through[2];
    let paper = graded(r.layers, r.slab_grading.unwrap_or(SlabGrading::DEFAULT));
    let at_default = largest_difference(&paper, reference);
    println!(
        "the paper default's mesh against the reference: {:.2} um ({:.3} sigma); \
         extrapolated errors: the reference through the thickness {:.2} um, \
         the finest plan of the in-plane sequence {:.2} um",
        at_default * 1e6,
        at_default / sigma,
        e_through * 1e6,
        e_plane * 1e6,
    );
    assert!(
        at_default < 0.1 * sigma,
        "default resolution error {at_default} vs sigma {sigma}"
    );
}

/// Largest marker difference over every state (m) and the state where it
/// lies.
fn largest_over_states(a: &[Vec<[f64; 2]>], b: &[Vec<[f64; 2]>]) -> (f64, usize) {
    a.iter()
        .zip(b)
        .map(|(p, q)| largest_difference(p, q))
        .enumerate()
        .fold(
            (0.0, 0),
            |best, (k, d)| if d > best.0 { (d, k) } else { best },
        )
}

/// [`largest_over_states`], with the marker where it lies.
fn worst_marker(a: &[Vec<[f64; 2]>], b: &[Vec<[f64; 2]>]) -> (f64, usize, usize) {
    let (gap, state) = largest_over_states(a, b);
    let marker = a[state]
        .iter()
        .zip(&b[state])
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .enumerate()
        .fold(
            (0, 0.0),
            |best, (i, d)| if d > best.1 { (i, d) } else { best },
        )
        .0;
    (gap, state, marker)
}

/// The tensor slab the fine paper default settled its needle trials on
/// from session 36 to 40, before its slab of its own along each
/// insertion's material path: five levels towards the faces and sides,
/// three towards each needle line, two towards the mid-plane and the top
/// face. The tests below that use it measure the tensor slabs.
const TENSOR_MARKER_SLAB: SlabGrading = SlabGrading {
    faces: 5,
    needle_lines: 3,
    mid_plane: 2,
    top_face: 2,
    probe_edges: 0,
    local: None,
};

/// The reference slab of the needle trials: the finest level through the
/// thickness of the test above.
const NEEDLE_REFERENCE: SlabGrading = SlabGrading {
    faces: 5,
    needle_lines: 4,
    mid_plane: 3,
    top_face: 3,
    probe_edges: 0,
    local: None,
};

/// The insertion of the null slab above, and one of the paper default's
/// last insertions: 9 mm/s on day 5 on the line x = 39.5 mm, with its
/// velocity-dependent friction and the tip's cutting force.
fn insertions() -> [(&'static str, Scenario); 2] {
    let null = slab(1, 4, 0.005);
    let mut paper_like = slab(1, 4, 0.005);
    paper_like.effects = Effects::none()
        .with(EffectId::OutOfPlane)
        .with(EffectId::VelocityDependentFriction)
        .with(EffectId::TipCuttingForce);
    paper_like.needles.velocities = vec![0.009];
    paper_like.needles.days = vec![5.0];
    paper_like.needles.first_line = 0.0395;
    [
        ("null slab, 1 mm/s, x = 12 mm", null),
        (
            "tip peak and velocity friction, 9 mm/s, x = 39.5 mm",
            paper_like,
        ),
    ]
}

#[test]
#[ignore = "minutes: the slab's needle settled on a finer mesh against the reference"]
fn the_tensor_marker_slab_is_within_a_tenth_of_the_marker_noise_of_the_tensor_reference() {
    let fine = Scenario::paper_default_fine().resolution;
    let paper = Scenario::paper_default().resolution;
    let sigma = Scenario::paper_default_fine().sensors.marker_sigma;
    assert_eq!((fine.refinement, fine.layers), (1, 4), "as the reference");
    let mut worst_fine: f64 = 0.0;
    for (insertion_name, scenario) in insertions() {
        let insertion = |placement: Option<SlabGrading>, markers: Option<SlabGrading>| {
            let mut s = scenario.clone();
            s.resolution.slab_grading = placement;
            s.resolution.marker_grading = markers;
            respond(&s).unwrap().remove(0).markers
        };
        let reference = insertion(Some(NEEDLE_REFERENCE), None);
        let rows = [
            ("the paper default's mesh", paper.slab_grading, None),
            (
                "the tensor marker slab alone",
                Some(TENSOR_MARKER_SLAB),
                None,
            ),
            (
                "the paper default's placement settled on the tensor marker slab",
                paper.slab_grading,
                Some(TENSOR_MARKER_SLAB),
            ),
            (
                "the fine paper default's placement settled on the tensor marker slab",
                fine.slab_grading,
                Some(TENSOR_MARKER_SLAB),
            ),
        ];
        println!(
            "{insertion_name}: against the reference, largest over the markers at each of the {} states (um):",
            reference.len()
        );
        // The last row is the fine paper default's.
        let mut last_row = 0.0;
        for (name, placement, markers) in rows {
            let states = insertion(placement, markers);
            let per_state: Vec<String> = states
                .iter()
                .zip(&reference)
                .map(|(a, b)| format!("{:.2}", largest_difference(a, b) * 1e6))
                .collect();
            let (worst, at) = largest_over_states(&states, &reference);
            println!(
                "| {name} | {:.2} (state {at}, {:.3} sigma) | {} |",
                worst * 1e6,
                worst / sigma,
                per_state.join(" ")
            );
            last_row = worst;
        }
        worst_fine = worst_fine.max(last_row);
    }
    assert!(
        worst_fine < 0.1 * sigma,
        "the fine paper default {worst_fine} m from the reference, sigma {sigma} m"
    );
}

/// Every insertion of the paper default's campaign (its line, velocity,
/// day and effects; no probes, no compression test), each alone on a
/// slab graded towards its line only, states every 5 mm (2.5 mm over the
/// first 8 mm): the fine paper default's placement settled on its marker
/// slab, and the paper default's mesh, against the reference slab above.
/// Asserts the fine paper default's within a tenth of the marker noise at
/// every state of every insertion; prints both per insertion.
#[test]
#[ignore = "about sixteen minutes: ten insertions on the reference slab"]
fn every_insertion_on_the_tensor_marker_slab_is_within_a_tenth_of_the_marker_noise_of_the_tensor_reference()
 {
    let fine = Scenario::paper_default_fine();
    let sigma = fine.sensors.marker_sigma;
    let paper_slab = Scenario::paper_default().resolution.slab_grading;
    let mut worst_fine: f64 = 0.0;
    println!(
        "| insertion | line x (mm) | velocity (mm/s) | day | the paper default's mesh: largest (um), state | the fine paper default: largest (um), state |"
    );
    for (k, plan) in fine.needles.plan().into_iter().enumerate() {
        let alone = campaign_insertion_alone(&fine, k);
        let insertion = |placement: Option<SlabGrading>, markers: Option<SlabGrading>| {
            let mut s = alone.clone();
            s.resolution.slab_grading = placement;
            s.resolution.marker_grading = markers;
            let trial = respond(&s).unwrap().remove(0);
            assert_eq!(trial.kind, TrialKind::Needle);
            trial.markers
        };
        let reference = insertion(Some(NEEDLE_REFERENCE), None);
        let (paper, paper_at) = largest_over_states(&insertion(paper_slab, None), &reference);
        let (settled, settled_at) = largest_over_states(
            &insertion(fine.resolution.slab_grading, Some(TENSOR_MARKER_SLAB)),
            &reference,
        );
        println!(
            "| {} | {:.1} | {:.0} | {} | {:.2} ({:.3} sigma), {paper_at} | {:.2} ({:.3} sigma), {settled_at} |",
            k + 1,
            plan.line * 1e3,
            plan.velocity * 1e3,
            plan.day,
            paper * 1e6,
            paper / sigma,
            settled * 1e6,
            settled / sigma,
        );
        worst_fine = worst_fine.max(settled);
    }
    assert!(
        worst_fine < 0.1 * sigma,
        "the fine paper default {worst_fine} m from the reference, sigma {sigma} m"
    );
}

/// The campaign's insertion `k`, alone as in the test above.
fn campaign_insertion_alone(fine: &Scenario, k: usize) -> Scenario {
    let plan = fine.needles.plan()[k];
    let mut alone = fine.clone();
    alone.probes.clear();
    alone.compression = None;
    alone.frames = None;
    alone.needles.velocities = vec![plan.velocity];
    alone.needles.days = vec![plan.day];
    alone.needles.first_line = plan.line;
    alone.resolution.depth_step = 0.005;
    alone.resolution.probe_grading = None;
    alone
}

/// Every reference above, and every mesh of the sequences it was chosen
/// by, has the in-plane refinement of 1: grading adds node lines near the
/// faces, the needle line, the mid-plane and the top face, but the
/// elements elsewhere in the plane stay a marker spacing wide. This test
/// halves them: the campaign's last insertion (the worst of the paper
/// default's) on refinement 2, graded one level less towards the faces
/// and the needle line so that its finest elements there are the fine
/// paper default's, against the reference slab at refinement 1. Asserts
/// the two within a tenth of the marker noise, which would make the
/// reference's in-plane error negligible; prints the fine paper default's
/// distance from both.
#[test]
#[ignore = "minutes: the reference against a slab of half its in-plane size"]
fn the_reference_is_converged_in_the_plane() {
    let fine = Scenario::paper_default_fine();
    let sigma = fine.sensors.marker_sigma;
    let alone = campaign_insertion_alone(&fine, fine.needles.plan().len() - 1);
    let insertion = |refinement: usize, placement: SlabGrading, markers: Option<SlabGrading>| {
        let mut s = alone.clone();
        s.resolution.refinement = refinement;
        s.resolution.slab_grading = Some(placement);
        s.resolution.marker_grading = markers;
        respond(&s).unwrap().remove(0).markers
    };
    let reference = insertion(1, NEEDLE_REFERENCE, None);
    let fine_default = insertion(
        1,
        fine.resolution.slab_grading.unwrap(),
        Some(TENSOR_MARKER_SLAB),
    );
    let halved_marker_slab = SlabGrading {
        faces: 4,
        needle_lines: 2,
        mid_plane: 2,
        top_face: 2,
        probe_edges: 0,
        local: None,
    };
    let halved_placement = SlabGrading {
        faces: 2,
        needle_lines: 1,
        ..SlabGrading::DEFAULT
    };
    let halved = insertion(2, halved_placement, Some(halved_marker_slab));
    for (name, a, b) in [
        (
            "the fine paper default against the reference",
            &fine_default,
            &reference,
        ),
        (
            "the fine paper default against refinement 2",
            &fine_default,
            &halved,
        ),
        ("refinement 2 against the reference", &halved, &reference),
    ] {
        let (gap, state, marker) = worst_marker(a, b);
        println!(
            "{name}: {:.2} um ({:.3} sigma), state {state}, marker {marker}",
            gap * 1e6,
            gap / sigma
        );
    }
    let (gap, _, _) = worst_marker(&halved, &reference);
    assert!(
        gap < 0.1 * sigma,
        "the reference {gap} m from the slab of half its in-plane size, sigma {sigma} m"
    );
}

/// The in-plane element size alone, halved twice: the campaign's last
/// insertion on refinements 1, 2 and 4 (elements 3.75, 1.875 and
/// 0.9375 mm wide away from the graded lines), each placed on a coarser
/// slab and settled on its marker slab, graded so that the finest
/// elements towards the faces and the needle line are the fine paper
/// default's at every level (one level less per halving), with one level
/// towards the mid-plane and the top face (the fine paper default has
/// two; at two the finest plan would need a factor of some 34 GB, at one
/// it needs 11). Prints the largest differences over the markers and
/// states, the observed order and the extrapolated in-plane error of each
/// level, and, beyond 15 mm of the needle's line, the differences as
/// they are and once each state's markers are scaled by the ratio of the
/// two base forces (what differs only in the total load); asserts the
/// extrapolated in-plane error of refinement 1, the fine paper default's,
/// below a tenth of the marker noise.
#[test]
#[ignore = "about five minutes: the last insertion on three plans, the finest of 800,000 unknowns and 21 GB"]
fn the_in_plane_error_of_the_tensor_marker_slab_is_below_a_tenth_of_the_marker_noise() {
    let fine = Scenario::paper_default_fine();
    let sigma = fine.sensors.marker_sigma;
    let alone = campaign_insertion_alone(&fine, fine.needles.plan().len() - 1);
    let marker_slab = TENSOR_MARKER_SLAB;
    let placement = fine.resolution.slab_grading.unwrap();
    // (refinement, grading levels fewer than the fine paper default's)
    let levels = [(1, 0), (2, 1), (4, 2)];
    let (columns, _) = fine.phantom.markers;
    let spacing = fine.phantom.width / (columns - 1) as f64;
    let sizes = levels.map(|(refinement, _)| spacing * 1e3 / refinement as f64);
    let trials: Vec<TrialResponse> = levels
        .iter()
        .map(|&(refinement, fewer)| {
            let mut s = alone.clone();
            s.resolution.refinement = refinement;
            s.resolution.slab_grading = Some(SlabGrading {
                faces: placement.faces - fewer,
                needle_lines: placement.needle_lines - fewer,
                ..placement
            });
            s.resolution.marker_grading = Some(SlabGrading {
                faces: marker_slab.faces - fewer,
                needle_lines: marker_slab.needle_lines - fewer,
                mid_plane: 1,
                top_face: 1,
                probe_edges: 0,
                local: None,
            });
            respond(&s).unwrap().remove(0)
        })
        .collect();
    // Markers more than 15 mm (four marker spacings) from the needle's
    // line, where the field is smooth.
    let line = fine.needles.plan().last().unwrap().line;
    let far: Vec<bool> = (0..trials[0].markers[0].len())
        .map(|m| ((m % columns) as f64 * spacing - line).abs() > 0.015)
        .collect();
    let compare = |i: usize, j: usize| {
        let (a, b) = (&trials[i], &trials[j]);
        let (gap, state, marker) = worst_marker(&a.markers, &b.markers);
        let scaled: Vec<Vec<[f64; 2]>> = a
            .markers
            .iter()
            .zip(a.force.iter().zip(&b.force))
            .map(|(state, (fa, fb))| {
                let ratio = if *fa > 0.0 { fb / fa } else { 1.0 };
                state.iter().map(|p| [p[0] * ratio, p[1] * ratio]).collect()
            })
            .collect();
        let far_only = |states: &[Vec<[f64; 2]>]| -> Vec<Vec<[f64; 2]>> {
            states
                .iter()
                .map(|state| {
                    state
                        .iter()
                        .enumerate()
                        .filter(|(m, _)| far[*m])
                        .map(|(_, p)| *p)
                        .collect()
                })
                .collect()
        };
        let (far_gap, _) = largest_over_states(&far_only(&a.markers), &far_only(&b.markers));
        let (far_scaled_gap, _) = largest_over_states(&far_only(&scaled), &far_only(&b.markers));
        let force_gap = largest_relative_difference(&a.force, &b.force);
        println!(
            "| {} | {} | {:.2} ({:.3} sigma) | state {state}, marker {marker} | {:.2} | {:.2} | {:.1e} |",
            levels[i].0,
            levels[j].0,
            gap * 1e6,
            gap / sigma,
            far_gap * 1e6,
            far_scaled_gap * 1e6,
            force_gap,
        );
        gap
    };
    println!(
        "| refinement | against | largest (um) | where | beyond 15 mm of the needle (um) | there, scaled by the force ratio (um) | largest relative force difference |"
    );
    let (d01, d12) = (compare(0, 1), compare(1, 2));
    compare(0, 2);
    let error = extrapolate_in_plane(sizes, levels.map(|(r, _)| r), d01, d12, sigma);
    assert!(
        error < 0.1 * sigma,
        "the in-plane error of refinement 1 is {error} m, sigma {sigma} m"
    );
}

/// The observed order from the largest differences `d01` and `d12` of
/// three plans of in-plane element sizes `sizes` (mm) at `refinements`,
/// printed with each plan's extrapolated error ($C h^p$, $C$ from the
/// last pair); returns the coarsest plan's (m).
fn extrapolate_in_plane(
    sizes: [f64; 3],
    refinements: [usize; 3],
    d01: f64,
    d12: f64,
    sigma: f64,
) -> f64 {
    let p = observed_order(sizes, d01, d12);
    let c = d12 / (sizes[1].powf(p) - sizes[2].powf(p));
    println!("observed order {p:.2}");
    for (h, refinement) in sizes.iter().zip(refinements) {
        let error = c * h.powf(p);
        println!(
            "refinement {refinement} (elements {h:.4} mm): extrapolated in-plane error {:.2} um ({:.3} sigma)",
            error * 1e6,
            error / sigma
        );
    }
    c * sizes[0].powf(p)
}

/// A marker difference `gap` at `state` as the tables print it: in um
/// and in units of `sigma`, and the state, column and row.
fn located(gap: f64, sigma: f64, state: usize, marker: usize, columns: usize) -> String {
    format!(
        "{:.2} um ({:.3} sigma) | {state}, {}, {}",
        gap * 1e6,
        gap / sigma,
        marker % columns,
        marker / columns
    )
}

/// The fine paper default's insertion `k`, placed and settled as the
/// preset does, with `layers` layers and its slab along the material
/// path refined as `local` says.
fn settled_locally(k: usize, local: LocalRefinement, layers: usize) -> TrialResponse {
    let fine = Scenario::paper_default_fine();
    let mut s = campaign_insertion_alone(&fine, k);
    s.resolution.layers = layers;
    s.resolution.marker_grading = Some(SlabGrading {
        local: Some(local),
        ..fine.resolution.marker_grading.unwrap()
    });
    respond(&s).unwrap().remove(0)
}

/// Asserts the fine paper default's last insertion, settled as the
/// preset does, within a tenth of the marker noise at every marker of
/// every state of the same insertion settled on each of the `finer`
/// (name, local refinement, layers), and prints the table.
fn last_insertion_within_a_tenth_of_the_noise_of(finer: &[(&str, LocalRefinement, usize)]) {
    let fine = Scenario::paper_default_fine();
    let sigma = fine.sensors.marker_sigma;
    let base = fine.resolution.marker_grading.unwrap().local.unwrap();
    let (columns, _) = fine.phantom.markers;
    let last = fine.needles.plan().len() - 1;
    let reference = settled_locally(last, base, fine.resolution.layers);
    println!(
        "| refined | largest marker difference | where (state, column, row) | force, relative |"
    );
    let mut worst: f64 = 0.0;
    for &(name, local, layers) in finer {
        let trial = settled_locally(last, local, layers);
        let (gap, state, marker) = worst_marker(&reference.markers, &trial.markers);
        let force = largest_relative_difference(&reference.force, &trial.force);
        println!(
            "| {name} | {} | {force:.1e} |",
            located(gap, sigma, state, marker, columns)
        );
        worst = worst.max(gap);
    }
    assert!(
        worst < 0.1 * sigma,
        "a finer slab moves the markers by {worst} m, sigma {sigma} m"
    );
}

#[test]
#[ignore = "about twelve minutes and 20 GB: the last insertion on seven locally refined slabs"]
fn a_locally_refined_slab_is_within_a_tenth_of_the_marker_noise_of_each_finer_one() {
    let fine = Scenario::paper_default_fine();
    let base = fine.resolution.marker_grading.unwrap().local.unwrap();
    let layers = fine.resolution.layers;
    let finer = [
        (
            "path: one level more",
            LocalRefinement {
                needle_paths: base.needle_paths + 1,
                ..base
            },
            layers,
        ),
        (
            "entry and tip: two levels more",
            LocalRefinement {
                needle_ends: base.needle_ends + 2,
                ..base
            },
            layers,
        ),
        (
            "back face: one level more",
            LocalRefinement {
                back_face: base.back_face + 1,
                ..base
            },
            layers,
        ),
        (
            "far field: one level more",
            LocalRefinement {
                far_field: base.far_field + 1,
                ..base
            },
            layers,
        ),
        (
            "grading 0.5",
            LocalRefinement {
                grading: 0.5,
                ..base
            },
            layers,
        ),
        ("six layers", base, 6),
    ];
    last_insertion_within_a_tenth_of_the_noise_of(&finer);
}

/// The fine paper default's last insertion, settled as the preset does,
/// against two slabs refined several ways at once in the plan: the far
/// field one level more with grading 0.5, and the path one level more,
/// the entry and tip two, the back face one with grading 0.5. The five
/// ways at once, or either with six layers, do not fit in this
/// machine's memory. Asserts both within a tenth of the marker noise at
/// every marker of every state.
#[test]
#[ignore = "about fifteen minutes and 22 GB: the last insertion on three locally refined slabs"]
fn a_locally_refined_slab_is_within_a_tenth_of_the_marker_noise_of_slabs_refined_several_ways_at_once()
 {
    let fine = Scenario::paper_default_fine();
    let base = fine.resolution.marker_grading.unwrap().local.unwrap();
    let layers = fine.resolution.layers;
    let finer = [
        (
            "far field one level more, grading 0.5",
            LocalRefinement {
                far_field: base.far_field + 1,
                grading: 0.5,
                ..base
            },
            layers,
        ),
        (
            "path one level more, entry and tip two, back face one, grading 0.5",
            LocalRefinement {
                needle_paths: base.needle_paths + 1,
                needle_ends: base.needle_ends + 2,
                back_face: base.back_face + 1,
                grading: 0.5,
                ..base
            },
            layers,
        ),
    ];
    last_insertion_within_a_tenth_of_the_noise_of(&finer);
}

/// Every insertion of the fine paper default's campaign (its line,
/// velocity, day and effects, alone), settled as the preset does and on
/// its slab with the far field one level finer, the largest of the
/// one-way differences of the test above. Asserts the two within a tenth
/// of the marker noise at every state of every insertion.
#[test]
#[ignore = "about forty minutes and 20 GB: ten insertions on two locally refined slabs each"]
fn every_insertion_of_the_fine_paper_default_is_within_a_tenth_of_the_marker_noise_of_a_finer_far_field()
 {
    let fine = Scenario::paper_default_fine();
    let sigma = fine.sensors.marker_sigma;
    let base = fine.resolution.marker_grading.unwrap().local.unwrap();
    let finer = LocalRefinement {
        far_field: base.far_field + 1,
        ..base
    };
    let layers = fine.resolution.layers;
    let (columns, _) = fine.phantom.markers;
    println!(
        "| insertion | line x (mm) | velocity (mm/s) | day | largest marker difference | where (state, column, row) |"
    );
    let mut worst: f64 = 0.0;
    for (k, plan) in fine.needles.plan().into_iter().enumerate() {
        let settled = settled_locally(k, base, layers);
        let refined = settled_locally(k, finer, layers);
        let (gap, state, marker) = worst_marker(&settled.markers, &refined.markers);
        println!(
            "| {} | {:.1} | {:.0} | {} | {} |",
            k + 1,
            plan.line * 1e3,
            plan.velocity * 1e3,
            plan.day,
            located(gap, sigma, state, marker, columns)
        );
        worst = worst.max(gap);
    }
    assert!(
        worst < 0.1 * sigma,
        "a finer far field moves the markers by {worst} m, sigma {sigma} m"
    );
}

/// The final markers and force of probe `k` of `base` pressed alone: on
/// a slab of its own graded as `own` (the insertions left out: that slab
/// has no needle lines), or, without, on `base`'s slab, its needle lines
/// kept and its insertions cut to 1 mm.
fn probe_alone(base: &Scenario, k: usize, own: Option<SlabGrading>) -> (Vec<[f64; 2]>, f64) {
    let mut s = base.clone();
    s.probes = vec![base.probes[k]];
    s.compression = None;
    s.needles.depth = 0.001;
    if own.is_some() {
        s.needles.velocities.clear();
        s.resolution.marker_grading = None;
    }
    s.resolution.probe_grading = own;
    let probe = respond(&s)
        .unwrap()
        .into_iter()
        .find(|t| t.kind == TrialKind::Probe)
        .unwrap();
    (
        probe.markers.last().unwrap().clone(),
        *probe.force.last().unwrap(),
    )
}

/// The slab the fine paper default pressed each probe on until session
/// 42: a tensor slab at in-plane refinement 1, graded four levels towards
/// the faces and sides, three towards the top face and eight towards the
/// probe's edges.
const TENSOR_PROBE_SLAB: SlabGrading = SlabGrading {
    faces: 4,
    needle_lines: 0,
    mid_plane: 0,
    top_face: 3,
    probe_edges: 8,
    local: None,
};

/// The paper default's four probes (x = 15, 30, 45 and 60 mm, 3 mm
/// deep), on the paper default's slab and on probe slabs of their own
/// graded as [`TENSOR_PROBE_SLAB`], against slabs graded once more
/// towards the faces, the top face and the probe's edges. Asserts the
/// tensor probe slabs within a tenth of the marker noise at every
/// marker; prints the paper default's too, over every marker and
/// beyond one phantom thickness of the contact (the markers the
/// diagnosis fits), there also at the same force (the diagnosis loads
/// its probe by the measured force), and the force.
#[test]
#[ignore = "minutes: the probes' own slabs against finer ones"]
fn the_tensor_probe_slab_is_within_a_tenth_of_the_marker_noise_of_a_finer_one() {
    let paper = Scenario::paper_default();
    let fine = Scenario::paper_default_fine();
    let sigma = paper.sensors.marker_sigma;
    let own = TENSOR_PROBE_SLAB;
    let reference = SlabGrading {
        faces: own.faces + 1,
        top_face: own.top_face + 1,
        probe_edges: own.probe_edges + 1,
        ..own
    };
    let (columns, rows) = paper.phantom.markers;
    let spacing = [
        paper.phantom.width / (columns - 1) as f64,
        paper.phantom.depth / (rows - 1) as f64,
    ];
    let mut worst_fine: f64 = 0.0;
    for k in 0..paper.probes.len() {
        let x = paper.probes[k].x;
        let (converged, force) = probe_alone(&paper, k, Some(reference));
        let far: Vec<usize> = (0..converged.len())
            .filter(|m| {
                let dx = (m % columns) as f64 * spacing[0] - x;
                let dy = (m / columns) as f64 * spacing[1];
                dx.hypot(dy) > paper.phantom.thickness
            })
            .collect();
        let pick = |markers: &[[f64; 2]]| far.iter().map(|&m| markers[m]).collect::<Vec<_>>();
        println!("probe at x = {:.0} mm, against {reference:?}:", x * 1e3);
        println!(
            "| slab | largest (um) | worst marker | rms (um) | beyond 7.5 mm (um) | the same at the same force (um) | force (mN) |"
        );
        println!("|---|---|---|---|---|---|---|");
        let slabs = [
            ("the paper default's", probe_alone(&paper, k, None)),
            ("the tensor probe slab", probe_alone(&fine, k, Some(own))),
        ];
        for (name, (markers, f)) in &slabs {
            let (largest, rms, column, row) = compare(markers, &converged, columns);
            let (far_largest, ..) = compare(&pick(markers), &pick(&converged), far.len());
            // A model loaded by the measured force (the diagnosis's) sees
            // the markers at the same force.
            let scaled: Vec<[f64; 2]> = pick(&converged)
                .iter()
                .map(|q| [q[0] * f / force, q[1] * f / force])
                .collect();
            let (same_force, ..) = compare(&pick(markers), &scaled, far.len());
            println!(
                "| {name} | {:.2} ({:.3} sigma) | column {column}, row {row} | {:.2} | {:.2} | {:.2} | {:+.2} of {:.1} |",
                largest * 1e6,
                largest / sigma,
                rms * 1e6,
                far_largest * 1e6,
                same_force * 1e6,
                (f - force) * 1e3,
                force * 1e3
            );
        }
        worst_fine = worst_fine.max(compare(&slabs[1].1.0, &converged, columns).0);
    }
    assert!(
        worst_fine < 0.1 * sigma,
        "the tensor probe slab {worst_fine} m from the reference, sigma {sigma} m"
    );
}

/// The tensor probe slab's reference, like the needle trials', is at
/// in-plane refinement 1. This test refines the in-plane size alone for
/// the first probe (x = 15 mm; the probes' own slabs differ only in where
/// they lie): its [`TENSOR_PROBE_SLAB`] at refinements 1, 2 and 3, with
/// the same node planes through the thickness, graded one level less towards the
/// faces, sides and probe edges at refinement 2 so that the finest
/// elements there are the fine paper default's, and at refinement 3 as
/// many levels as make them no larger (0.156 and 0.0098 mm against 0.234
/// and 0.0146; at refinement 4 the run needed more than this machine's
/// 23 GB). Prints the largest differences and those at the same force,
/// the observed order and the extrapolated in-plane errors; asserts that
/// of refinement 1 below a tenth of the marker noise.
#[test]
#[ignore = "minutes: one probe on three plans"]
fn the_in_plane_error_of_the_tensor_probe_slab_is_below_a_tenth_of_the_marker_noise() {
    let fine = Scenario::paper_default_fine();
    let sigma = fine.sensors.marker_sigma;
    let columns = fine.phantom.markers.0;
    let own = TENSOR_PROBE_SLAB;
    // (refinement, levels towards the faces and sides, towards the edges)
    let levels = [
        (1, own.faces, own.probe_edges),
        (2, own.faces - 1, own.probe_edges - 1),
        (3, own.faces - 1, own.probe_edges - 1),
    ];
    let spacing = fine.phantom.width / (columns - 1) as f64;
    let sizes = levels.map(|(refinement, ..)| spacing * 1e3 / refinement as f64);
    let solved: Vec<(Vec<[f64; 2]>, f64)> = levels
        .iter()
        .map(|&(refinement, faces, probe_edges)| {
            let mut s = fine.clone();
            s.resolution.refinement = refinement;
            let grading = SlabGrading {
                faces,
                probe_edges,
                ..own
            };
            probe_alone(&s, 0, Some(grading))
        })
        .collect();
    println!(
        "| refinement | against | largest (um) | worst marker (column, row) | rms (um) | largest at the same force (um) | force difference (mN) |"
    );
    let differences: Vec<f64> = [(0, 1), (1, 2), (0, 2)]
        .iter()
        .map(|&(i, j)| {
            let ((a, fa), (b, fb)) = (&solved[i], &solved[j]);
            let (largest, rms, column, row) = compare(a, b, columns);
            let scaled: Vec<[f64; 2]> = a.iter().map(|p| [p[0] * fb / fa, p[1] * fb / fa]).collect();
            let (same_force, ..) = compare(&scaled, b, columns);
            println!(
                "| {} | {} | {:.2} ({:.3} sigma) | {column}, {row} | {:.2} | {:.2} | {:+.3} of {:.1} |",
                levels[i].0,
                levels[j].0,
                largest * 1e6,
                largest / sigma,
                rms * 1e6,
                same_force * 1e6,
                (fa - fb) * 1e3,
                fb * 1e3
            );
            largest
        })
        .collect();
    let error = extrapolate_in_plane(
        sizes,
        levels.map(|(r, ..)| r),
        differences[0],
        differences[1],
        sigma,
    );
    assert!(
        error < 0.1 * sigma,
        "the in-plane error of the probe's plan at refinement 1 is {error} m, sigma {sigma} m"
    );
}

/// The largest marker difference of a probe's final `markers` and force
/// from the `reference`'s, and the table cells saying it: the gap, its
/// worst marker and the force difference.
fn probe_row(
    (reference, force): (&[[f64; 2]], f64),
    (markers, f): (&[[f64; 2]], f64),
    columns: usize,
    sigma: f64,
) -> (f64, String) {
    let (gap, _, column, row) = compare(reference, markers, columns);
    let cells = format!(
        "{:.2} ({:.3} sigma) | {column}, {row} | {:+.3} of {:.1}",
        gap * 1e6,
        gap / sigma,
        (force - f) * 1e3,
        f * 1e3
    );
    (gap, cells)
}

/// The fine paper default, its probe slab and that slab's local refinement.
fn fine_probe_slab() -> (Scenario, SlabGrading, LocalRefinement) {
    let fine = Scenario::paper_default_fine();
    let own = fine
        .resolution
        .probe_grading
        .expect("the fine one has them");
    let base = own.local.expect("refined locally");
    (fine, own, base)
}

/// Asserts probe `probe` of `fine`, pressed on its own slab as the preset
/// does, within a tenth of the marker noise of each of the `finer` (name,
/// scenario, probe slab) at every marker, and prints the table. Returns
/// the largest difference (m).
fn probe_within_a_tenth_of_the_noise_of(
    fine: &Scenario,
    probe: usize,
    finer: &[(&str, &Scenario, SlabGrading)],
) -> f64 {
    let sigma = fine.sensors.marker_sigma;
    let columns = fine.phantom.markers.0;
    let own = fine.resolution.probe_grading;
    let (reference, force) = probe_alone(fine, probe, own);
    println!("probe {probe} (x = {:.0} mm):", fine.probes[probe].x * 1e3);
    println!(
        "| refined | largest marker difference (um) | worst marker (column, row) | force (mN) |"
    );
    println!("|---|---|---|---|");
    let mut worst: f64 = 0.0;
    for &(name, scenario, grading) in finer {
        let (markers, f) = probe_alone(scenario, probe, Some(grading));
        let (gap, row) = probe_row((&reference, force), (&markers, f), columns, sigma);
        println!("| {name} | {row} |");
        worst = worst.max(gap);
    }
    assert!(
        worst < 0.1 * sigma,
        "a finer probe slab moves probe {probe}'s markers by {worst} m, sigma {sigma} m"
    );
    worst
}

/// The first probe (x = 15 mm, nearest a side) of the fine paper default,
/// pressed on its own slab as the preset does and on six slabs each
/// refined one way more: the edges, the back face, the far field, the
/// grading, the node planes towards the top face and the layers. Asserts
/// each within a tenth of the marker noise at every marker.
#[test]
#[ignore = "about ten minutes and 20 GB: one probe on seven slabs refined in the plan"]
fn the_fine_paper_default_s_probe_slab_is_within_a_tenth_of_the_marker_noise_of_each_finer_one() {
    let (fine, own, base) = fine_probe_slab();
    let with = |local: LocalRefinement| SlabGrading {
        local: Some(local),
        ..own
    };
    let mut six_layers = fine.clone();
    six_layers.resolution.layers = 6;
    let finer = [
        (
            "edges: one level more",
            &fine,
            with(LocalRefinement {
                probe_edges: base.probe_edges + 1,
                ..base
            }),
        ),
        (
            "back face: one level more",
            &fine,
            with(LocalRefinement {
                back_face: base.back_face + 1,
                ..base
            }),
        ),
        (
            "far field: one level more",
            &fine,
            with(LocalRefinement {
                far_field: base.far_field + 1,
                ..base
            }),
        ),
        (
            "grading 0.25",
            &fine,
            with(LocalRefinement {
                grading: 0.25,
                ..base
            }),
        ),
        (
            "top face: one level more",
            &fine,
            SlabGrading {
                top_face: own.top_face + 1,
                ..own
            },
        ),
        ("six layers", &six_layers, own),
    ];
    probe_within_a_tenth_of_the_noise_of(&fine, 0, &finer);
}

/// The fine paper default's two slabs refined several ways at once: in
/// the plan (the edges, the back face and the far field one level more,
/// grading 0.25) and through the thickness (the node planes one level
/// more towards the top face, six layers). The six ways all at once do
/// not fit in this machine's memory.
fn refined_several_ways_at_once() -> [(&'static str, Scenario, SlabGrading); 2] {
    let (fine, own, base) = fine_probe_slab();
    let in_plan = SlabGrading {
        local: Some(LocalRefinement {
            probe_edges: base.probe_edges + 1,
            back_face: base.back_face + 1,
            far_field: base.far_field + 1,
            grading: 0.25,
            ..base
        }),
        ..own
    };
    let mut six_layers = fine.clone();
    six_layers.resolution.layers = 6;
    let through_thickness = SlabGrading {
        top_face: own.top_face + 1,
        ..own
    };
    [
        (
            "edges, back face and far field one level more, grading 0.25",
            fine,
            in_plan,
        ),
        (
            "top face one level more, six layers",
            six_layers,
            through_thickness,
        ),
    ]
}

/// Asserts the fine paper default's `probes`, each pressed on its own
/// slab as the preset does, within a tenth of the marker noise of the two
/// slabs refined several ways at once (`refined_several_ways_at_once`),
/// and prints their tables and the largest difference.
fn probes_within_a_tenth_of_the_noise_of_slabs_refined_several_ways_at_once(
    probes: std::ops::Range<usize>,
) {
    let (fine, ..) = fine_probe_slab();
    let slabs = refined_several_ways_at_once();
    let finer: Vec<_> = slabs.iter().map(|(name, s, g)| (*name, s, *g)).collect();
    let worst = probes
        .map(|probe| probe_within_a_tenth_of_the_noise_of(&fine, probe, &finer))
        .fold(0.0, f64::max);
    println!("largest: {:.2} um", worst * 1e6);
}

/// The first probe (x = 15 mm) of the fine paper default against the two
/// slabs refined several ways at once.
#[test]
#[ignore = "about six minutes and 21 GB: one probe on three slabs refined in the plan"]
fn the_fine_paper_default_s_probe_slab_is_within_a_tenth_of_the_marker_noise_of_slabs_refined_several_ways_at_once()
 {
    probes_within_a_tenth_of_the_noise_of_slabs_refined_several_ways_at_once(0..1);
}

/// The other three probes of the fine paper default (x = 30, 45 and
/// 60 mm) against the same two slabs, as the first probe is above.
#[test]
#[ignore = "about twenty minutes and 21 GB: three probes on three slabs each"]
fn the_other_probes_of_the_fine_paper_default_are_within_a_tenth_of_the_marker_noise_of_slabs_refined_several_ways_at_once()
 {
    probes_within_a_tenth_of_the_noise_of_slabs_refined_several_ways_at_once(1..4);
}

/// Each of the fine paper default's four probes, pressed on its own slab
/// as the preset does, against the two finer slabs that moved the first
/// probe most in the test above: the far field one level finer and
/// grading 0.25. Asserts every probe within a tenth of the marker noise
/// of both.
#[test]
#[ignore = "about eighteen minutes and 20 GB: four probes on three slabs each"]
fn every_probe_of_the_fine_paper_default_is_within_a_tenth_of_the_marker_noise_of_a_finer_far_field_and_grading()
 {
    let (fine, own, base) = fine_probe_slab();
    let sigma = fine.sensors.marker_sigma;
    let columns = fine.phantom.markers.0;
    let finer = [
        (
            "far field: one level more",
            LocalRefinement {
                far_field: base.far_field + 1,
                ..base
            },
        ),
        (
            "grading 0.25",
            LocalRefinement {
                grading: 0.25,
                ..base
            },
        ),
    ];
    println!(
        "| probe | refined | largest marker difference (um) | worst marker (column, row) | force (mN) |"
    );
    println!("|---|---|---|---|---|");
    let mut worst: f64 = 0.0;
    for (k, probe) in fine.probes.iter().enumerate() {
        let (reference, force) = probe_alone(&fine, k, Some(own));
        for (name, local) in finer {
            let grading = SlabGrading {
                local: Some(local),
                ..own
            };
            let (markers, f) = probe_alone(&fine, k, Some(grading));
            let (gap, row) = probe_row((&reference, force), (&markers, f), columns, sigma);
            println!("| x = {:.0} mm | {name} | {row} |", probe.x * 1e3);
            worst = worst.max(gap);
        }
    }
    assert!(
        worst < 0.1 * sigma,
        "a finer probe slab moves the markers by {worst} m, sigma {sigma} m"
    );
}

/// Largest error over every marker and every odd state of `fine` (states
/// at half the step) when read from the even states only: by the straight
/// line between the two neighbours, and by the truth's own interpolation
/// (`needle_synth::interpolate`). Markers (m), as vector lengths, and
/// force (N); the worst state of the truth's interpolation.
struct InterpolationErrors {
    linear: f64,
    truth: f64,
    worst_state: usize,
    force_linear: f64,
    force_truth: f64,
}

fn interpolation_errors(fine: &TrialResponse) -> InterpolationErrors {
    let grid: Vec<f64> = fine.states.iter().step_by(2).copied().collect();
    let coarse: Vec<&Vec<[f64; 2]>> = fine.markers.iter().step_by(2).collect();
    let force: Vec<f64> = fine.force.iter().step_by(2).copied().collect();
    assert_eq!(fine.states.len() % 2, 1, "an even number of fine steps");
    let mut e = InterpolationErrors {
        linear: 0.0,
        truth: 0.0,
        worst_state: 0,
        force_linear: 0.0,
        force_truth: 0.0,
    };
    for k in (1..fine.states.len()).step_by(2) {
        let s = stencil(&grid, fine.states[k]);
        let (a, b) = (&fine.markers[k - 1], &fine.markers[k + 1]);
        for (m, exact) in fine.markers[k].iter().enumerate() {
            let line = [0.5 * (a[m][0] + b[m][0]), 0.5 * (a[m][1] + b[m][1])];
            let mut read = [0.0; 2];
            for (j, w) in s.terms() {
                read[0] += w * coarse[j][m][0];
                read[1] += w * coarse[j][m][1];
            }
            e.linear = e.linear.max((line[0] - exact[0]).hypot(line[1] - exact[1]));
            let error = (read[0] - exact[0]).hypot(read[1] - exact[1]);
            if error > e.truth {
                e.truth = error;
                e.worst_state = k;
            }
        }
        let line = 0.5 * (fine.force[k - 1] + fine.force[k + 1]);
        e.force_linear = e.force_linear.max((line - fine.force[k]).abs());
        e.force_truth = e.force_truth.max((s.apply(&force) - fine.force[k]).abs());
    }
    e
}

#[test]
#[ignore = "seconds: interpolation between solved needle states"]
fn interpolation_between_states_is_below_a_tenth_of_the_marker_noise() {
    let default = Scenario::paper_default();
    let sigma = default.sensors.marker_sigma;
    let force_sigma = stated_force_sigma(&default.sensors);
    let step = default.resolution.depth_step;
    // The 3-D null slab at 1 mm/s; the paper default's slab (with its tip
    // peak) at 9 mm/s, its largest shaft load; the plane-strain null truth.
    let mut paper = default.clone();
    paper.probes.clear();
    paper.needles.velocities = vec![0.009];
    paper.needles.days = vec![2.0];
    paper.frames = None;
    let mut cases = vec![
        (
            "3-D null slab, 1 mm/s",
            slab(
                default.resolution.refinement,
                default.resolution.layers,
                step,
            ),
        ),
        ("3-D paper default, 9 mm/s", paper),
        ("plane null truth, 1 mm/s", plane(1)),
        (
            "plane tip peak alone, 1 mm/s",
            fixture("tip-cutting-force.ron"),
        ),
    ];
    println!(
        "states every {step} m, read at the midpoints from states 2 x {} m apart",
        step / 2.0
    );
    println!(
        "| truth | linear (um) | cubic (um) | cubic / sigma | worst state (mm) | force linear / cubic (mN) |"
    );
    println!("|---|---|---|---|---|---|");
    let mut largest = 0.0f64;
    for (name, s) in &mut cases {
        s.probes.clear();
        s.resolution.depth_step = step / 2.0;
        let fine = respond(s).unwrap();
        let e = interpolation_errors(&fine[0]);
        println!(
            "| {name} | {:.3} | {:.3} | {:.4} | {:.1} | {:.3} / {:.4} |",
            e.linear * 1e6,
            e.truth * 1e6,
            e.truth / sigma,
            fine[0].states[e.worst_state] * 1e3,
            e.force_linear * 1e3,
            e.force_truth * 1e3,
        );
        assert!(
            e.force_truth < 0.1 * force_sigma,
            "{name}: force {}",
            e.force_truth
        );
        largest = largest.max(e.truth);
    }
    assert!(largest < 0.1 * sigma, "interpolation error {largest} m");
}

/// One 1 mm/s insertion of a fixture scenario, without its probes.
fn fixture(name: &str) -> Scenario {
    let path = format!(
        "{}/../../fixtures/scenarios/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    let mut s = load_scenario(&path).unwrap();
    s.probes.clear();
    s.needles.velocities = vec![0.001];
    s.needles.days = vec![2.0];
    s
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

/// The largest of $|a_i - b_i| / b_i$ over two force histories.
fn largest_relative_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(fa, fb)| (fa - fb).abs() / fb.max(f64::MIN_POSITIVE))
        .fold(0.0, f64::max)
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

/// The first probe of `fixtures/scenarios/material-nonlinearity.ron` (a
/// 4 mm wide rigid punch pressed 4 mm into the neo-Hookean phantom)
/// alone, at in-plane `refinement` with `levels` of plane grading.
fn neo_hookean_probe(refinement: usize, levels: usize) -> Scenario {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/scenarios/material-nonlinearity.ron"
    );
    let mut s = load_scenario(path).unwrap();
    s.probes.truncate(1);
    s.needles.velocities.clear();
    s.resolution.refinement = refinement;
    s.resolution.plane_grading = Some(levels);
    s
}

/// The neo-Hookean truth's mesh: the fixture's (refinement 6, its 3
/// levels of grading) against the finest that solves the probe
/// (refinement 12, 2 levels: the elements at the punch's corners the same
/// size, every other halved; finer corner elements are crushed,
/// `grid::NEO_HOOKEAN_GRADING_LEVELS`). Besides the requirement over every
/// marker, it prints the markers beyond one phantom thickness of the
/// contact, the ones the diagnosis fits (`probe_near_field`), since the
/// corners of a rigid flat punch make the strain singular next to them,
/// and those markers compared at the same probe force, since the corners
/// also set the force at which the punch reaches its depth.
#[test]
#[ignore = "minutes: mesh convergence of the neo-Hookean plane truth"]
fn neo_hookean_truth_discretisation_error_is_below_a_tenth_of_the_marker_noise() {
    let fixture = neo_hookean_probe(6, 3);
    let sigma = fixture.sensors.marker_sigma;
    let (columns, rows) = fixture.phantom.markers;
    let spacing = [
        fixture.phantom.width / (columns - 1) as f64,
        fixture.phantom.depth / (rows - 1) as f64,
    ];
    let contact = [fixture.probes[0].x, 0.0];
    let near_field = fixture.phantom.thickness;
    let coarse = respond(&fixture).unwrap();
    let fine = respond(&neo_hookean_probe(12, 2)).unwrap();
    let (a, b) = (&coarse[0], &fine[0]);
    assert_eq!(a.id, b.id);
    let (a_last, b_last) = (a.markers.last().unwrap(), b.markers.last().unwrap());
    let (largest, rms, column, row) = compare(a_last, b_last, columns);
    let far: Vec<usize> = (0..a_last.len())
        .filter(|k| {
            let x = (k % columns) as f64 * spacing[0] - contact[0];
            let y = (k / columns) as f64 * spacing[1] - contact[1];
            x.hypot(y) > near_field
        })
        .collect();
    let pick = |m: &[[f64; 2]]| far.iter().map(|&k| m[k]).collect::<Vec<_>>();
    let (far_a, far_b) = (pick(a_last), pick(b_last));
    let (far_largest, far_rms, far_worst, _) = compare(&far_a, &far_b, far.len());
    let far_worst = far[far_worst];
    let force = (a.force.last().unwrap() - b.force.last().unwrap()).abs();
    // Beyond the near field the strain is small and the displacement
    // nearly proportional to the probe's force. The truth presses the
    // probe to a depth and the two meshes' forces differ; a model loaded
    // by the measured force (the diagnosis's) compares the markers at the
    // same force.
    let amplitude = a.force.last().unwrap() / b.force.last().unwrap();
    let scaled: Vec<[f64; 2]> = far_b
        .iter()
        .map(|q| [amplitude * q[0], amplitude * q[1]])
        .collect();
    let (scaled_largest, scaled_rms, _, _) = compare(&far_a, &scaled, far.len());
    println!(
        "probe {} at {:.1} mm deep, refinement 6 (3 levels) against 12 (2 levels), um:",
        a.id,
        a.states.last().unwrap() * 1e3
    );
    println!(
        "every marker: {:.2} / {:.2} (largest / rms), worst column {column} row {row}",
        largest * 1e6,
        rms * 1e6
    );
    println!(
        "{} markers beyond {:.1} mm of the contact: {:.2} / {:.2}, worst column {} row {}",
        far.len(),
        near_field * 1e3,
        far_largest * 1e6,
        far_rms * 1e6,
        far_worst % columns,
        far_worst / columns
    );
    println!(
        "base force: {:.3} mN of {:.1} mN (ratio {:.5}); the far markers at the same \
         force: {:.2} / {:.2}",
        force * 1e3,
        b.force.last().unwrap().abs() * 1e3,
        amplitude,
        scaled_largest * 1e6,
        scaled_rms * 1e6
    );
    assert!(
        largest < 0.1 * sigma,
        "neo-Hookean truth: {largest} m between meshes against sigma {sigma} m"
    );
}

/// The fixture's first probe with its edges rounded to 0.5 mm (4 mm
/// wide) and pressed 1 mm in 0.125 mm steps, in frictionless contact
/// (`ProbeTrial::edge_radius`), on refinement 6 and 12 with 3 levels of
/// grading each: every element halved, the grading at the probe's edges
/// and over its footprint included. Under a frictionless probe the face
/// slides sideways (0.54 mm at 1 mm deep for this probe), so where the
/// contact ends moves across the footprint as the probe goes in.
#[test]
#[ignore = "40 minutes: mesh convergence of the rounded probe in contact"]
fn rounded_probe_truth_discretisation_error_is_below_a_tenth_of_the_marker_noise() {
    let rounded = |refinement| {
        let mut s = neo_hookean_probe(refinement, 3);
        s.compression = None;
        s.probes[0].edge_radius = Some(0.0005);
        s.probes[0].indentation = 0.001;
        s.resolution.indentation_step = 0.000125;
        s
    };
    let coarse = rounded(6);
    let sigma = coarse.sensors.marker_sigma;
    let columns = coarse.phantom.markers.0;
    let a = &respond(&coarse).unwrap()[0];
    let b = &respond(&rounded(12)).unwrap()[0];
    let (largest, rms, column, row) = compare(
        a.markers.last().unwrap(),
        b.markers.last().unwrap(),
        columns,
    );
    println!(
        "rounded probe 1 mm deep, refinement 6 against 12 (3 levels each), um: {:.2} / {:.2} \
         (largest / rms), worst column {column} row {row}; force {:.3} against {:.3} mN",
        largest * 1e6,
        rms * 1e6,
        a.force.last().unwrap() * 1e3,
        b.force.last().unwrap() * 1e3
    );
    assert!(
        largest < 0.1 * sigma,
        "rounded probe: {largest} m between meshes against sigma {sigma} m"
    );
}
