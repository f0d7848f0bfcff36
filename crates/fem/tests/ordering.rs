//! The fill-reducing ordering of `LinearProblem`: nested dissection along
//! the mesh's planes against faer's approximate minimum degree, on the
//! kinds of mesh the toolkit solves.

use faer::Side;
use faer::prelude::Solve;
use faer::sparse::linalg::cholesky::factorize_symbolic_cholesky;
use needle_fem::mesh::{MarkerGrid, RectangleMesh, SlabMesh};
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, LinearProblem, Material, Materials, Mesh,
};

/// A problem on `mesh` held on its back face, and the number of entries
/// of $L$ with its own ordering and with minimum degree.
fn fill<const D: usize>(
    mesh: Mesh<D>,
    formulation: Formulation,
) -> (LinearProblem<D>, usize, usize) {
    let dirichlet = Dirichlet::fixed_face(&mesh, Face::Back);
    let problem = LinearProblem::new(
        Assembler::new(mesh, formulation).unwrap(),
        vec![],
        dirichlet,
    )
    .unwrap();
    let own = problem.new_factor().symbolic().len_val();
    let minimum_degree = factorize_symbolic_cholesky(
        problem.reduced_stiffness().symbolic(),
        Side::Lower,
        Default::default(),
        Default::default(),
    )
    .unwrap()
    .len_val();
    (problem, own, minimum_degree)
}

fn plan(markers: usize, refinement: usize) -> RectangleMesh {
    let spacing = 0.075 / (markers + 1) as f64;
    let lines: Vec<f64> = (1..=markers).map(|i| i as f64 * spacing).collect();
    let grid = MarkerGrid {
        x: lines.clone(),
        y: lines,
    };
    RectangleMesh::with_markers(0.075, 0.075, &grid, refinement).unwrap()
}

#[test]
fn dissection_fills_less_than_minimum_degree_on_slabs() {
    // Here 0.79 and 0.77 (an ordering applied inverted: 10.4); at the
    // sizes of the default campaign 0.57 on a four-layer slab and 0.79
    // on the whole mirrored one (docs/benchmarks.md, session 32).
    let slab = SlabMesh::new(plan(9, 1), 0.0075, 4).unwrap();
    for (name, mesh) in [
        ("four layers", slab.build(ElementKind::Tet10).unwrap()),
        (
            "mirrored",
            slab.build_symmetric(ElementKind::Tet10).unwrap(),
        ),
    ] {
        let (_, own, minimum_degree) = fill(mesh, Formulation::Solid);
        let ratio = own as f64 / minimum_degree as f64;
        assert!(ratio < 0.85, "{name}: {own} against {minimum_degree}");
    }
}

#[test]
fn dissection_fills_no_more_than_minimum_degree_on_a_fine_plane() {
    // Here 0.89.
    let mesh = plan(9, 4).build(ElementKind::Tri6).unwrap();
    let (_, own, minimum_degree) = fill(mesh, Formulation::PlaneStrain { thickness: 0.0075 });
    assert!(own <= minimum_degree, "{own} against {minimum_degree}");
}

#[test]
fn the_solution_does_not_depend_on_the_ordering() {
    // The same K_ff factorised by faer with minimum degree.
    let slab = SlabMesh::new(plan(5, 1), 0.0075, 2).unwrap();
    let (mut problem, _, _) = fill(slab.build(ElementKind::Tet10).unwrap(), Formulation::Solid);
    let materials = Materials::homogeneous(Material::new(25.0e3, 0.48).unwrap());
    problem.factorize(&materials).unwrap();
    let mut loads = vec![0.0; problem.mesh().dof_count()];
    let front = problem.mesh().nodes_on_face(Face::Front);
    for &n in &front {
        loads[3 * n + 1] = 1e-3;
        loads[3 * n + 2] = -2e-4;
    }
    let own = problem.solve(&loads).unwrap().displacement;
    let free = problem.free_dofs().to_vec();
    let reduced = problem.reduced_stiffness();
    let llt = reduced.sp_cholesky(Side::Lower).unwrap();
    let rhs = faer::Mat::from_fn(free.len(), 1, |i, _| loads[free[i]]);
    let other = llt.solve(&rhs);
    let scale = own.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.0);
    for (i, &d) in free.iter().enumerate() {
        assert!((own[d] - other[(i, 0)]).abs() < 1e-10 * scale);
    }
}
