//! Bad input gives a typed error, never a panic or a NaN.

use needle_fem::{
    Assembler, Dirichlet, ElementKind, FemError, Formulation, LineDensity, LinearProblem, Locator,
    Material, Materials, Mesh, RectangleMesh, Support,
};

const PLANE: Formulation = Formulation::PlaneStrain { thickness: 0.01 };

fn square(kind: ElementKind) -> Mesh<2> {
    RectangleMesh::uniform(1.0, 1.0, 3, 3)
        .unwrap()
        .build(kind)
        .unwrap()
}

#[test]
fn youngs_modulus_must_be_positive_and_finite() {
    for e in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(
            matches!(
                Material::new(e, 0.3),
                Err(FemError::YoungsModulus { region: 0, .. })
            ),
            "{e}"
        );
    }
    assert!(matches!(
        Materials::from_parameters(&[(1.0, 0.3), (-2.0, 0.3)]),
        Err(FemError::YoungsModulus { region: 1, .. })
    ));
}

#[test]
fn poisson_ratio_must_lie_in_its_open_interval() {
    for nu in [0.5, 0.7, -1.0, -1.5, f64::NAN, f64::NEG_INFINITY] {
        assert!(
            matches!(Material::new(1.0, nu), Err(FemError::PoissonRatio { .. })),
            "{nu}"
        );
    }
    assert!(Material::new(1.0, 0.4999).is_ok());
    assert!(Material::new(1.0, -0.99).is_ok());
}

#[test]
fn no_dirichlet_condition_is_reported_as_unconstrained() {
    let assembler = Assembler::new(square(ElementKind::Tri3), PLANE).unwrap();
    let err = LinearProblem::new(assembler, vec![], Dirichlet::new()).unwrap_err();
    assert_eq!(err, FemError::Unconstrained { free_modes: 3 });
}

#[test]
fn one_pinned_node_leaves_the_rotation_free() {
    let mesh = square(ElementKind::Tri6);
    let mut d = Dirichlet::new();
    d.fix_nodes(&mesh, &[0]).unwrap();
    let err = LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], d).unwrap_err();
    assert_eq!(err, FemError::Unconstrained { free_modes: 1 });
}

#[test]
fn rollers_in_one_direction_leave_a_translation_free() {
    let mesh = square(ElementKind::Tri3);
    let back = mesh.nodes_on_face(needle_fem::Face::Back);
    let mut d = Dirichlet::new();
    d.set_nodes(&mesh, &back, 1, 0.0).unwrap();
    let err = LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], d).unwrap_err();
    assert_eq!(err, FemError::Unconstrained { free_modes: 1 });
}

#[test]
fn a_foundation_alone_constrains_the_body() {
    let mesh = square(ElementKind::Tri3);
    let support = Support::Foundation {
        stiffness: [1.0e3, 1.0e3],
    };
    let mut problem = LinearProblem::new(
        Assembler::new(mesh, PLANE).unwrap(),
        vec![support],
        Dirichlet::new(),
    )
    .unwrap();
    problem
        .factorize(&Materials::homogeneous(Material::new(1.0e4, 0.3).unwrap()))
        .unwrap();
    // Uniform body force against uniform springs: u = b h / k everywhere would
    // hold for a free body on springs (no strain), here checked via the total.
    let mut loads = vec![0.0; problem.mesh().dof_count()];
    needle_fem::load::add_body_force(problem.mesh(), PLANE, &mut loads, |_| [0.0, 2.0e3]).unwrap();
    let u = problem.solve(&loads).unwrap().displacement;
    let expected = 2.0e3 * 0.01 / 1.0e3;
    for n in 0..problem.mesh().node_count() {
        assert!(
            u[2 * n].abs() < 1e-12 && (u[2 * n + 1] - expected).abs() < 1e-9 * expected,
            "node {n}: {:?}",
            &u[2 * n..2 * n + 2]
        );
    }
}

#[test]
fn inverted_and_degenerate_elements_are_rejected() {
    let nodes = vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
    let inverted = Mesh::new(ElementKind::Tri3, nodes.clone(), vec![0, 2, 1], vec![0]);
    assert!(matches!(
        inverted,
        Err(FemError::DegenerateElement { element: 0, .. })
    ));
    let flat = Mesh::new(
        ElementKind::Tri3,
        vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]],
        vec![0, 1, 2],
        vec![0],
    );
    assert!(matches!(
        flat,
        Err(FemError::DegenerateElement { element: 0, .. })
    ));
    // A T6 whose mid-edge node is pushed past the opposite corner folds.
    let folded = Mesh::new(
        ElementKind::Tri6,
        vec![
            [0.0, 0.0],
            [1.0, 0.0],
            [0.0, 1.0],
            [0.5, 1.2],
            [0.5, 0.5],
            [0.0, 0.5],
        ],
        vec![0, 1, 2, 3, 4, 5],
        vec![0],
    );
    assert!(matches!(folded, Err(FemError::DegenerateElement { .. })));
}

