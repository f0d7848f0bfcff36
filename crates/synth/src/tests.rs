//! Unit tests of the truth physics on small meshes (they need the crate's
//! internals: reactions, material points, tangents).

use crate::effect::MaterialStiffening;
use crate::effect::material_nonlinearity::{NeoHookean, uniaxial_nominal_stress};
use crate::effect::{CompliantSupport, Effects, LayeredStiffness, OutOfPlane, TipCuttingForce};
use crate::line_response::{LineResponse, Missing};
use crate::needle::{
    Band, CONSISTENCY_TOLERANCE, ENTRY_DEPTH, NeedleRun, depth_grid, insert, insert_with,
};
use crate::probe::{Factorisation, press};
use crate::scenario::{NeedlePlan, Scenario};
use crate::slab_mesh::Span;
use crate::system::{Factorised, Stiffness};
use crate::world::World;
use crate::{LocalRefinement, SlabGrading, TrialResponse, respond};
use needle_data::TrialKind;
use needle_fem::material::Materials;

/// A small plane-strain null scenario: 6 x 6 markers, coarse mesh.
fn small() -> Scenario {
    let mut s = Scenario::quick();
    s.phantom.markers = (6, 6);
    s.resolution.refinement = 1;
    s.resolution.depth_step = 0.005;
    s.resolution.shaft_step = 0.002;
    s.effects = Effects::none();
    s.needles.depth = 0.03;
    s.needles.first_line = 0.03;
    s.needles.velocities = vec![0.003];
    s
}

/// The small scenario with the 2-D truth and with the 3-D slab truth.
fn plane_and_slab() -> [Scenario; 2] {
    [
        small(),
        Scenario {
            effects: Effects {
                out_of_plane: Some(OutOfPlane),
                ..Effects::none()
            },
            ..small()
        },
    ]
}

/// The small slab meshed locally (`local_mesh`): an octree refined
/// towards the needle's path and ends and the back face's edges.
fn local_slab() -> Scenario {
    let [_, mut s] = plane_and_slab();
    s.resolution.slab_grading = Some(SlabGrading {
        faces: 0,
        needle_lines: 0,
        mid_plane: 0,
        top_face: 0,
        probe_edges: 0,
        local: Some(LocalRefinement {
            refinement: None,
            needle_paths: 1,
            needle_ends: 2,
            back_face: 1,
            probe_edges: 1,
            far_field: 0,
            plan_only: false,
            grading: 1.0,
        }),
    });
    s
}

/// A locally refined slab's grid takes its own refinement when it states
/// one, and the scenario's otherwise; `far_field` halves every cell.
#[test]
fn a_locally_refined_slab_s_largest_cell_follows_its_refinement_and_far_field() {
    let s = local_slab();
    let with = |refinement: Option<usize>, far_field: usize| {
        let mut t = s.clone();
        let grading = t.resolution.slab_grading.as_mut().unwrap();
        let local = grading.local.as_mut().unwrap();
        local.refinement = refinement;
        local.far_field = far_field;
        World::new(&t).unwrap().body.element_size
    };
    let scenario_s = with(None, 0);
    let r = s.resolution.refinement;
    assert_eq!(with(Some(r), 0), scenario_s);
    for (refinement, far_field, ratio) in [
        (Some(2 * r), 0, 0.5),
        (None, 1, 0.5),
        (Some(2 * r), 1, 0.25),
    ] {
        let largest = with(refinement, far_field);
        assert!(
            (largest - ratio * scenario_s).abs() < 1e-12 * scenario_s,
            "{refinement:?}, {far_field}: {largest} against {scenario_s}"
        );
    }
}

/// The local slab refined in the plan alone (`plan_only`): a quadtree
/// extruded through the node planes.
fn plan_slab() -> Scenario {
    let mut s = local_slab();
    let grading = s.resolution.slab_grading.as_mut().unwrap();
    grading.local.as_mut().unwrap().plan_only = true;
    s
}

/// The small scenario on the plane, the tensor slab and the local slabs.
fn every_body() -> Vec<Scenario> {
    let mut all = plane_and_slab().to_vec();
    all.push(local_slab());
    all.push(plan_slab());
    all
}

fn plan(s: &Scenario) -> NeedlePlan {
    s.needles.plan()[0]
}

/// Sum of the y components of `r` over the nodes on the back face, of the
/// whole phantom.
fn back_reaction(world: &World, r: &[f64]) -> f64 {
    let depth = world.scenario.phantom.depth;
    world.body.copies()
        * world
            .body
            .nodes_where(|x| (x[1] - depth).abs() < 1e-12)
            .iter()
            .map(|&n| r[n * world.body.dim + 1])
            .sum::<f64>()
}

#[test]
fn needle_load_is_balanced_by_the_fixed_face() {
    for s in every_body() {
        let world = World::new(&s).unwrap();
        let response = world.response(0.0).unwrap();
        let run = insert(
            &world,
            &[(plan(&s), &response)],
            s.needles.depth,
            s.resolution.depth_step,
        )
        .unwrap();
        let u = &run[0].last_displacement;
        let r = response.internal_forces(&world.body, u);
        let applied: f64 = *run[0].force.last().unwrap();
        // Expected base force: density times the inserted length.
        let inserted = s.needles.depth - run[0].entry.last().unwrap();
        assert!(
            (applied - s.shaft.density * inserted).abs() < 1e-12,
            "{applied} vs {}",
            s.shaft.density * inserted
        );
        // K u = f: the reactions on the held face balance the shaft force.
        let reaction = back_reaction(&world, &r);
        assert!(
            (reaction + applied).abs() < 1e-9 * applied,
            "reaction {reaction} vs applied {applied}"
        );
        // Off the held face, K u equals the applied load: its y sum is the force.
        let total: f64 = (0..world.body.nodes.len())
            .map(|n| r[n * world.body.dim + 1])
            .sum();
        assert!(total.abs() < 1e-9 * applied, "net force {total}");
    }
}

#[test]
fn needle_tip_is_solved_consistently() {
    let s = small();
    let world = World::new(&s).unwrap();
    let response = world.response(0.0).unwrap();
    let run = &insert(
        &world,
        &[(plan(&s), &response)],
        s.needles.depth,
        s.resolution.depth_step,
    )
    .unwrap()[0];
    let x = run.tip_material;
    let at = world.body.locate(x).unwrap();
    let u = world.body.value(&at, &run.last_displacement);
    let spatial = [x[0] + u[0], x[1] + u[1]];
    assert!(
        (spatial[0] - plan(&s).line).abs() < 10.0 * CONSISTENCY_TOLERANCE,
        "{spatial:?}"
    );
    assert!(
        (spatial[1] - s.needles.depth).abs() < 10.0 * CONSISTENCY_TOLERANCE,
        "{spatial:?}"
    );
    // The tissue is dragged forwards: the material tip lies behind the
    // spatial tip by a displacement far above the tolerance.
    assert!(u[1] > 1e-4, "tip displacement {}", u[1]);
}

