//! `LinearProblem::displacements_near`: solves restricted to the part of
//! the factor that a sparse load reaches give the whole solve's entries
//! there, at every wanted dof, and compute fewer entries than the whole.

use needle_fem::mesh::{MarkerGrid, RectangleMesh, SlabMesh};
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, LinearProblem, Material, Materials,
};
use std::sync::LazyLock;

use proptest::prelude::*;

/// A four-layer slab of quadratic tetrahedra held on its back face,
/// factorised: large enough for faer's supernodal layout.
fn slab() -> LinearProblem<3> {
    let lines: Vec<f64> = (1..=9).map(|i| i as f64 * 0.0075).collect();
    let grid = MarkerGrid {
        x: lines.clone(),
        y: lines,
    };
    let plan = RectangleMesh::with_markers(0.075, 0.075, &grid, 1).unwrap();
    let mesh = SlabMesh::new(plan, 0.0075, 4)
        .unwrap()
        .build(ElementKind::Tet10)
        .unwrap();
    let dirichlet = Dirichlet::fixed_face(&mesh, Face::Back);
    let mut problem = LinearProblem::new(
        Assembler::new(mesh, Formulation::Solid).unwrap(),
        vec![],
        dirichlet,
    )
    .unwrap();
    let materials = Materials::homogeneous(Material::new(25.0e3, 0.48).unwrap());
    problem.factorize(&materials).unwrap();
    problem
}

/// A load on the three dofs of each of `nodes`.
fn load_on(problem: &LinearProblem<3>, nodes: &[usize], seed: f64) -> Vec<f64> {
    let mut load = vec![0.0; problem.mesh().dof_count()];
    for (k, &n) in nodes.iter().enumerate() {
        for axis in 0..3 {
            load[3 * n + axis] = 1e-3 * (1.0 + seed + 0.37 * (k + axis) as f64).sin();
        }
    }
    load
}

/// Checks the partial solve of `loads` with `wanted` against the whole
/// solve; returns the share of free dofs it computed.
fn check(problem: &LinearProblem<3>, loads: &[Vec<f64>], wanted: &[usize]) -> f64 {
    let refs: Vec<&[f64]> = loads.iter().map(|l| l.as_slice()).collect();
    let whole = problem.displacements_many(&refs).unwrap();
    let near = problem.displacements_near(&refs, wanted).unwrap();
    let mut computed = 0;
    for (w, n) in whole.iter().zip(&near) {
        // Zero for a load on held dofs alone: the entries must then be 0.
        let scale = w.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for &d in wanted {
            assert!(n[d].is_finite(), "wanted dof {d} not computed");
        }
        for &d in problem.free_dofs() {
            if n[d].is_finite() {
                computed += 1;
                assert!(
                    (n[d] - w[d]).abs() <= 1e-11 * scale,
                    "dof {d}: {} against {}",
                    n[d],
                    w[d]
                );
            }
        }
        for (d, _) in problem.dirichlet().iter() {
            assert_eq!(n[d], w[d], "prescribed dof {d}");
        }
    }
    computed as f64 / (problem.free_dofs().len() * loads.len()) as f64
}

#[test]
fn a_corner_load_read_beside_it_computes_a_small_part_of_the_solution() {
    let problem = slab();
    let corner = problem
        .mesh()
        .nodes()
        .iter()
        .enumerate()
        .min_by(|(_, a), (_, b)| (a[0] + a[1]).total_cmp(&(b[0] + b[1])))
        .map(|(n, _)| n)
        .unwrap();
    let near_corner: Vec<usize> = (problem.mesh().nodes().iter().enumerate())
        .filter(|(_, p)| p[0] < 0.01 && p[1] < 0.01)
        .map(|(n, _)| n)
        .collect();
    let wanted: Vec<usize> = near_corner
        .iter()
        .flat_map(|&n| [3 * n, 3 * n + 1])
        .collect();
    let loads = [
        load_on(&problem, &[corner], 0.0),
        load_on(&problem, &[corner], 1.0),
    ];
    let share = check(&problem, &loads, &wanted);
    // Here 0.17: the corner's subdomains and the separators above them.
    assert!(share < 0.5, "computed {share} of the solution");
}

#[test]
fn loads_everywhere_compute_the_whole_solution() {
    let problem = slab();
    let every: Vec<usize> = (0..problem.mesh().node_count()).collect();
    let share = check(&problem, &[load_on(&problem, &every, 0.5)], &[]);
    assert_eq!(share, 1.0);
}

#[test]
fn prescribed_values_are_lifted_into_the_reach() {
    // Nonzero prescribed values load every free dof next to the held face:
    // the reach grows to hold them, and the entries stay exact.
    let mut problem = slab();
    let held: Vec<usize> = problem.dirichlet().iter().map(|(d, _)| d).collect();
    for &d in held.iter().filter(|&&d| d % 3 == 2) {
        problem.set_prescribed(d, 1e-5).unwrap();
    }
    let share = check(&problem, &[load_on(&problem, &[0], 0.0)], &[]);
    assert!(share > 0.0);
}

#[test]
fn a_wanted_dof_out_of_range_is_refused() {
    let problem = slab();
    let load = load_on(&problem, &[0], 0.0);
    let beyond = problem.mesh().dof_count();
    assert!(problem.displacements_near(&[&load], &[beyond]).is_err());
}

/// A load on a node of the held back face alone, with nothing wanted, is
/// checked like any other (the property below found this case: it
/// computes no free dof, and must not have to).
#[test]
fn a_load_on_held_dofs_alone_is_solved_too() {
    let problem = slab();
    let held = problem
        .mesh()
        .nodes()
        .iter()
        .position(|x| (x[1] - 0.075).abs() < 1e-12)
        .unwrap();
    let load = load_on(&problem, &[held], 0.0);
    assert!(problem.free_dofs().iter().all(|&d| load[d] == 0.0));
    let share = check(&problem, &[load], &[]);
    assert!((0.0..=1.0).contains(&share));
}

/// One factorised slab for every case of the property below.
static SLAB: LazyLock<LinearProblem<3>> = LazyLock::new(slab);

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn partial_solves_match_the_whole_solve(
        loaded in proptest::collection::vec(0usize..10_000, 1..6),
        wanted in proptest::collection::vec(0usize..30_000, 0..20),
        columns in 1usize..4,
    ) {
        let problem = &*SLAB;
        let nodes = problem.mesh().node_count();
        let loaded: Vec<usize> = loaded.iter().map(|n| n % nodes).collect();
        let wanted: Vec<usize> = wanted.iter().map(|d| d % problem.mesh().dof_count()).collect();
        let loads: Vec<Vec<f64>> = (0..columns)
            .map(|c| load_on(problem, &loaded[..=(c % loaded.len())], c as f64))
            .collect();
        let share = check(problem, &loads, &wanted);
        prop_assert!(share <= 1.0);
        // Loads on held dofs alone (the back face) reach nothing, and
        // with nothing wanted nothing need be computed.
        let reaches_free = loads
            .iter()
            .any(|l| problem.free_dofs().iter().any(|&d| l[d] != 0.0));
        if reaches_free {
            prop_assert!(share > 0.0);
        }
    }
}
