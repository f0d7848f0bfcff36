//! Invariants that hold on any valid mesh: element null spaces, the patch
//! test, equilibrium, interpolation exactness, and the derivatives of K.

mod common;

use common::{dense, distorted_cube, distorted_square, solve};
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Formulation, LinearProblem, Locator, Material, Materials,
    Mesh, Parameter,
};
use proptest::prelude::*;

const PLANE: Formulation = Formulation::PlaneStrain { thickness: 0.01 };

fn one_element_stiffness<const D: usize>(
    mesh: &Mesh<D>,
    e: usize,
    formulation: Formulation,
    material: Material,
) -> nalgebra::DMatrix<f64> {
    let nodes: Vec<usize> = mesh.element(e).to_vec();
    let coordinates: Vec<[f64; D]> = nodes.iter().map(|&n| mesh.node(n)).collect();
    let single = Mesh::new(
        mesh.kind(),
        coordinates,
        (0..nodes.len()).collect(),
        vec![0],
    )
    .unwrap();
    let k = Assembler::new(single, formulation)
        .unwrap()
        .stiffness(&Materials::homogeneous(material))
        .unwrap();
    dense(&k)
}

/// Number of eigenvalues below `1e-10` of the largest, and the smallest
/// eigenvalue relative to the largest.
fn null_space(k: &nalgebra::DMatrix<f64>) -> (usize, f64) {
    let eigen = k.clone().symmetric_eigenvalues();
    let largest = eigen.iter().copied().fold(0.0, f64::max);
    let smallest = eigen.iter().copied().fold(f64::INFINITY, f64::min);
    (
        eigen.iter().filter(|&&l| l.abs() < 1e-10 * largest).count(),
        smallest / largest,
    )
}

fn symmetric_error(k: &nalgebra::DMatrix<f64>) -> f64 {
    (k - k.transpose()).amax() / k.amax()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    #[test]
    fn triangle_stiffness_is_symmetric_psd_with_three_rigid_modes(
        seed in any::<u64>(), e in 0usize..18, nu in -0.9f64..0.49, quadratic in any::<bool>()
    ) {
        let kind = if quadratic { ElementKind::Tri6 } else { ElementKind::Tri3 };
        let mesh = distorted_square(kind, 3, 0.2, seed);
        let k = one_element_stiffness(&mesh, e, PLANE, Material::new(1e4, nu).unwrap());
        prop_assert!(symmetric_error(&k) < 1e-13);
        let (zero, smallest) = null_space(&k);
        prop_assert_eq!(zero, 3);
        prop_assert!(smallest > -1e-12);
    }

    #[test]
    fn tetrahedron_stiffness_is_symmetric_psd_with_six_rigid_modes(
        seed in any::<u64>(), e in 0usize..48, nu in -0.9f64..0.49, quadratic in any::<bool>()
    ) {
        let kind = if quadratic { ElementKind::Tet10 } else { ElementKind::Tet4 };
        let mesh = distorted_cube(kind, 2, 0.25, seed);
        let k = one_element_stiffness(&mesh, e, Formulation::Solid, Material::new(1e4, nu).unwrap());
        prop_assert!(symmetric_error(&k) < 1e-13);
        let (zero, smallest) = null_space(&k);
        prop_assert_eq!(zero, 6);
        prop_assert!(smallest > -1e-12);
    }

    #[test]
    fn patch_test_2d(seed in any::<u64>(), coefficients in prop::array::uniform6(-1.0f64..1.0), quadratic in any::<bool>()) {
        let kind = if quadratic { ElementKind::Tri6 } else { ElementKind::Tri3 };
        let mesh = distorted_square(kind, 4, 0.2, seed);
        let affine = |p: [f64; 2]| {
            let c = &coefficients;
            [c[0] + c[1] * p[0] + c[2] * p[1], c[3] + c[4] * p[0] + c[5] * p[1]]
        };
        patch_test(mesh, PLANE, affine)?;
    }

    #[test]
    fn patch_test_3d(seed in any::<u64>(), coefficients in prop::array::uniform12(-1.0f64..1.0), quadratic in any::<bool>()) {
        let kind = if quadratic { ElementKind::Tet10 } else { ElementKind::Tet4 };
        let mesh = distorted_cube(kind, 2, 0.25, seed);
        let affine = |p: [f64; 3]| {
            let c = &coefficients;
            std::array::from_fn(|i| c[4 * i] + c[4 * i + 1] * p[0] + c[4 * i + 2] * p[1] + c[4 * i + 3] * p[2])
        };
        patch_test(mesh, Formulation::Solid, affine)?;
    }

    #[test]
    fn interpolation_reproduces_polynomials_of_the_element_degree(
        seed in any::<u64>(), c in prop::array::uniform6(-1.0f64..1.0), points in prop::collection::vec((0.0f64..1.0, 0.0f64..1.0), 1..8)
    ) {
        for kind in [ElementKind::Tri3, ElementKind::Tri6] {
            let mesh = distorted_square(kind, 3, 0.2, seed);
            let field = |p: [f64; 2]| {
                let quadratic = if kind == ElementKind::Tri6 { c[3] * p[0] * p[0] + c[4] * p[0] * p[1] + c[5] * p[1] * p[1] } else { 0.0 };
                [c[0] + c[1] * p[0] + c[2] * p[1] + quadratic, c[2] - c[0] * p[1] + quadratic]
            };
            let nodal: Vec<f64> = mesh.nodes().iter().flat_map(|&p| field(p)).collect();
            let locator = Locator::new(&mesh);
            let targets: Vec<[f64; 2]> = points.iter().map(|&(x, y)| [x, y]).collect();
            let h = locator.interpolation_matrix(&targets, &[0, 1]).unwrap();
            let hu = dense(&h) * nalgebra::DVector::from_column_slice(&nodal);
            for (k, &p) in targets.iter().enumerate() {
                let exact = field(p);
                let direct = locator.interpolate(&nodal, p).unwrap();
                for i in 0..2 {
                    prop_assert!((hu[2 * k + i] - exact[i]).abs() < 1e-12, "{:?} at {:?}: {} vs {}", kind, p, hu[2 * k + i], exact[i]);
                    prop_assert!((direct[i] - exact[i]).abs() < 1e-12);
                }
            }
        }
    }
}