#[test]
fn probe_force_balances_the_fixed_face_and_scales_linearly() {
    let s = small();
    let world = World::new(&s).unwrap();
    let probe = s.probes[0];
    let run = press(&world, &probe, Factorisation::Shared).unwrap();
    let force = *run.force.last().unwrap();
    assert!(force > 0.0);
    let materials =
        Materials::from_parameters(&[(s.phantom.youngs_modulus, s.phantom.poisson_ratio)]).unwrap();
    let k = Stiffness::new(&world.body.stiffness(&materials).unwrap(), &[]).unwrap();
    let r = k.multiply(&run.last_displacement);
    assert!((back_reaction(&world, &r) + force).abs() < 1e-9 * force);
    // Halving the indentation halves the force.
    let half = press(
        &world,
        &crate::scenario::ProbeTrial {
            indentation: probe.indentation / 2.0,
            ..probe
        },
        Factorisation::Shared,
    )
    .unwrap();
    assert!((2.0 * half.force.last().unwrap() - force).abs() < 1e-9 * force);
}

/// The stiffness of `s`'s phantom at modulus `e`, factorised with the back
/// face and `extra` components held: the direct solve the shared
/// factorisation and the probe's Lagrange multipliers must reproduce.
fn direct(world: &World, e: f64, extra: &[usize]) -> (Stiffness, Factorised) {
    let materials =
        Materials::from_parameters(&[(e, world.scenario.phantom.poisson_ratio)]).unwrap();
    let k = Stiffness::new(&world.body.stiffness(&materials).unwrap(), &[]).unwrap();
    let mut held = world.fixed.clone();
    for &d in extra {
        held[d] = true;
    }
    let f = Factorised::new(&k, &held, "direct").unwrap();
    (k, f)
}