#[test]
fn non_finite_inputs_are_rejected() {
    let nan_node = Mesh::new(
        ElementKind::Tri3,
        vec![[0.0, 0.0], [f64::NAN, 0.0], [0.0, 1.0]],
        vec![0, 1, 2],
        vec![0],
    );
    assert!(matches!(nan_node, Err(FemError::InvalidValue { .. })));
    assert!(matches!(
        RectangleMesh::uniform(f64::INFINITY, 1.0, 2, 2),
        Err(FemError::InvalidValue { .. })
    ));
    assert!(matches!(
        Dirichlet::new().set(0, f64::NAN),
        Err(FemError::InvalidValue { .. })
    ));

    let mesh = square(ElementKind::Tri6);
    let fixed = Dirichlet::fixed_face(&mesh, needle_fem::Face::Back);
    let locator = Locator::new(&mesh);
    let mut loads = vec![0.0; mesh.dof_count()];
    let nan = needle_fem::load::add_point_force(&locator, &mut loads, [0.5, 0.5], [f64::NAN, 0.0]);
    assert!(matches!(nan, Err(FemError::InvalidValue { .. })));
    let bad_density = |_s: f64| [f64::INFINITY, 0.0];
    let shaft = LineDensity::Function {
        density: &bad_density,
        breakpoints: vec![],
    };
    let err = needle_fem::load::add_line_load(&locator, &mut loads, [0.5, 0.0], [0.5, 0.5], &shaft);
    assert!(matches!(err, Err(FemError::InvalidValue { .. })));
    drop(locator);

    let mut problem =
        LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], fixed).unwrap();
    problem
        .factorize(&Materials::homogeneous(Material::new(1.0, 0.3).unwrap()))
        .unwrap();
    let mut loads = vec![0.0; problem.mesh().dof_count()];
    loads[3] = f64::NAN;
    assert!(matches!(
        problem.solve(&loads),
        Err(FemError::InvalidValue { .. })
    ));
    assert!(matches!(
        problem.solve(&[0.0; 3]),
        Err(FemError::DimensionMismatch { .. })
    ));
}

#[test]
fn solving_before_factorising_is_an_error() {
    let mesh = square(ElementKind::Tri3);
    let fixed = Dirichlet::fixed_face(&mesh, needle_fem::Face::Back);
    let problem = LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], fixed).unwrap();
    let loads = vec![0.0; problem.mesh().dof_count()];
    assert!(matches!(
        problem.solve(&loads),
        Err(FemError::Factorization(_))
    ));
}

#[test]
fn missing_material_and_out_of_range_indices() {
    let mut mesh = square(ElementKind::Tri3);
    mesh.assign_regions(|c| usize::from(c[0] > 0.5));
    let assembler = Assembler::new(mesh.clone(), PLANE).unwrap();
    let one = Materials::homogeneous(Material::new(1.0, 0.3).unwrap());
    assert!(matches!(
        assembler.stiffness(&one),
        Err(FemError::MissingMaterial { region: 1, .. })
    ));
    let mut d = Dirichlet::new();
    d.set(10_000, 0.0).unwrap();
    assert!(matches!(
        LinearProblem::new(assembler, vec![], d),
        Err(FemError::DofOutOfRange { .. })
    ));
    assert!(matches!(
        Mesh::new(ElementKind::Tri3, vec![[0.0, 0.0]], vec![0, 1, 2], vec![0]),
        Err(FemError::NodeOutOfRange { .. })
    ));
    assert!(matches!(
        Assembler::new(mesh, Formulation::Solid),
        Err(FemError::InvalidMesh(_))
    ));
}

#[test]
fn points_outside_the_mesh_are_reported_with_their_index() {
    let mesh = square(ElementKind::Tri6);
    let locator = Locator::new(&mesh);
    let err = locator
        .interpolation_matrix(&[[0.5, 0.5], [1.5, 0.5]], &[0, 1])
        .unwrap_err();
    assert!(matches!(err, FemError::PointOutsideMesh { index: 1, .. }));
    assert!(locator.locate([f64::NAN, 0.0]).is_none());
}