/// Prescribes `affine` on the boundary, solves with no load, and checks that
/// every node reproduces it (the displacement patch test).
fn patch_test<const D: usize>(
    mesh: Mesh<D>,
    formulation: Formulation,
    affine: impl Fn([f64; D]) -> [f64; D],
) -> Result<(), TestCaseError> {
    let (lo, hi) = mesh.bounding_box();
    let on_boundary =
        |p: [f64; D]| (0..D).any(|i| (p[i] - lo[i]).abs() < 1e-12 || (p[i] - hi[i]).abs() < 1e-12);
    let mut dirichlet = Dirichlet::new();
    for n in mesh.nodes_where(on_boundary) {
        let u = affine(mesh.node(n));
        for i in 0..D {
            dirichlet.set(n * D + i, u[i]).unwrap();
        }
    }
    let exact: Vec<f64> = mesh.nodes().iter().flat_map(|&p| affine(p)).collect();
    let material = Material::new(2.0e4, 0.3).unwrap();
    let (_, displacement) = solve(
        mesh,
        formulation,
        dirichlet,
        material,
        &vec![0.0; exact.len()],
    );
    let error = displacement
        .iter()
        .zip(&exact)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    prop_assert!(error < 1e-11, "patch test error {error:e}");
    Ok(())
}

/// The supports hold the body: reactions plus applied loads sum to zero.
#[test]
fn reactions_balance_applied_loads() {
    let mesh = distorted_square(ElementKind::Tri6, 4, 0.2, 7);
    let dirichlet = Dirichlet::fixed_face(&mesh, needle_fem::Face::Back);
    let mut loads = vec![0.0; mesh.dof_count()];
    let locator = Locator::new(&mesh);
    needle_fem::load::add_point_force(&locator, &mut loads, [0.37, 0.41], [0.3, -1.2]).unwrap();
    let density = |s: f64| [0.1 * s, 2.0 + s * s];
    let shaft = needle_fem::LineDensity::Function {
        density: &density,
        breakpoints: vec![],
    };
    let applied_line =
        needle_fem::load::add_line_load(&locator, &mut loads, [0.5, 0.0], [0.52, 0.7], &shaft)
            .unwrap();
    drop(locator);
    let mut problem =
        LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], dirichlet).unwrap();
    problem
        .factorize(&Materials::homogeneous(Material::new(2.5e4, 0.48).unwrap()))
        .unwrap();
    let solution = problem.solve(&loads).unwrap();
    let applied = [0.3 + applied_line[0], -1.2 + applied_line[1]];
    for i in 0..2 {
        let reaction: f64 = solution.reactions.iter().skip(i).step_by(2).sum();
        let load: f64 = loads.iter().skip(i).step_by(2).sum();
        assert!((load - applied[i]).abs() < 1e-12 * applied[i].abs().max(1.0));
        assert!(
            (reaction + applied[i]).abs() < 1e-9 * applied[i].abs().max(1.0),
            "axis {i}: {reaction} vs {}",
            applied[i]
        );
    }
    // Nodal forces K u equal the loads at free dofs and the reactions at fixed ones.
    let ku = problem.nodal_forces(&solution.displacement).unwrap();
    for d in 0..ku.len() {
        let expected = if problem.reduced_index(d).is_some() {
            loads[d]
        } else {
            loads[d] + solution.reactions[d]
        };
        assert!((ku[d] - expected).abs() < 1e-9, "dof {d}");
    }
}

#[test]
fn stiffness_derivatives_match_finite_differences() {
    for formulation in [PLANE, Formulation::PlaneStress { thickness: 0.01 }] {
        let mesh = distorted_square(ElementKind::Tri6, 2, 0.2, 3);
        let assembler = Assembler::new(mesh, formulation).unwrap();
        let (e, nu) = (2.5e4, 0.45);
        let k = |e: f64, nu: f64| {
            dense(
                &assembler
                    .stiffness(&Materials::homogeneous(Material::new(e, nu).unwrap()))
                    .unwrap(),
            )
        };
        let materials = Materials::homogeneous(Material::new(e, nu).unwrap());
        let d_e = dense(
            &assembler
                .stiffness_derivative(&materials, Parameter::YoungsModulus, None)
                .unwrap(),
        );
        let d_nu = dense(
            &assembler
                .stiffness_derivative(&materials, Parameter::PoissonRatio, None)
                .unwrap(),
        );
        assert!((&d_e - k(e, nu) / e).amax() < 1e-12 * d_e.amax());
        let step = 1e-6;
        let fd = (k(e, nu + step) - k(e, nu - step)) / (2.0 * step);
        assert!(
            (&d_nu - &fd).amax() < 1e-6 * d_nu.amax(),
            "{}",
            (&d_nu - &fd).amax() / d_nu.amax()
        );
    }
    let mesh = distorted_cube(ElementKind::Tet4, 1, 0.0, 1);
    let assembler = Assembler::new(mesh, Formulation::Solid).unwrap();
    let k = |nu: f64| {
        dense(
            &assembler
                .stiffness(&Materials::homogeneous(Material::new(1.0, nu).unwrap()))
                .unwrap(),
        )
    };
    let materials = Materials::homogeneous(Material::new(1.0, 0.3).unwrap());
    let d_nu = dense(
        &assembler
            .stiffness_derivative(&materials, Parameter::PoissonRatio, None)
            .unwrap(),
    );
    let fd = (k(0.3 + 1e-6) - k(0.3 - 1e-6)) / 2e-6;
    assert!((&d_nu - &fd).amax() < 1e-6 * d_nu.amax());
}