fn largest_gap(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// The barycentric coordinates of `p` in the straight simplex `e`.
fn barycentric(body: &crate::body::Body, e: usize, p: [f64; 3]) -> Vec<f64> {
    let corner = |k: usize| body.nodes[body.element(e)[k]];
    let mut jacobian = [[0.0; 3]; 3];
    for (k, row) in jacobian.iter_mut().enumerate() {
        row[k] = 1.0;
    }
    for col in 0..body.dim {
        for row in 0..body.dim {
            jacobian[row][col] = corner(col + 1)[row] - corner(0)[row];
        }
    }
    let inverse = crate::body::invert3(&jacobian);
    let d: Vec<f64> = (0..3).map(|c| p[c] - corner(0)[c]).collect();
    let xi: Vec<f64> = (0..body.dim)
        .map(|r| (0..body.dim).map(|c| inverse[r][c] * d[c]).sum())
        .collect();
    std::iter::once(1.0 - xi.iter().sum::<f64>())
        .chain(xi)
        .collect()
}

#[test]
fn every_point_of_the_body_is_located_in_an_element_that_holds_it() {
    for s in every_body() {
        let world = World::new(&s).unwrap();
        let body = &world.body;
        let (lo, hi) = body.bounds();
        // Every node (on the grid's lines, edges and corners, the hardest
        // case) and points spread through the box by a Weyl sequence.
        let mut points = body.nodes.clone();
        let steps = [0.618_033_988_7, 0.754_877_666_2, 0.569_840_290_9];
        points.extend((1..2000).map(|k| {
            std::array::from_fn(|c| {
                let t = (k as f64 * steps[c]).fract();
                lo[c] + t * (hi[c] - lo[c])
            })
        }));
        for p in points {
            let at = body
                .locate(p)
                .unwrap_or_else(|| panic!("{p:?} is in the body but was not located"));
            let worst = barycentric(body, at.element, p)
                .into_iter()
                .fold(f64::INFINITY, f64::min);
            assert!(worst >= -1e-9, "{p:?} lies outside element {}", at.element);
        }
        let beyond = 1e-6 * (hi[0] - lo[0]);
        for c in 0..body.dim {
            let mut p = [
                0.5 * (lo[0] + hi[0]),
                0.5 * (lo[1] + hi[1]),
                0.5 * (lo[2] + hi[2]),
            ];
            p[c] = hi[c] + beyond;
            assert!(body.locate(p).is_none(), "{p:?} lies outside the body");
            p[c] = lo[c] - beyond;
            assert!(body.locate(p).is_none(), "{p:?} lies outside the body");
        }
    }
}

#[test]
fn stiffened_day_shares_the_factorisation_and_scales_exactly() {
    let mut s = small();
    s.effects.material_stiffening = Some(MaterialStiffening { rate_per_day: 0.05 });
    let world = World::new(&s).unwrap();
    let day = 4.0;
    let e = s.phantom.youngs_modulus * 1.2;
    let (_, direct) = direct(&world, e, &[]);
    let mut load = vec![0.0; world.body.dof_count()];
    let at = world.body.locate([0.03, 0.02, 0.0]).unwrap();
    world.body.add_point_force(&at, [0.1, 0.3, 0.0], &mut load);
    let expected = direct.solve(&[&load]).pop().unwrap();
    let shared = world
        .response(day)
        .unwrap()
        .solve(&world.body, &[load], &[])
        .unwrap();
    let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(largest_gap(&shared[0], &expected) < 1e-10 * scale);
    // Day 0 and the stiffened day use the same factorisation.
    let (a, b) = (world.response(0.0).unwrap(), world.response(day).unwrap());
    match (a, b) {
        (
            crate::world::Response::Linear {
                system: a,
                scale: sa,
            },
            crate::world::Response::Linear {
                system: b,
                scale: sb,
            },
        ) => {
            assert!(std::sync::Arc::ptr_eq(&a, &b));
            assert_eq!(sa, 1.0);
            assert!((sb - 1.2).abs() < 1e-12);
        }
        _ => panic!("the linear truth answers linearly"),
    }
}

#[test]
fn probe_by_lagrange_multipliers_equals_the_held_face_solve() {
    for s in plane_and_slab() {
        let world = World::new(&s).unwrap();
        let probe = s.probes[0];
        let run = press(&world, &probe, Factorisation::Shared).unwrap();
        let dim = world.body.dim;
        let contact = world.body.nodes_where(|x| {
            x[1].abs() < 1e-12 && (x[0] - probe.x).abs() <= probe.width / 2.0 + 1e-12
        });
        assert!(contact.len() >= 3);
        let held: Vec<usize> = contact.iter().map(|&n| n * dim + 1).collect();
        let (k, f) = direct(&world, s.phantom.youngs_modulus, &held);
        let mut prescribed = vec![0.0; world.body.dof_count()];
        for &d in &held {
            prescribed[d] = probe.indentation;
        }
        let expected = f.solve_prescribed(&k, &prescribed);
        let gap = largest_gap(&run.last_displacement, &expected);
        assert!(gap < 1e-9 * probe.indentation, "gap {gap}");
        let r = k.multiply(&expected);
        let force: f64 = world.body.copies() * held.iter().map(|&d| r[d]).sum::<f64>();
        let got = *run.force.last().unwrap();
        assert!((got - force).abs() < 1e-9 * force, "{got} vs {force}");
        // A probe with a factorisation of its own holds the face directly.
        let own = press(&world, &probe, Factorisation::Own).unwrap();
        let gap = largest_gap(&own.last_displacement, &expected);
        assert!(gap < 1e-9 * probe.indentation, "own: gap {gap}");
        let got = *own.force.last().unwrap();
        assert!((got - force).abs() < 1e-9 * force, "own: {got} vs {force}");
        let (a, b) = (run.moment.last().unwrap(), own.moment.last().unwrap());
        assert!((a - b).abs() < 1e-9 * force * probe.width, "{a} vs {b}");
    }
}

#[test]
fn neo_hookean_tangent_at_rest_is_the_linear_stiffness() {
    for s in plane_and_slab() {
        let world = World::new(&s).unwrap();
        let pairs = [(s.phantom.youngs_modulus, s.phantom.poisson_ratio)];
        let linear = Stiffness::new(
            &world
                .body
                .stiffness(&Materials::from_parameters(&pairs).unwrap())
                .unwrap(),
            &[],
        )
        .unwrap();
        let neo = NeoHookean::new(&world.body, &pairs, &[], world.fixed.clone(), &[]).unwrap();
        let tangent = neo
            .tangent_at(&world.body, &vec![0.0; world.body.dof_count()], None)
            .unwrap();
        // Compare the two matrices through their action on a few vectors.
        for seed in 0..3 {
            let v: Vec<f64> = (0..world.body.dof_count())
                .map(|i| ((i * 7919 + seed * 104729) % 1000) as f64 / 1000.0 - 0.5)
                .collect();
            let a = linear.multiply(&v);
            let b = tangent.multiply(&v);
            let scale = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let diff = a
                .iter()
                .zip(&b)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            assert!(
                diff < 1e-9 * scale,
                "dim {}: {diff} vs {scale}",
                world.body.dim
            );
        }
    }
}

/// Away from rest the tangent must still be the derivative of the
/// internal forces: Newton's convergence rests on it. Checked against a
/// central difference of $f_{int}$ along a few directions at a smooth
/// field whose strains reach some 60%.
#[test]
fn neo_hookean_tangent_is_the_derivative_of_the_internal_forces_when_strained() {
    for s in plane_and_slab() {
        let world = World::new(&s).unwrap();
        let body = &world.body;
        let pairs = [(s.phantom.youngs_modulus, s.phantom.poisson_ratio)];
        let neo = NeoHookean::new(body, &pairs, &[], world.fixed.clone(), &[]).unwrap();
        let (w, d) = (s.phantom.width, s.phantom.depth);
        let mut u = vec![0.0; body.dof_count()];
        for (n, x) in body.nodes.iter().enumerate() {
            let (a, b) = (x[0] / w, x[1] / d);
            u[n * body.dim] = 0.2 * w * a * b * (1.0 - b);
            u[n * body.dim + 1] = -0.3 * d * b * b + 0.1 * d * a * b;
        }
        let tangent = neo.tangent_at(body, &u, None).unwrap();
        for seed in 0..3 {
            let v: Vec<f64> = (0..body.dof_count())
                .map(|i| ((i * 7919 + seed * 104729) % 1000) as f64 / 1000.0 - 0.5)
                .collect();
            let h = 1e-7 * w;
            let shifted = |sign: f64| -> Vec<f64> {
                let p: Vec<f64> = u.iter().zip(&v).map(|(a, b)| a + sign * h * b).collect();
                neo.internal_forces(body, &p)
            };
            let (plus, minus) = (shifted(1.0), shifted(-1.0));
            let exact = tangent.multiply(&v);
            let scale = exact.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let diff = (0..exact.len())
                .map(|i| ((plus[i] - minus[i]) / (2.0 * h) - exact[i]).abs())
                .fold(0.0f64, f64::max);
            assert!(diff < 1e-6 * scale, "dim {}: {diff} vs {scale}", body.dim);
        }
    }
}

/// A scenario's `resolution.plane_grading` sets the plane truth's levels
/// of grading; absent, each material keeps its own (`grid`).
#[test]
fn the_plane_truth_is_graded_as_the_scenario_says() {
    use crate::grid::{NEO_HOOKEAN_GRADING_LEVELS, PLANE_GRADING_LEVELS};
    let nodes = |s: &Scenario| World::new(s).unwrap().body.nodes.len();
    let mut linear = small();
    let mut neo_hookean = small();
    neo_hookean.effects.material_nonlinearity = Some(crate::effect::MaterialNonlinearity);
    let (linear_default, neo_hookean_default) = (nodes(&linear), nodes(&neo_hookean));
    assert!(neo_hookean_default < linear_default);
    linear.resolution.plane_grading = Some(PLANE_GRADING_LEVELS);
    neo_hookean.resolution.plane_grading = Some(NEO_HOOKEAN_GRADING_LEVELS);
    assert_eq!(nodes(&linear), linear_default);
    assert_eq!(nodes(&neo_hookean), neo_hookean_default);
    linear.resolution.plane_grading = Some(NEO_HOOKEAN_GRADING_LEVELS);
    assert_eq!(nodes(&linear), neo_hookean_default);
    linear.resolution.plane_grading = Some(0);
    assert!(nodes(&linear) < neo_hookean_default);
}

/// The probe's force and marker field, neo-Hookean against linear on the
/// same mesh. The linear response is the neo-Hookean one at a vanishing
/// indentation (10 um) scaled up: its tangent at rest is the linear
/// stiffness (`neo_hookean_tangent_at_rest_is_the_linear_stiffness`), and
/// the two meshes of the plane truth differ (the neo-Hookean one is graded
/// less, `grid::NEO_HOOKEAN_GRADING_LEVELS`), so a linear world would
/// compare meshes, not materials. At 30 um the response must still be
/// proportional (it departs by 0.03% of the largest marker displacement);
/// at 6 mm the markers depart by 8.3% and the force by 2.2%.
#[test]
fn neo_hookean_matches_linear_at_small_load_and_departs_at_large() {
    let mut s = small();
    s.effects.material_nonlinearity = Some(crate::effect::MaterialNonlinearity);
    let world = World::new(&s).unwrap();
    let pressed = |indentation: f64| {
        let probe = crate::scenario::ProbeTrial {
            indentation,
            ..s.probes[0]
        };
        press(&world, &probe, Factorisation::Shared).unwrap()
    };
    let unit = 1e-5;
    let linear = pressed(unit);
    for (indentation, close) in [(3e-5, true), (0.006, false)] {
        let a = pressed(indentation);
        let scale = indentation / unit;
        let (fa, fb) = (
            *a.force.last().unwrap(),
            scale * linear.force.last().unwrap(),
        );
        let force = (fa - fb).abs() / fb;
        let (ma, mb) = (a.markers.last().unwrap(), linear.markers.last().unwrap());
        let largest = scale * mb.iter().map(|m| m[0].hypot(m[1])).fold(0.0, f64::max);
        let markers = ma
            .iter()
            .zip(mb)
            .map(|(p, q)| (p[0] - scale * q[0]).hypot(p[1] - scale * q[1]))
            .fold(0.0, f64::max)
            / largest;
        if close {
            assert!(
                force < 1e-3 && markers < 1e-3,
                "small indentation: neo-Hookean {fa} vs linear {fb}, markers {markers}"
            );
        } else {
            assert!(
                markers > 2e-2,
                "large indentation: markers depart by {markers} of the largest"
            );
        }
    }
}

#[test]
fn uniaxial_neo_hookean_starts_with_slope_e() {
    let e = 25_300.0;
    let stress = uniaxial_nominal_stress(e, 0.48, 1.0 - 1e-5);
    assert!((stress / 1e-5 - e).abs() < 1e-3 * e, "{}", stress / 1e-5);
    // Compression stiffens relative to linear in nominal stress.
    assert!(uniaxial_nominal_stress(e, 0.48, 0.7) > 0.3 * e);
}

#[test]
fn out_of_plane_markers_move_less_than_the_mid_plane() {
    let s = Scenario {
        effects: Effects {
            out_of_plane: Some(OutOfPlane),
            ..Effects::none()
        },
        ..small()
    };
    let world = World::new(&s).unwrap();
    let response = world.response(0.0).unwrap();
    let run = &insert(
        &world,
        &[(plan(&s), &response)],
        s.needles.depth,
        s.resolution.depth_step,
    )
    .unwrap()[0];
    let u = &run.last_displacement;
    let line = plan(&s).line;
    let mid = world
        .body
        .value(&world.body.locate([line, 0.02, 0.0]).unwrap(), u)[1];
    let top = world.body.value(
        &world
            .body
            .locate([line, 0.02, world.body.marker_z()])
            .unwrap(),
        u,
    )[1];
    assert!(top > 0.0 && top < 0.9 * mid, "top {top} mid {mid}");
}

#[test]
fn compliant_support_lets_the_back_face_move() {
    let mut s = small();
    s.effects.compliant_support = Some(CompliantSupport {
        normal: 1e6,
        tangential: 1e6,
    });
    let world = World::new(&s).unwrap();
    assert!(world.fixed.iter().all(|f| !f));
    let response = world.response(0.0).unwrap();
    let run = &insert(
        &world,
        &[(plan(&s), &response)],
        s.needles.depth,
        s.resolution.depth_step,
    )
    .unwrap()[0];
    let back = world.body.value(
        &world
            .body
            .locate([plan(&s).line, s.phantom.depth, 0.0])
            .unwrap(),
        &run.last_displacement,
    )[1];
    // Traction about F / (width t) over the face, divided by k.
    let expected = run.force.last().unwrap() / (s.phantom.width * s.phantom.thickness) / 1e6;
    assert!(
        back > 0.2 * expected && back < 5.0 * expected,
        "back face moves {back}, order {expected}"
    );
    // The springs carry the whole load.
    let r = response.internal_forces(&world.body, &run.last_displacement);
    let total: f64 = (0..world.body.nodes.len()).map(|n| r[n * 2 + 1]).sum();
    assert!((total - run.force.last().unwrap()).abs() < 1e-9);
}

#[test]
fn layered_phantom_assigns_regions_by_depth() {
    let mut s = small();
    s.effects.layered_stiffness = Some(LayeredStiffness {
        boundaries: vec![0.03],
        moduli: vec![20e3, 60e3],
    });
    let world = World::new(&s).unwrap();
    assert_eq!(world.moduli(0.0), vec![20e3, 60e3]);
    let regions = world.body.regions();
    for e in 0..world.body.element_count() {
        let y = world
            .body
            .element(e)
            .iter()
            .map(|&n| world.body.nodes[n][1])
            .sum::<f64>()
            / 6.0;
        assert_eq!(regions[e], usize::from(y >= 0.03));
    }
}

#[test]
fn tip_peak_adds_force_near_the_tip_only() {
    let mut s = small();
    let plain = crate::shaft::ShaftLoad::of(&s, &plan(&s));
    s.effects.tip_cutting_force = Some(TipCuttingForce {
        amplitude: 1.0,
        offset: 0.002,
        width: 0.0015,
    });
    let peaked = crate::shaft::ShaftLoad::of(&s, &plan(&s));
    assert!((peaked.at(0.002) - 2.0 * plain.at(0.002)).abs() < 1e-12);
    assert!((peaked.at(0.02) - plain.at(0.02)).abs() < 1e-9);
    let extra: f64 = peaked
        .points(0.0, 0.03, 60)
        .iter()
        .map(|p| p.force)
        .sum::<f64>()
        - plain
            .points(0.0, 0.03, 60)
            .iter()
            .map(|p| p.force)
            .sum::<f64>();
    // Integral of the bump: A q w sqrt(pi) (almost all of it behind the tip).
    let expected = plain.density
        * 0.0015
        * std::f64::consts::PI.sqrt()
        * 0.5
        * (1.0 + libm_erf(0.002 / 0.0015));
    assert!(
        (extra - expected).abs() < 1e-3 * expected,
        "{extra} vs {expected}"
    );
}

/// erf by its series (enough terms for |x| < 3).
fn libm_erf(x: f64) -> f64 {
    let mut sum = 0.0;
    let mut term = x;
    for n in 0..60 {
        sum += term / (2 * n + 1) as f64;
        term *= -x * x / (n + 1) as f64;
    }
    2.0 / std::f64::consts::PI.sqrt() * sum
}

#[test]
fn kept_columns_give_the_full_solve_on_the_band_and_at_the_markers() {
    for s in plane_and_slab() {
        let world = World::new(&s).unwrap();
        let response = world.response(3.0).unwrap();
        let body = &world.body;
        let line = plan(&s).line;
        let mut columns = LineResponse::new(&world, &response, line, 0.02, 1e-3)
            .unwrap()
            .unwrap();
        // Point loads along +y just off the line, in the mid-plane.
        let mut f = vec![0.0; body.dof_count()];
        for (k, y) in [0.001, 0.0072, 0.013, 0.0195].into_iter().enumerate() {
            let at = body.locate([line + 2e-5 * k as f64, y, 0.0]).unwrap();
            body.add_point_force(&at, [0.0, 0.1 + 0.05 * k as f64, 0.0], &mut f);
        }
        // The first columns are the nodes on the line; the loads just off
        // it ask for the columns of their side.
        let Err(Missing::Columns(missing)) = columns.solve(&f) else {
            panic!("loads off the line need more columns")
        };
        columns.add_columns(&world, &response, &missing).unwrap();
        let (u, markers) = columns.solve(&f).expect("the loads lie in the band");
        let full = response
            .solve(body, &[f.clone()], &[])
            .unwrap()
            .pop()
            .unwrap();
        let scale = full.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut compared = 0;
        for e in (0..body.element_count()).filter(|&e| columns.covers(e)) {
            for &n in body.element(e) {
                for c in 0..body.dim {
                    let d = n * body.dim + c;
                    assert!((u[d] - full[d]).abs() < 1e-12 * scale, "dof {d}");
                    compared += 1;
                }
            }
        }
        assert!(compared > 0);
        for (m, exact) in markers.iter().zip(world.marker_displacements(&full)) {
            for c in 0..3 {
                assert!(
                    (m[c] - exact[c]).abs() < 1e-12 * scale,
                    "{m:?} vs {exact:?}"
                );
            }
        }
        // A load off the band has no column: the caller must solve it.
        let mut off = vec![0.0; body.dof_count()];
        let at = body.locate([line + 0.01, 0.01, 0.0]).unwrap();
        body.add_point_force(&at, [0.0, 0.1, 0.0], &mut off);
        assert!(matches!(columns.solve(&off), Err(Missing::Band)));
    }
}

/// Largest difference of the marker displacements and of the forces of
/// two runs of the same insertion.
fn run_gap(a: &NeedleRun, b: &NeedleRun) -> (f64, f64) {
    assert_eq!(a.depths, b.depths);
    let mut markers = 0.0f64;
    for (sa, sb) in a.markers.iter().zip(&b.markers) {
        for (ma, mb) in sa.iter().zip(sb) {
            for c in 0..3 {
                markers = markers.max((ma[c] - mb[c]).abs());
            }
        }
    }
    let force = largest_gap(&a.force, &b.force);
    (markers, force)
}

#[test]
fn insertion_from_kept_columns_equals_full_solves_with_and_without_fallback() {
    // The plane, the slab, and the slab with a needle whose drag is read
    // on its surface (in band elements above the mid-plane too).
    for s in plane_and_slab()
        .into_iter()
        .chain([slab_needle(thick_needle())])
    {
        let world = World::new(&s).unwrap();
        let response = world.response(0.0).unwrap();
        let trials = [(plan(&s), &response)];
        let (depth, step) = (s.needles.depth, s.resolution.depth_step);
        let full = &insert_with(&world, &trials, depth, step, None).unwrap()[0];
        let columns = &insert(&world, &trials, depth, step).unwrap()[0];
        // The band covers only the first elements of the insertion: the
        // later states fall back to full solves.
        let short = Band {
            margin: 1e-3 * world.body.element_size,
            depth: 0.2 * depth,
        };
        let mixed = &insert_with(&world, &trials, depth, step, Some(short)).unwrap()[0];
        assert!(
            mixed.full_solves > columns.full_solves,
            "the fallback was taken"
        );
        let density = columns.load.density;
        for run in [columns, mixed] {
            // The two agree within what the consistency tolerance allows:
            // no material point is off by more than it, so no marker and
            // no load position either.
            let (markers, force) = run_gap(run, full);
            assert!(
                markers < CONSISTENCY_TOLERANCE,
                "markers off by {markers} m"
            );
            assert!(
                force < 2.0 * density * CONSISTENCY_TOLERANCE,
                "force off by {force} N"
            );
            assert!(
                largest_gap(&run.last_displacement, &full.last_displacement)
                    < CONSISTENCY_TOLERANCE
            );
        }
    }
}

/// The small 3-D slab with a needle of `radius`.
fn slab_needle(radius: f64) -> Scenario {
    let mut s = plane_and_slab()[1].clone();
    s.needles.radius = radius;
    s
}

/// A needle radius a fifth of the small slab's thickness (1.5 mm).
fn thick_needle() -> f64 {
    0.2 * plane_and_slab()[1].phantom.thickness
}

#[test]
fn a_needles_radius_drags_the_tissue_less_than_its_axis_and_shrinks_to_it() {
    let run = |radius: f64| {
        let s = slab_needle(radius);
        let world = World::new(&s).unwrap();
        let response = world.response(0.0).unwrap();
        let trials = [(plan(&s), &response)];
        insert(&world, &trials, s.needles.depth, s.resolution.depth_step)
            .unwrap()
            .remove(0)
    };
    let axis = run(0.0);
    let thin = run(1e-9);
    let thick = run(thick_needle());
    // The drag is read on the needle's surface, where the displacement
    // has fallen off from its peak at the loaded axis: the entry and the
    // loaded points are dragged in less.
    for (k, (a, t)) in axis.entry.iter().zip(&thick.entry).enumerate().skip(1) {
        assert!(
            t < a,
            "state {k}: entry {t} m with the radius, {a} m on the axis"
        );
    }
    // A vanishing radius reads the axis.
    let (markers, _) = run_gap(&thin, &axis);
    assert!(
        markers < CONSISTENCY_TOLERANCE,
        "markers off by {markers} m"
    );
}

#[test]
fn needle_states_are_halved_near_the_entry_and_nest_when_the_step_is_halved() {
    let grid = depth_grid(0.05, 0.001);
    // 8 halved intervals (16 states) and 42 whole ones, after the rest state.
    assert_eq!(grid.len(), 1 + 16 + 42);
    for (k, w) in grid.windows(2).enumerate() {
        let expected = if w[0] < ENTRY_DEPTH - 1e-12 {
            0.0005
        } else {
            0.001
        };
        assert!((w[1] - w[0] - expected).abs() < 1e-12, "interval {k}");
    }
    assert_eq!(*grid.last().unwrap(), 0.05);
    let fine = depth_grid(0.05, 0.0005);
    assert_eq!(fine.len(), 2 * grid.len() - 1);
    for (a, b) in fine.iter().step_by(2).zip(&grid) {
        assert!((a - b).abs() < 1e-15);
    }
}

/// Largest difference between the marker displacements of two runs, over
/// every state, and the largest displacement of the second.
fn marker_gap(a: &[Vec<[f64; 3]>], b: &[Vec<[f64; 3]>]) -> (f64, f64) {
    assert_eq!(a.len(), b.len());
    let pairs = a.iter().flatten().zip(b.iter().flatten());
    let gap = pairs
        .map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max);
    let largest = b
        .iter()
        .flatten()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    (gap, largest)
}