/// The homogeneous body's $K = a K_\lambda + \mu K_\mu$ against every
/// element's integral with its own $D$, for two materials in turn on one
/// assembler (the second reuses $K_\lambda$ and $K_\mu$).
fn homogeneous_matches_elementwise<const D: usize>(
    mesh: Mesh<D>,
    formulation: Formulation,
    materials: [(f64, f64); 2],
) {
    let assembler = Assembler::new(mesh, formulation).unwrap();
    for (e, nu) in materials {
        let material = Material::new(e, nu).unwrap();
        let fast = dense(
            &assembler
                .stiffness(&Materials::homogeneous(material))
                .unwrap(),
        );
        let mut k = assembler.pattern().zeros();
        assembler
            .assemble_into(&[Some(material.constitutive(formulation))], &mut k)
            .unwrap();
        let elementwise = dense(&k);
        let error = (&fast - &elementwise).amax() / elementwise.amax();
        assert!(error < 1e-13, "{formulation:?} E {e} nu {nu}: {error:e}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(8))]
    #[test]
    fn homogeneous_stiffness_is_the_lame_combination(
        e in 1.0e3..1.0e6f64,
        nu in 0.0..0.499f64,
        e2 in 1.0e3..1.0e6f64,
        nu2 in -0.5..0.499f64,
    ) {
        for kind in [ElementKind::Tri3, ElementKind::Tri6] {
            for formulation in [PLANE, Formulation::PlaneStress { thickness: 0.01 }] {
                homogeneous_matches_elementwise(
                    distorted_square(kind, 3, 0.2, 11),
                    formulation,
                    [(e, nu), (e2, nu2)],
                );
            }
        }
        for kind in [ElementKind::Tet4, ElementKind::Tet10] {
            homogeneous_matches_elementwise(
                distorted_cube(kind, 2, 0.2, 13),
                Formulation::Solid,
                [(e, nu), (e2, nu2)],
            );
        }
    }
}

#[test]
fn region_derivatives_sum_to_the_homogeneous_derivative() {
    let mut mesh = distorted_square(ElementKind::Tri3, 4, 0.2, 5);
    mesh.assign_regions(|c| usize::from(c[1] > 0.5));
    let assembler = Assembler::new(mesh, PLANE).unwrap();
    let materials = Materials::from_parameters(&[(2.0e4, 0.45), (2.0e4, 0.45)]).unwrap();
    let whole = dense(
        &assembler
            .stiffness_derivative(&materials, Parameter::PoissonRatio, None)
            .unwrap(),
    );
    let parts = dense(
        &assembler
            .stiffness_derivative(&materials, Parameter::PoissonRatio, Some(0))
            .unwrap(),
    ) + dense(
        &assembler
            .stiffness_derivative(&materials, Parameter::PoissonRatio, Some(1))
            .unwrap(),
    );
    assert!((whole - parts).amax() < 1e-12 * assembler.pattern().nnz() as f64);
}

/// A needle along the slab's mid-plane lies on element faces (two layers):
/// every piece must be counted once, and the nodal loads must sum to the
/// integral of the density.
#[test]
fn line_load_on_element_faces_is_counted_once_in_3d() {
    let plan = needle_fem::RectangleMesh::uniform(0.075, 0.075, 6, 6).unwrap();
    for kind in [ElementKind::Tet4, ElementKind::Tet10] {
        let mesh = needle_fem::SlabMesh::new(plan.clone(), 0.0075, 2)
            .unwrap()
            .build(kind)
            .unwrap();
        let locator = Locator::new(&mesh);
        let mut loads = vec![0.0; mesh.dof_count()];
        // Along a grid line x = 0.0375 in the mid-plane z = 0, with a tip peak.
        let density = |s: f64| [0.0, if s > 0.03 { 40.0 } else { 20.0 }, 0.0];
        let shaft = needle_fem::LineDensity::Function {
            density: &density,
            breakpoints: vec![0.03],
        };
        let total = needle_fem::load::add_line_load(
            &locator,
            &mut loads,
            [0.0375, 0.0, 0.0],
            [0.0375, 0.04, 0.0],
            &shaft,
        )
        .unwrap();
        let expected = 20.0 * 0.03 + 40.0 * 0.01;
        assert!((total[1] - expected).abs() < 1e-12, "{kind:?}: {total:?}");
        let sum: f64 = loads.iter().skip(1).step_by(3).sum();
        assert!((sum - expected).abs() < 1e-12, "{kind:?}: nodal sum {sum}");
        // The load acts on the needle's line: its first moment about x is zero.
        let moment_x: f64 = (0..mesh.node_count())
            .map(|n| loads[3 * n + 1] * (mesh.node(n)[0] - 0.0375))
            .sum();
        assert!(moment_x.abs() < 1e-12, "{kind:?}: moment {moment_x}");
    }
}

/// A line load crossing elements obliquely in 2-D: the nodal loads have the
/// resultant and the first moment of the density.
#[test]
fn oblique_line_load_has_the_right_resultant_and_moment() {
    let mesh = distorted_square(ElementKind::Tri6, 5, 0.25, 11);
    let locator = Locator::new(&mesh);
    let mut loads = vec![0.0; mesh.dof_count()];
    let (start, end): ([f64; 2], [f64; 2]) = ([0.1, 0.05], [0.83, 0.91]);
    let length = (end[0] - start[0]).hypot(end[1] - start[1]);
    let density = |s: f64| [1.0 + s, 0.5 * s * s];
    let shaft = needle_fem::LineDensity::Function {
        density: &density,
        breakpoints: vec![],
    };
    let total = needle_fem::load::add_line_load(&locator, &mut loads, start, end, &shaft).unwrap();
    let exact_x = length + length * length / 2.0;
    let exact_y = length.powi(3) / 6.0;
    assert!((total[0] - exact_x).abs() < 1e-12 && (total[1] - exact_y).abs() < 1e-12);
    // Moment about the start point of the y-force: int q_y(s) * x(s) ds.
    let dir = [(end[0] - start[0]) / length, (end[1] - start[1]) / length];
    let exact_moment = 0.5 * dir[0] * length.powi(4) / 4.0;
    let moment: f64 = (0..mesh.node_count())
        .map(|n| loads[2 * n + 1] * (mesh.node(n)[0] - start[0]))
        .sum();
    assert!(
        (moment - exact_moment).abs() < 1e-12,
        "{moment} vs {exact_moment}"
    );
}

/// Markers on the top face of a Tet10 slab: the interpolation operator
/// reproduces a quadratic field exactly.
#[test]
fn top_face_marker_operator_reproduces_quadratic_fields() {
    let markers = needle_fem::MarkerGrid::uniform(5, 5, (0.005, 0.005), (0.07, 0.07));
    let plan = needle_fem::RectangleMesh::with_markers(0.075, 0.075, &markers, 1).unwrap();
    let slab = needle_fem::SlabMesh::new(plan, 0.0075, 2).unwrap();
    let mesh = slab.build(ElementKind::Tet10).unwrap();
    // Every marker is a mesh node.
    for p in markers.points() {
        let n = mesh.nearest_node([p[0], p[1], slab.top()]).unwrap();
        let q = mesh.node(n);
        assert!(
            (q[0] - p[0]).abs() < 1e-12
                && (q[1] - p[1]).abs() < 1e-12
                && (q[2] - slab.top()).abs() < 1e-12
        );
    }
    let field = |p: [f64; 3]| [p[0] * p[1] + p[2], p[1] * p[1] - 2.0 * p[0] * p[2], p[0]];
    let nodal: Vec<f64> = mesh.nodes().iter().flat_map(|&p| field(p)).collect();
    let locator = Locator::new(&mesh);
    let points: Vec<[f64; 3]> = (0..7)
        .map(|k| [0.003 + 0.01 * k as f64, 0.07 - 0.009 * k as f64, slab.top()])
        .collect();
    let h = dense(&locator.interpolation_matrix(&points, &[0, 1]).unwrap());
    let hu = h * nalgebra::DVector::from_column_slice(&nodal);
    for (k, &p) in points.iter().enumerate() {
        let exact = field(p);
        assert!((hu[2 * k] - exact[0]).abs() < 1e-14 && (hu[2 * k + 1] - exact[1]).abs() < 1e-14);
    }
}

/// A body on back-face springs, pulled by a uniform traction on the same
/// face, translates rigidly by t / k: the consistent spring matrix and the
/// consistent traction load share the edge shape functions.
#[test]
fn boundary_springs_match_consistent_tractions() {
    let mesh = needle_fem::RectangleMesh::uniform(1.0, 1.0, 4, 4)
        .unwrap()
        .build(ElementKind::Tri6)
        .unwrap();
    let back = mesh.facets_on_face(needle_fem::Face::Back);
    let spring = [1.0e3, 4.0e3];
    let support = needle_fem::Support::Boundary {
        facets: back.clone(),
        stiffness: spring,
    };
    let mut loads = vec![0.0; mesh.dof_count()];
    needle_fem::load::add_traction(&mesh, PLANE, &mut loads, &back, |_| [2.0, -5.0]).unwrap();
    let mut problem = LinearProblem::new(
        Assembler::new(mesh, PLANE).unwrap(),
        vec![support],
        Dirichlet::new(),
    )
    .unwrap();
    problem
        .factorize(&Materials::homogeneous(Material::new(1.0e4, 0.45).unwrap()))
        .unwrap();
    let u = problem.solve(&loads).unwrap().displacement;
    let expected = [2.0 / spring[0], -5.0 / spring[1]];
    for n in 0..problem.mesh().node_count() {
        for i in 0..2 {
            assert!(
                (u[2 * n + i] - expected[i]).abs() < 1e-10 * expected[i].abs(),
                "node {n}: {:?}",
                &u[2 * n..2 * n + 2]
            );
        }
    }
}

/// Scaling a support's stiffness after set-up gives the problem built with
/// the scaled stiffness (to round-off), and the supports report it.
#[test]
fn scaled_supports_match_a_problem_built_with_them() {
    let mesh = distorted_square(ElementKind::Tri6, 3, 0.2, 5);
    let back = mesh.facets_on_face(needle_fem::Face::Back);
    let supports = |k_back: f64, k_area: f64| {
        vec![
            needle_fem::Support::Boundary {
                facets: back.clone(),
                stiffness: [k_back, 2.0 * k_back],
            },
            needle_fem::Support::Foundation {
                stiffness: [k_area; 2],
            },
        ]
    };
    let materials = Materials::homogeneous(Material::new(1.0e4, 0.45).unwrap());
    let loads: Vec<f64> = (0..mesh.dof_count())
        .map(|d| (0.7 * d as f64).cos() * 1e-3)
        .collect();
    let mut scaled = LinearProblem::new(
        Assembler::new(mesh.clone(), PLANE).unwrap(),
        supports(1.0e3, 50.0),
        Dirichlet::new(),
    )
    .unwrap();
    scaled.scale_support(0, 30.0).unwrap();
    scaled.scale_support(1, 0.2).unwrap();
    scaled.factorize(&materials).unwrap();
    let mut fresh = LinearProblem::new(
        Assembler::new(mesh, PLANE).unwrap(),
        supports(3.0e4, 10.0),
        Dirichlet::new(),
    )
    .unwrap();
    fresh.factorize(&materials).unwrap();
    let a = scaled.solve(&loads).unwrap().displacement;
    let b = fresh.solve(&loads).unwrap().displacement;
    let size = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-10 * size));
    assert_eq!(scaled.supports(), fresh.supports());
    // The change matters: the unscaled problem answers differently.
    let mut unscaled = scaled.clone();
    unscaled.scale_support(0, 1.0 / 30.0).unwrap();
    unscaled.factorize(&materials).unwrap();
    let c = unscaled.solve(&loads).unwrap().displacement;
    assert!(a.iter().zip(&c).any(|(x, y)| (x - y).abs() > 1e-3 * size));
    for bad in [0.0, -1.0, f64::NAN] {
        assert!(scaled.scale_support(0, bad).is_err());
    }
    assert!(scaled.scale_support(2, 2.0).is_err());
}