#[test]
fn the_slabs_upper_half_answers_as_the_whole_symmetric_slab() {
    let [_, tensor] = plane_and_slab();
    for s in [tensor, local_slab()] {
        upper_half_answers_as_the_whole(s);
    }
}

fn upper_half_answers_as_the_whole(mut s: Scenario) {
    // Springs on the back face too: the half carries half their area.
    s.effects.compliant_support = Some(CompliantSupport {
        normal: 1e6,
        tangential: 1e6,
    });
    let half = World::covering(&s, Span::UpperHalf).unwrap();
    let whole = World::covering(&s, Span::Whole).unwrap();
    assert!(half.body.upper_half && !whole.body.upper_half);
    // Three node planes of five.
    let ratio = half.body.dof_count() as f64 / whole.body.dof_count() as f64;
    assert!(ratio < 0.65, "{ratio}");

    let probe = s.probes[0];
    let (a, b) = (
        press(&half, &probe, Factorisation::Shared).unwrap(),
        press(&whole, &probe, Factorisation::Shared).unwrap(),
    );
    let (gap, largest) = marker_gap(&a.markers, &b.markers);
    assert!(
        largest > 1e-5 && gap < 1e-10 * largest,
        "probe: {gap} of {largest}"
    );
    let (fa, fb) = (*a.force.last().unwrap(), *b.force.last().unwrap());
    assert!(fb > 0.0 && (fa - fb).abs() < 1e-10 * fb, "{fa} vs {fb}");
    let (ma, mb) = (*a.moment.last().unwrap(), *b.moment.last().unwrap());
    assert!((ma - mb).abs() < 1e-9 * fb * probe.width, "{ma} vs {mb}");

    let needle = |world: &World| {
        let response = world.response(0.0).unwrap();
        insert(
            world,
            &[(plan(&s), &response)],
            s.needles.depth,
            s.resolution.depth_step,
        )
        .unwrap()
        .remove(0)
    };
    let (a, b) = (needle(&half), needle(&whole));
    let (gap, largest) = marker_gap(&a.markers, &b.markers);
    // The insertion's placement is iterated until its points move less
    // than CONSISTENCY_TOLERANCE: the two agree to that, not to round-off.
    assert!(
        largest > 1e-5 && gap < 1e-2 * CONSISTENCY_TOLERANCE,
        "needle: {gap} of {largest}"
    );
    for (ea, eb) in a.entry.iter().zip(&b.entry) {
        assert!(
            (ea - eb).abs() < CONSISTENCY_TOLERANCE,
            "entry {ea} vs {eb}"
        );
    }
    let tip = (0..3).map(|c| (a.tip_material[c] - b.tip_material[c]).abs());
    assert!(tip.fold(0.0, f64::max) < CONSISTENCY_TOLERANCE);
}

#[test]
fn the_neo_hookean_slabs_upper_half_answers_as_the_whole() {
    let [_, mut s] = plane_and_slab();
    s.effects.material_nonlinearity = Some(crate::effect::MaterialNonlinearity);
    // One Newton solve of a millimetre's indentation; the whole mirrored
    // slab's tangent is indefinite there (an antisymmetric mode), which
    // the half's symmetry plane removes.
    s.resolution.indentation_step = 0.001;
    let probe = crate::scenario::ProbeTrial {
        indentation: 0.001,
        ..s.probes[0]
    };
    let run = |span| {
        press(
            &World::covering(&s, span).unwrap(),
            &probe,
            Factorisation::Shared,
        )
        .unwrap()
    };
    let (a, b) = (run(Span::UpperHalf), run(Span::Whole));
    let (gap, largest) = marker_gap(&a.markers, &b.markers);
    assert!(largest > 1e-5 && gap < 1e-9 * largest, "{gap} of {largest}");
    let (fa, fb) = (*a.force.last().unwrap(), *b.force.last().unwrap());
    assert!((fa - fb).abs() < 1e-9 * fb, "{fa} vs {fb}");
}

/// Largest marker difference over every state of every trial of `kind`
/// (m), as vector lengths.
fn trial_marker_gap(a: &[TrialResponse], b: &[TrialResponse], kind: TrialKind) -> f64 {
    a.iter()
        .zip(b)
        .filter(|(t, _)| t.kind == kind)
        .flat_map(|(t, u)| t.markers.iter().zip(&u.markers))
        .flat_map(|(p, q)| p.iter().zip(q))
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .fold(0.0, f64::max)
}