/// `clone_from` between clones of one problem copies supports, prescribed
/// values and factor into the target's own storage and answers as the
/// source; from a problem of another lineage it is a plain clone.
#[test]
fn clone_from_answers_as_the_source_in_the_target_s_storage() {
    let mesh = distorted_square(ElementKind::Tri6, 3, 0.2, 5);
    let back = mesh.facets_on_face(needle_fem::Face::Back);
    let support = vec![needle_fem::Support::Boundary {
        facets: back,
        stiffness: [1.0e3, 2.0e3],
    }];
    let left = Dirichlet::fixed_face(&mesh, needle_fem::Face::Left);
    let loads: Vec<f64> = (0..mesh.dof_count())
        .map(|d| (0.3 * d as f64).sin() * 1e-3)
        .collect();
    let template = LinearProblem::new(
        Assembler::new(mesh.clone(), PLANE).unwrap(),
        support.clone(),
        left.clone(),
    )
    .unwrap();
    let mut source = template.clone();
    source.scale_support(0, 7.0).unwrap();
    let (dof, _) = left.iter().next().unwrap();
    source.set_prescribed(dof, 1e-4).unwrap();
    source
        .factorize(&Materials::homogeneous(Material::new(2.0e4, 0.45).unwrap()))
        .unwrap();
    let expected = source.solve(&loads).unwrap();
    let mut target = template.clone();
    target
        .factorize(&Materials::homogeneous(Material::new(1.0e4, 0.3).unwrap()))
        .unwrap();
    let storage = target.reduced_stiffness().val().as_ptr();
    target.clone_from(&source);
    assert_eq!(target.reduced_stiffness().val().as_ptr(), storage);
    assert_eq!(target.supports(), source.supports());
    assert_eq!(target.dirichlet(), source.dirichlet());
    let same = |s: &needle_fem::Solution| {
        s.displacement == expected.displacement && s.reactions == expected.reactions
    };
    assert!(same(&target.solve(&loads).unwrap()));
    // Refactorised after the copy, it still answers as the source.
    target
        .factorize(&Materials::homogeneous(Material::new(2.0e4, 0.45).unwrap()))
        .unwrap();
    assert!(same(&target.solve(&loads).unwrap()));
    // Another lineage (its own symbolic analysis): a plain clone.
    let mut other = LinearProblem::new(
        Assembler::new(mesh, PLANE).unwrap(),
        vec![],
        Dirichlet::fixed_face(
            &distorted_square(ElementKind::Tri6, 3, 0.2, 5),
            needle_fem::Face::Back,
        ),
    )
    .unwrap();
    other.clone_from(&source);
    assert!(same(&other.solve(&loads).unwrap()));
}