/// The small slab graded as `grading`, its needle settled on `markers`.
fn graded_slab(grading: SlabGrading, markers: Option<SlabGrading>) -> Scenario {
    let mut s = plane_and_slab()[1].clone();
    s.probes.clear();
    s.resolution.slab_grading = Some(grading);
    s.resolution.marker_grading = markers;
    s
}

#[test]
fn a_needle_settled_on_a_copy_of_its_placement_mesh_is_the_placement_mesh_s() {
    let grading = SlabGrading::DEFAULT;
    let alone = respond(&graded_slab(grading, None)).unwrap();
    let copied = respond(&graded_slab(grading, Some(grading))).unwrap();
    let largest = alone
        .iter()
        .flat_map(|t| t.markers.iter().flatten())
        .map(|p| p[0].hypot(p[1]))
        .fold(0.0, f64::max);
    let gap = trial_marker_gap(&alone, &copied, TrialKind::Needle);
    assert!(largest > 1e-4, "the needle moves the markers: {largest} m");
    // The same loads, solved by back-substitution instead of from the
    // kept columns: equal up to round-off, and consistent at once.
    assert!(gap < 1e-9 * largest, "markers differ by {gap} m");
    for (a, c) in alone.iter().zip(&copied) {
        assert_eq!(a.force, c.force, "{}: the force is the placement's", a.id);
    }
}

#[test]
fn only_a_linear_slab_reads_its_markers_on_a_marker_mesh() {
    use crate::marker_mesh::marker_scenario;
    let finer = Some(SlabGrading {
        faces: 3,
        ..SlabGrading::DEFAULT
    });
    let mut slab = graded_slab(SlabGrading::DEFAULT, finer);
    let fine = marker_scenario(&slab).unwrap();
    assert_eq!(fine.resolution.slab_grading, finer);
    assert_eq!(fine.resolution.marker_grading, None);
    assert_eq!(fine.phantom, slab.phantom);
    slab.effects.material_nonlinearity = Some(crate::effect::MaterialNonlinearity);
    assert!(marker_scenario(&slab).is_none());
    let mut plane = small();
    plane.resolution.marker_grading = finer;
    assert!(marker_scenario(&plane).is_none());
}

/// With `resolution.marker_grading` the needle placed on the coarse mesh
/// goes on to a consistent placement on the finer one: the finer mesh's
/// own insertion, to the consistency tolerance, and nearer the converged
/// markers than the coarse mesh's.
#[test]
fn a_needle_settled_on_a_finer_mesh_is_that_mesh_s_own() {
    let coarse = SlabGrading::DEFAULT;
    let fine = SlabGrading {
        faces: 3,
        needle_lines: 2,
        mid_plane: 1,
        top_face: 2,
        probe_edges: 0,
        local: None,
    };
    let reference = SlabGrading {
        faces: 4,
        needle_lines: 3,
        mid_plane: 2,
        top_face: 3,
        probe_edges: 0,
        local: None,
    };
    let converged = respond(&graded_slab(reference, None)).unwrap();
    let alone = respond(&graded_slab(coarse, None)).unwrap();
    let settled = respond(&graded_slab(coarse, Some(fine))).unwrap();
    let fine_alone = respond(&graded_slab(fine, None)).unwrap();
    let before = trial_marker_gap(&alone, &converged, TrialKind::Needle);
    let after = trial_marker_gap(&settled, &converged, TrialKind::Needle);
    // Measured: 27.7 um from the coarse mesh, 5.85 um settled on the
    // finer one and on the finer mesh alone.
    assert!(
        after < 0.35 * before,
        "settled on the finer mesh {after} m from the converged markers, {before} m before"
    );
    // The two are found independently: the settled placement from the
    // coarse mesh's kept columns and then back-substitutions of the finer
    // mesh, the finer mesh's own from its kept columns; both consistent to
    // CONSISTENCY_TOLERANCE in the loads' material points, which move the
    // far markers by much less (measured: 4.8 nm).
    let settled_gap = trial_marker_gap(&settled, &fine_alone, TrialKind::Needle);
    assert!(
        settled_gap < 0.1 * CONSISTENCY_TOLERANCE,
        "settled {settled_gap} m from the finer mesh's own markers"
    );
    // The force is the shaft load's integral from the entry, which both
    // place within the tolerance: they differ by at most the load on
    // twice that length of shaft (the density at the entry is the shaft's
    // own, below the mean F / depth).
    for (settled, own) in settled.iter().zip(&fine_alone) {
        for ((a, b), depth) in settled.force.iter().zip(&own.force).zip(&own.states) {
            let bound = 2.0 * CONSISTENCY_TOLERANCE * b.abs() / depth.max(f64::MIN_POSITIVE);
            assert!((a - b).abs() <= bound, "{}: {a} N against {b} N", own.id);
        }
    }
}

/// The small slab's probes alone (no needle, no compression test),
/// pressed on the slab of `grading` or, with `own`, each on a slab of its
/// own graded so.
fn probed_slab(grading: SlabGrading, own: Option<SlabGrading>) -> Scenario {
    let mut s = plane_and_slab()[1].clone();
    s.needles.velocities.clear();
    s.compression = None;
    s.resolution.slab_grading = Some(grading);
    s.resolution.probe_grading = own;
    s
}

#[test]
fn a_probe_pressed_on_its_own_copy_of_the_slab_is_the_shared_slab_s() {
    let grading = SlabGrading::DEFAULT;
    // One probe, so that its own slab has the same grid lines.
    let one_probe = |own| {
        let mut s = probed_slab(grading, own);
        s.probes.truncate(1);
        s
    };
    let shared = respond(&one_probe(None)).unwrap();
    let own = respond(&one_probe(Some(grading))).unwrap();
    let largest = shared
        .iter()
        .flat_map(|t| t.markers.iter().flatten())
        .map(|p| p[0].hypot(p[1]))
        .fold(0.0, f64::max);
    assert!(largest > 1e-4, "the probe moves the markers: {largest} m");
    let gap = trial_marker_gap(&shared, &own, TrialKind::Probe);
    assert!(gap < 1e-9 * largest, "markers differ by {gap} m");
    for (a, b) in shared.iter().zip(&own) {
        let (fa, fb) = (*a.force.last().unwrap(), *b.force.last().unwrap());
        assert!((fa - fb).abs() < 1e-9 * fa, "{}: {fa} vs {fb}", a.id);
        assert!((a.peak_strain - b.peak_strain).abs() < 1e-9 * a.peak_strain);
    }
}

#[test]
fn only_a_linear_slab_presses_its_flat_probes_on_slabs_of_their_own() {
    use crate::probe_mesh::probe_scenario;
    let own = Some(SlabGrading {
        probe_edges: 3,
        ..SlabGrading::DEFAULT
    });
    let mut slab = graded_slab(SlabGrading::DEFAULT, None);
    slab.probes = small().probes;
    slab.resolution.probe_grading = own;
    let probe = slab.probes[0];
    let alone = probe_scenario(&slab, &probe).unwrap();
    assert_eq!(alone.resolution.slab_grading, own);
    assert_eq!(alone.resolution.probe_grading, None);
    assert_eq!(alone.probes, [probe]);
    assert!(alone.needles.plan().is_empty() && alone.compression.is_none());
    assert_eq!(alone.phantom, slab.phantom);
    assert_eq!(alone.effects, slab.effects);
    slab.effects.material_nonlinearity = Some(crate::effect::MaterialNonlinearity);
    assert!(probe_scenario(&slab, &probe).is_none());
    let mut plane = small();
    plane.resolution.probe_grading = own;
    assert!(probe_scenario(&plane, &plane.probes[0]).is_none());
}

#[test]
fn a_slab_graded_towards_the_probe_edges_brings_the_probe_markers_near_the_converged_ones() {
    let coarse = SlabGrading::DEFAULT;
    let own = SlabGrading {
        top_face: 1,
        probe_edges: 3,
        ..coarse
    };
    let reference = SlabGrading {
        top_face: 2,
        probe_edges: 5,
        ..coarse
    };
    let converged = respond(&probed_slab(reference, None)).unwrap();
    let shared = respond(&probed_slab(coarse, None)).unwrap();
    let pressed_alone = respond(&probed_slab(coarse, Some(own))).unwrap();
    let before = trial_marker_gap(&shared, &converged, TrialKind::Probe);
    let after = trial_marker_gap(&pressed_alone, &converged, TrialKind::Probe);
    // Measured: 237 um on the shared slab, 35 um on the probe's own.
    assert!(after < 0.3 * before, "{after} m, {before} m before");
}

/// A probe with rounded edges (`contact`) on a small neo-Hookean phantom.
mod rounded_probe {
    use super::*;
    use crate::contact::Punch;
    use crate::effect::MaterialNonlinearity;

    /// One probe at the middle of the front face, 4 mm wide with 0.5 mm
    /// edges, pressed 0.5 mm into a coarse neo-Hookean plane phantom, the
    /// campaign's only trial on the mesh (`probe_mesh::pressed_apart`).
    fn scenario() -> Scenario {
        let mut s = Scenario::quick();
        s.needles.velocities.clear();
        s.phantom.markers = (6, 6);
        s.resolution.refinement = 1;
        s.resolution.indentation_step = 0.000125;
        s.effects = Effects::none();
        s.effects.material_nonlinearity = Some(MaterialNonlinearity);
        let mut probe = s.probes[0];
        probe.x = s.phantom.width / 2.0;
        probe.width = 0.004;
        probe.indentation = 0.0005;
        probe.edge_radius = Some(0.0005);
        s.probes = vec![probe];
        s
    }

    #[test]
    fn a_rounded_probe_is_pressed_on_a_mesh_of_its_own_and_a_flat_one_is_not() {
        use crate::probe_mesh::probe_scenario;
        let alone = scenario();
        let rounded = alone.probes[0];
        assert!(probe_scenario(&alone, &rounded).is_none());
        let mut flat = rounded;
        flat.x = alone.phantom.width / 4.0;
        flat.edge_radius = None;
        let mut campaign = alone.clone();
        campaign.probes.push(flat);
        campaign.needles.velocities = vec![0.003];
        let own = probe_scenario(&campaign, &rounded).unwrap();
        assert_eq!(own, without_compression_or_frames(&alone));
        assert!(probe_scenario(&campaign, &flat).is_none());
        // The campaign's mesh leaves the rounded probe's lines out, and its
        // own mesh is the probe's alone.
        let nodes = |s: &Scenario| World::new(s).unwrap().body.nodes.len();
        let mut without = campaign.clone();
        without.probes.remove(0);
        assert_eq!(nodes(&campaign), nodes(&without));
        assert_eq!(nodes(&own), nodes(&alone));
    }