/// Refactorising with new materials reuses the pattern and gives the same
/// answer as a fresh problem; displacement scales as 1/E.
#[test]
fn refactorisation_with_new_materials_and_many_right_hand_sides() {
    let mesh = distorted_square(ElementKind::Tri6, 3, 0.2, 2);
    let fixed = Dirichlet::fixed_face(&mesh, needle_fem::Face::Back);
    let loads_a: Vec<f64> = (0..mesh.dof_count())
        .map(|d| if d % 2 == 0 { 1e-3 } else { -2e-3 })
        .collect();
    let loads_b: Vec<f64> = (0..mesh.dof_count())
        .map(|d| (d as f64).sin() * 1e-3)
        .collect();
    let mut problem =
        LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], fixed).unwrap();
    problem
        .factorize(&Materials::homogeneous(Material::new(1.0e4, 0.45).unwrap()))
        .unwrap();
    let first = problem.solve_many(&[&loads_a, &loads_b]).unwrap();
    problem
        .factorize(&Materials::homogeneous(Material::new(2.0e4, 0.45).unwrap()))
        .unwrap();
    let second = problem.solve(&loads_b).unwrap();
    let scale = first[1]
        .displacement
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    for (a, b) in first[1].displacement.iter().zip(&second.displacement) {
        assert!((a - 2.0 * b).abs() < 1e-10 * scale);
    }
    let single = problem.solve(&loads_a).unwrap();
    problem
        .factorize(&Materials::homogeneous(Material::new(1.0e4, 0.45).unwrap()))
        .unwrap();
    let again = problem.solve(&loads_a).unwrap();
    let scale_a = first[0]
        .displacement
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        again
            .displacement
            .iter()
            .zip(&first[0].displacement)
            .all(|(x, y)| (x - y).abs() < 1e-13 * scale_a)
    );
    let scale = again
        .displacement
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        single
            .displacement
            .iter()
            .zip(&again.displacement)
            .all(|(s, a)| (2.0 * s - a).abs() < 1e-10 * scale)
    );
}