    #[test]
    fn the_force_sensor_reads_a_rounded_probe_s_sideways_push() {
        let mut s = scenario();
        s.probes[0].x = 0.005;
        s.compression = None;
        s.frames = None;
        s.sensors.force_sigma = 0.0;
        s.sensors.force_resolution = 0.0;
        let world = World::new(&s).unwrap();
        let run = press(&world, &s.probes[0], Factorisation::Shared).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let bundle = dir.path().join("bundle");
        crate::generate(&s, &bundle, &dir.path().join("truth.ron"), |_| {}).unwrap();
        let campaign = needle_data::read_bundle(&bundle).unwrap().campaign;
        let last = *campaign.trials[0].tool.last().unwrap();
        let [sideways, force] = [&run.sideways, &run.force].map(|f| *f.last().unwrap());
        assert!(sideways.abs() > 1e-3 * force, "{sideways} N sideways");
        assert!(
            (last.fx - sideways).abs() < 1e-12,
            "{} against {sideways}",
            last.fx
        );
        assert!(
            (last.fy - force).abs() < 1e-12,
            "{} against {force}",
            last.fy
        );
    }

    fn without_compression_or_frames(s: &Scenario) -> Scenario {
        let mut s = s.clone();
        s.compression = None;
        s.frames = None;
        s
    }

    #[test]
    fn a_rounded_probe_is_balanced_by_the_supports_and_nothing_passes_into_it() {
        // Off the middle, so that the face slides under the probe and its
        // edges push sideways.
        let mut s = scenario();
        s.probes[0].x = 0.005;
        let world = World::new(&s).unwrap();
        let body = &world.body;
        let probe = s.probes[0];
        let run = press(&world, &probe, Factorisation::Shared).unwrap();
        let u = &run.last_displacement;
        let force = *run.force.last().unwrap() / body.copies();
        let sideways = *run.sideways.last().unwrap() / body.copies();
        assert!(force > 0.0, "{force}");
        assert!(sideways.abs() > 1e-3 * force, "{sideways} N sideways");
        // The supports' reactions are the elastic forces at the held back
        // face; the probe's forces are the contact's. Computed apart, they
        // must balance, in force and, about the probe's centre, in moment
        // (the neo-Hookean forces have none of their own at the current
        // positions, the energy being blind to rotations).
        let solver = world.neo_hookean(probe.day, &[], &[]).unwrap();
        let reactions = solver.internal_forces(body, u);
        let held: Vec<usize> = (0..body.nodes.len())
            .filter(|&n| world.fixed[n * body.dim + 1])
            .collect();
        let along = |i: usize| -> f64 { held.iter().map(|&n| reactions[n * body.dim + i]).sum() };
        assert!(
            (along(1) + force).abs() < 1e-6 * force,
            "probe {force} N against supports {} N",
            along(1)
        );
        assert!(
            (along(0) + sideways).abs() < 1e-6 * force,
            "probe {sideways} N sideways against supports {} N",
            along(0)
        );
        let moment: f64 = held
            .iter()
            .map(|&n| {
                let arm = [
                    body.nodes[n][0] - probe.x,
                    body.nodes[n][1] - probe.indentation,
                ];
                arm[0] * reactions[n * body.dim + 1] - arm[1] * reactions[n * body.dim]
            })
            .sum();
        let probe_moment = *run.moment.last().unwrap() / body.copies();
        let scale = force * s.phantom.depth;
        assert!(
            (moment + probe_moment).abs() < 1e-6 * scale,
            "probe {probe_moment} N m against supports {moment} N m"
        );
        // Every front-face node is outside the probe or inside it by no
        // more than the penalty's error (measured 5.3e-9 m, about 1e-5 of
        // the depth), and the rounded edges are touched.
        let punch = Punch {
            centre: probe.x,
            half_width: probe.width / 2.0,
            edge_radius: probe.edge_radius.unwrap(),
            depth: probe.indentation,
        };
        let tol = 1e-9 * s.phantom.width;
        let front = body.nodes_where(|x| x[1].abs() < tol);
        let mut on_edges = 0;
        for &n in &front {
            let p = [
                body.nodes[n][0] + u[n * body.dim],
                body.nodes[n][1] + u[n * body.dim + 1],
            ];
            let at = punch.penetration_of(p);
            assert!(
                at.depth < 1e-4 * probe.indentation,
                "node {n} at {p:?} is {} m inside",
                at.depth
            );
            if at.depth > -1e-9 && at.curvature > 0.0 {
                on_edges += 1;
            }
        }
        assert!(on_edges >= 1, "no node on the rounded edges");
    }

    /// The probe pressed by `solver.press` in `scenario()`'s depth steps,
    /// every penalty scaled by `stiffer`: the markers and the force.
    fn pressed_with_penalty(world: &World, stiffer: f64) -> (Vec<[f64; 3]>, f64) {
        let (body, probe) = (&world.body, world.scenario.probes[0]);
        let tol = 1e-9 * world.scenario.phantom.width;
        let front = body.nodes_where(|x| x[1].abs() < tol);
        let solver = world.neo_hookean(probe.day, &[], &front).unwrap();
        let mut contact = solver.contact(Punch {
            centre: probe.x,
            half_width: probe.width / 2.0,
            edge_radius: probe.edge_radius.unwrap(),
            depth: 0.0,
        });
        for k in &mut contact.penalties {
            *k *= stiffer;
        }
        let steps = (probe.indentation / world.scenario.resolution.indentation_step).round();
        let mut u = vec![0.0; body.nodes.len() * body.dim];
        let mut from = 0.0;
        for k in 1..=steps as usize {
            contact.punch.depth = probe.indentation * k as f64 / steps;
            u = solver.press(body, &u, from, &mut contact).unwrap();
            from = contact.punch.depth;
        }
        let force = contact.resultant(&body.nodes, body.dim, &u).0[1];
        (world.marker_displacements(&u), force)
    }

    #[test]
    fn a_hundred_times_stiffer_penalty_moves_no_marker_by_a_thousandth_of_the_noise() {
        let s = scenario();
        let world = World::new(&s).unwrap();
        let (markers, force) = pressed_with_penalty(&world, 1.0);
        let (stiff_markers, stiff_force) = pressed_with_penalty(&world, 100.0);
        let moved = markers
            .iter()
            .zip(&stiff_markers)
            .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
            .fold(0.0f64, f64::max);
        let largest = markers
            .iter()
            .map(|a| a[0].hypot(a[1]))
            .fold(0.0f64, f64::max);
        assert!(largest > 1e-4, "the probe moved the markers {largest} m");
        // Measured: 6.0e-9 m of the largest 2.4e-4 m, force 9e-6 of itself.
        // A thousandth of the noise is a hundredth of the discretisation
        // error allowed (a tenth of the noise).
        assert!(
            moved < 1e-3 * s.sensors.marker_sigma,
            "a stiffer penalty moved a marker {moved} m"
        );
        assert!(
            (force - stiff_force).abs() < 1e-4 * force,
            "force {force} N, {stiff_force} N with the stiffer penalty"
        );
    }
}