/// A problem factorised again overwrites the last factor in place: its
/// solves equal, to the bit, those of a fresh copy factorised once with the
/// same materials, whatever it held before (another modulus and Poisson's
/// ratio), on a factor small enough for faer's simplicial kernel and on one
/// large enough for its supernodal kernel.
#[test]
fn a_factor_overwritten_in_place_solves_as_a_fresh_one_to_the_bit() {
    use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
    for (n, supernodal) in [(3, false), (40, true)] {
        let mesh = distorted_square(ElementKind::Tri6, n, 0.2, 5);
        let fixed = Dirichlet::fixed_face(&mesh, needle_fem::Face::Back);
        let before = Materials::homogeneous(Material::new(1.0e4, 0.3).unwrap());
        let loads: Vec<f64> = (0..mesh.dof_count())
            .map(|d| (d as f64 * 0.37).sin() * 1e-3)
            .collect();
        let template =
            LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], fixed).unwrap();
        let factor = template.new_factor();
        assert_eq!(
            matches!(factor.symbolic().raw(), SymbolicCholeskyRaw::Supernodal(_)),
            supernodal,
            "{n} x {n}"
        );
        let target = Materials::homogeneous(Material::new(2.5e4, 0.48).unwrap());
        let mut reused = template.clone();
        reused.factorize(&before).unwrap();
        let before = reused.solve(&loads).unwrap().displacement;
        reused.factorize(&target).unwrap();
        let mut fresh = template.clone();
        fresh.factorize(&target).unwrap();
        let (a, b) = (
            reused.solve(&loads).unwrap().displacement,
            fresh.solve(&loads).unwrap().displacement,
        );
        assert!(a.iter().zip(&before).any(|(x, y)| x != y));
        assert!(
            a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
            "{n} x {n}"
        );
    }
}

/// Many load cases solved as one block give each case's own solve, split
/// over the threads both from outside the pool and from one of its threads
/// (blocks of at least 8 cases there): the blocks never mix columns.
#[test]
fn a_block_of_load_cases_equals_each_case_solved_alone() {
    let mesh = distorted_square(ElementKind::Tri6, 4, 0.2, 3);
    let fixed = Dirichlet::fixed_face(&mesh, needle_fem::Face::Back);
    let n = mesh.dof_count();
    let mut problem =
        LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], fixed).unwrap();
    problem
        .factorize(&Materials::homogeneous(Material::new(1.0e4, 0.45).unwrap()))
        .unwrap();
    let cases: Vec<Vec<f64>> = (0..37)
        .map(|c| {
            (0..n)
                .map(|d| ((d * (c + 3)) as f64 * 0.37).sin() * 1e-3)
                .collect()
        })
        .collect();
    let refs: Vec<&[f64]> = cases.iter().map(|c| c.as_slice()).collect();
    let many = problem.displacements_many(&refs).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let in_pool = pool.install(|| problem.displacements_many(&refs)).unwrap();
    assert_eq!(many.len(), cases.len());
    assert_eq!(in_pool.len(), cases.len());
    for ((case, together), from_pool) in cases.iter().zip(&many).zip(&in_pool) {
        let alone = problem.solve(case).unwrap().displacement;
        let scale = alone.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(scale > 0.0);
        for ((a, b), c) in alone.iter().zip(together).zip(from_pool) {
            assert!((a - b).abs() <= 1e-12 * scale, "{a} vs {b}");
            assert!((a - c).abs() <= 1e-12 * scale, "{a} vs {c} in the pool");
        }
    }
}

/// Shape functions are nodal ($N_a(x_b) = \delta_{ab}$), sum to one, and
/// their gradients sum to zero, for every element kind.
#[test]
fn shape_functions_are_nodal_and_partition_unity() {
    use nalgebra::SVector;
    use needle_fem::element::shape::{gradients, reference_nodes, values};
    fn check<const D: usize, const N: usize>() {
        let nodes = reference_nodes::<D, N>();
        for b in 0..N {
            let xi: SVector<f64, D> = nodes.column(b).into();
            let n = values::<D, N>(&xi);
            for a in 0..N {
                assert!(
                    (n[a] - f64::from(u8::from(a == b))).abs() < 1e-15,
                    "N{a}(x{b}) = {}",
                    n[a]
                );
            }
        }
        for k in 0..20 {
            let raw: [f64; 3] = std::array::from_fn(|j| 0.5 + 0.5 * common::jitter(k, j));
            let total: f64 = raw[..D].iter().sum::<f64>().max(1.0);
            let xi = SVector::<f64, D>::from_fn(|j, _| raw[j] / total);
            assert!((values::<D, N>(&xi).sum() - 1.0).abs() < 1e-14);
            let g = gradients::<D, N>(&xi);
            for j in 0..D {
                assert!(g.row(j).sum().abs() < 1e-13);
                let step = 1e-6;
                let mut plus = xi;
                let mut minus = xi;
                plus[j] += step;
                minus[j] -= step;
                let fd = (values::<D, N>(&plus) - values::<D, N>(&minus)) / (2.0 * step);
                for a in 0..N {
                    assert!((fd[a] - g[(j, a)]).abs() < 1e-8, "dN{a}/dxi{j}");
                }
            }
        }
    }
    check::<2, 3>();
    check::<2, 6>();
    check::<3, 4>();
    check::<3, 10>();
}

/// Node and facet look-ups on structured meshes, counted by hand.
#[test]
fn node_and_facet_queries() {
    use needle_fem::Face;
    let mesh = needle_fem::RectangleMesh::uniform(0.075, 0.05, 6, 4)
        .unwrap()
        .build(ElementKind::Tri6)
        .unwrap();
    // Quadratic mesh: 13 x 9 nodes.
    assert_eq!(mesh.node_count(), 13 * 9);
    assert_eq!(mesh.nodes_on_face(Face::Back).len(), 13);
    assert_eq!(mesh.nodes_on_face(Face::Left).len(), 9);
    assert!(mesh.nodes_on_face(Face::Top).is_empty());
    assert_eq!(mesh.boundary_facets().len(), 2 * (6 + 4));
    assert_eq!(mesh.facets_on_face(Face::Front).len(), 6);
    // A needle path along x = 0.0375 from the front face to y = 0.03: nodes
    // every 0.05 / 8 = 6.25 mm, at y = 0 .. 25 mm.
    let path = mesh.nodes_along_segment([0.0375, 0.0], [0.0375, 0.03], 1e-9);
    assert_eq!(path.len(), 5);
    assert!(
        path.windows(2)
            .all(|w| mesh.node(w[0])[1] < mesh.node(w[1])[1])
    );
    assert_eq!(
        mesh.node(mesh.nearest_node([0.074, 0.049]).unwrap()),
        [0.075, 0.05]
    );

    let plan = needle_fem::RectangleMesh::uniform(0.075, 0.05, 3, 2).unwrap();
    let slab = needle_fem::SlabMesh::new(plan, 0.0075, 2)
        .unwrap()
        .build(ElementKind::Tet10)
        .unwrap();
    assert_eq!(slab.node_count(), 7 * 5 * 5);
    assert_eq!(slab.nodes_on_face(Face::Top).len(), 7 * 5);
    // Each face of a hexahedral cell is split into two triangles.
    assert_eq!(slab.facets_on_face(Face::Top).len(), 2 * 3 * 2);
    assert_eq!(slab.facets_on_face(Face::Back).len(), 2 * 3 * 2);
    assert_eq!(
        slab.boundary_facets().len(),
        2 * (2 * 3 * 2 + 2 * 3 * 2 + 2 * 2 * 2)
    );
}

#[test]
fn element_quality_is_one_for_regular_simplices_and_falls_as_they_flatten() {
    let height = 3f64.sqrt() / 2.0;
    let equilateral = Mesh::new(
        ElementKind::Tri3,
        vec![[0.0, 0.0], [1.0, 0.0], [0.5, height]],
        vec![0, 1, 2],
        vec![0],
    )
    .unwrap();
    assert!((equilateral.element_quality(0) - 1.0).abs() < 1e-12);
    let flattened = Mesh::new(
        ElementKind::Tri3,
        vec![[0.0, 0.0], [1.0, 0.0], [0.5, 0.01 * height]],
        vec![0, 1, 2],
        vec![0],
    )
    .unwrap();
    let q = flattened.element_quality(0);
    assert!(
        q > 0.0 && q < 0.02,
        "quality of a nearly flat triangle: {q}"
    );

    let s = 1.0 / 2f64.sqrt();
    let regular_tet = Mesh::new(
        ElementKind::Tet4,
        vec![
            [1.0, 0.0, -s],
            [-1.0, 0.0, -s],
            [0.0, 1.0, s],
            [0.0, -1.0, s],
        ],
        vec![0, 1, 3, 2],
        vec![0],
    )
    .unwrap();
    assert!((regular_tet.element_quality(0) - 1.0).abs() < 1e-12);

    // The structured meshes are made of right isosceles triangles,
    // q = 4 sqrt(3) (1/2) / 4 = sqrt(3)/2, and are reported as such.
    let rectangle = needle_fem::RectangleMesh::uniform(1.0, 1.0, 4, 4)
        .unwrap()
        .build(ElementKind::Tri6)
        .unwrap();
    let report = rectangle.quality(0.1);
    assert!((report.worst - 3f64.sqrt() / 2.0).abs() < 1e-12);
    assert!((report.mean - report.worst).abs() < 1e-12);
    assert!(report.below_threshold.is_empty());
}

proptest! {
    #[test]
    fn element_quality_is_scale_and_rotation_invariant_and_in_unit_interval(
        seed in 0u64..1000, scale in 0.001f64..1000.0, angle in 0.0f64..6.3,
    ) {
        let mesh = distorted_square(ElementKind::Tri3, 3, 0.2, seed);
        let (c, s) = (angle.cos(), angle.sin());
        let moved: Vec<[f64; 2]> = mesh
            .nodes()
            .iter()
            .map(|p| [scale * (c * p[0] - s * p[1]), scale * (s * p[0] + c * p[1])])
            .collect();
        let transformed = Mesh::new(
            ElementKind::Tri3,
            moved,
            mesh.connectivity().to_vec(),
            mesh.regions().to_vec(),
        )
        .unwrap();
        for e in 0..mesh.element_count() {
            let q = mesh.element_quality(e);
            prop_assert!(q > 0.0 && q <= 1.0 + 1e-12);
            prop_assert!((q - transformed.element_quality(e)).abs() < 1e-9);
        }
    }
}

/// The slab mirrored in its mid-plane, under a needle-like line load in
/// the mid-plane and a probe-like line through the thickness, with the
/// back face held: its displacement is symmetric about z = 0, and the
/// upper half alone (u_z = 0 held on z = 0, half the mid-plane load, the
/// same density through its half of the thickness) gives it exactly.
#[test]
fn upper_half_of_the_mirrored_slab_gives_its_displacement() {
    let (width, depth, thickness) = (0.075, 0.06, 0.0075);
    let plan = needle_fem::RectangleMesh::uniform(width, depth, 5, 4).unwrap();
    let material = Material::new(2.5e4, 0.48).unwrap();
    for layers in [2, 4] {
        let slab = needle_fem::SlabMesh::new(plan.clone(), thickness, layers).unwrap();
        let respond = |mesh: Mesh<3>, share: f64, bottom: f64| -> (Mesh<3>, Vec<f64>) {
            let locator = Locator::new(&mesh);
            let mut loads = vec![0.0; mesh.dof_count()];
            let needle = |s: f64| [-3.0 * share, share * (20.0 + 100.0 * s), 0.0];
            needle_fem::load::add_line_load(
                &locator,
                &mut loads,
                [0.02, 0.0, 0.0],
                [0.027, 0.041, 0.0],
                &needle_fem::LineDensity::Function {
                    density: &needle,
                    breakpoints: vec![],
                },
            )
            .unwrap();
            let probe = |_: f64| [0.5 / thickness, 2.0 / thickness, 0.0];
            needle_fem::load::add_line_load(
                &locator,
                &mut loads,
                [0.055, 0.0, bottom],
                [0.055, 0.0, 0.5 * thickness],
                &needle_fem::LineDensity::Function {
                    density: &probe,
                    breakpoints: vec![],
                },
            )
            .unwrap();
            let mut dirichlet = Dirichlet::fixed_face(&mesh, needle_fem::Face::Back);
            if bottom == 0.0 {
                let mid_plane = mesh.nodes_on_face(needle_fem::Face::Bottom);
                dirichlet.set_nodes(&mesh, &mid_plane, 2, 0.0).unwrap();
            }
            solve(mesh, Formulation::Solid, dirichlet, material, &loads)
        };
        let (full, u_full) = respond(
            slab.build_symmetric(ElementKind::Tet10).unwrap(),
            1.0,
            -0.5 * thickness,
        );
        let (half, u_half) = respond(slab.build_upper_half(ElementKind::Tet10).unwrap(), 0.5, 0.0);
        assert_eq!(full.element_count(), 2 * half.element_count());
        let largest = u_full.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(largest > 1e-4, "the loads move the slab: {largest}");
        let key = |p: [f64; 3]| p.map(|c| (c * 1e9).round() as i64);
        let index: std::collections::HashMap<[i64; 3], usize> = (0..full.node_count())
            .map(|n| (key(full.node(n)), n))
            .collect();
        let (mut symmetry, mut halves) = (0.0f64, 0.0f64);
        for n in 0..full.node_count() {
            let [x, y, z] = full.node(n);
            let m = index[&key([x, y, -z])];
            for (axis, sign) in [(0, 1.0), (1, 1.0), (2, -1.0)] {
                symmetry = symmetry.max((u_full[3 * n + axis] - sign * u_full[3 * m + axis]).abs());
            }
        }
        for n in 0..half.node_count() {
            let m = index[&key(half.node(n))];
            for axis in 0..3 {
                halves = halves.max((u_half[3 * n + axis] - u_full[3 * m + axis]).abs());
            }
        }
        assert!(
            symmetry < 1e-9 * largest,
            "{layers} layers: asymmetry {symmetry} of {largest}"
        );
        assert!(
            halves < 1e-9 * largest,
            "{layers} layers: half vs whole {halves} of {largest}"
        );
        // Kuhn's subdivision alone is not symmetric: the check above could fail.
        let (kuhn, u_kuhn) = respond(
            slab.build(ElementKind::Tet10).unwrap(),
            1.0,
            -0.5 * thickness,
        );
        let asymmetry = (0..kuhn.node_count())
            .map(|n| {
                let [x, y, z] = kuhn.node(n);
                let m = (0..kuhn.node_count())
                    .find(|&m| key(kuhn.node(m)) == key([x, y, -z]))
                    .unwrap();
                (u_kuhn[3 * n] - u_kuhn[3 * m]).abs()
            })
            .fold(0.0f64, f64::max);
        println!(
            "{layers} layers: largest {largest:.3e} m; mirrored asymmetry {symmetry:.1e}, half vs whole {halves:.1e}, Kuhn's asymmetry {asymmetry:.1e}"
        );
        assert!(
            asymmetry > 1e3 * symmetry.max(1e-15 * largest),
            "{asymmetry}"
        );
    }
}
