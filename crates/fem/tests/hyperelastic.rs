//! The neo-Hookean model against truths that do not depend on its code:
//! finite differences of its own force (tangent), the linear model (small
//! strain), closed-form homogeneous stretches, rigid rotations (frame
//! indifference), Newton's quadratic rate, and agreement of the two solvers.

mod common;

use common::{distorted_cube, distorted_square, jitter};
use needle_fem::assemble::multiply;
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, HyperelasticAssembler,
    HyperelasticProblem, LinearProblem, Material, Materials, Mesh, NonlinearError,
    NonlinearOptions, RectangleMesh, SlabMesh,
};

const PLANE: Formulation = Formulation::PlaneStrain { thickness: 0.0075 };

fn materials() -> Materials {
    Materials::homogeneous(Material::new(25.3e3, 0.48).unwrap())
}

/// A smooth finite deformation (strains of 10-20 %) plus nodal noise.
fn deformed_state<const D: usize>(mesh: &Mesh<D>, seed: u64) -> Vec<f64> {
    let mut u = vec![0.0; mesh.dof_count()];
    for (n, x) in mesh.nodes().iter().enumerate() {
        for i in 0..D {
            let smooth = 0.12 * x[(i + 1) % D] * x[i] - 0.08 * x[(i + D - 1) % D];
            u[n * D + i] = smooth + 0.01 * jitter(seed, n * D + i);
        }
    }
    u
}

/// Largest entry of |K_T - central difference of f_int| relative to the
/// largest |K_T| entry, over all columns.
fn tangent_error<const D: usize>(mesh: Mesh<D>, formulation: Formulation) -> f64 {
    let assembler = HyperelasticAssembler::new(Assembler::new(mesh, formulation).unwrap()).unwrap();
    let u = deformed_state(assembler.mesh(), 7);
    let tangent = common::dense(&assembler.tangent(&materials(), &u).unwrap());
    let h = 1e-6;
    let mut worst: f64 = 0.0;
    for j in 0..u.len() {
        let (mut plus, mut minus) = (u.clone(), u.clone());
        plus[j] += h;
        minus[j] -= h;
        let fp = assembler.internal_force(&materials(), &plus).unwrap();
        let fm = assembler.internal_force(&materials(), &minus).unwrap();
        for i in 0..u.len() {
            worst = worst.max(((fp[i] - fm[i]) / (2.0 * h) - tangent[(i, j)]).abs());
        }
    }
    worst / tangent.abs().max()
}

#[test]
fn tangent_is_the_central_difference_of_the_internal_force_in_2d() {
    let error = tangent_error(distorted_square(ElementKind::Tri6, 2, 0.2, 3), PLANE);
    assert!(error < 1e-6, "relative error {error:e}");
}

#[test]
fn tangent_is_the_central_difference_of_the_internal_force_in_3d() {
    let error = tangent_error(
        distorted_cube(ElementKind::Tet10, 2, 0.2, 5),
        Formulation::Solid,
    );
    assert!(error < 1e-6, "relative error {error:e}");
}

#[test]
fn tangent_at_rest_is_the_linear_stiffness() {
    let check = |k_t: Vec<f64>, k: Vec<f64>| {
        let scale = k.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let diff = k_t
            .iter()
            .zip(&k)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(diff < 1e-12 * scale, "{diff:e} vs {scale:e}");
    };
    let plane = Assembler::new(distorted_square(ElementKind::Tri6, 3, 0.2, 1), PLANE).unwrap();
    let k = plane.stiffness(&materials()).unwrap().val().to_vec();
    let hyper = HyperelasticAssembler::new(plane).unwrap();
    let zero = vec![0.0; hyper.mesh().dof_count()];
    check(
        hyper.tangent(&materials(), &zero).unwrap().val().to_vec(),
        k,
    );
    let solid = Assembler::new(
        distorted_cube(ElementKind::Tet10, 2, 0.2, 2),
        Formulation::Solid,
    )
    .unwrap();
    let k = solid.stiffness(&materials()).unwrap().val().to_vec();
    let hyper = HyperelasticAssembler::new(solid).unwrap();
    let zero = vec![0.0; hyper.mesh().dof_count()];
    check(
        hyper.tangent(&materials(), &zero).unwrap().val().to_vec(),
        k,
    );
}

/// Rotation by `angle` about an axis, as a D x D array.
fn rotation<const D: usize>(angle: f64) -> [[f64; D]; D] {
    let (s, c) = angle.sin_cos();
    let mut r = [[0.0; D]; D];
    if D == 2 {
        r[0] = [c, -s, 0.0][..D].try_into().unwrap();
        r[1] = [s, c, 0.0][..D].try_into().unwrap();
    } else {
        // About the axis (1, 2, 2)/3 by Rodrigues' formula.
        let a = [1.0 / 3.0, 2.0 / 3.0, 2.0 / 3.0];
        for i in 0..D {
            for j in 0..D {
                let cross = match (i, j) {
                    (0, 1) => -a[2],
                    (1, 0) => a[2],
                    (0, 2) => a[1],
                    (2, 0) => -a[1],
                    (1, 2) => -a[0],
                    (2, 1) => a[0],
                    _ => 0.0,
                };
                let identity = if i == j { 1.0 } else { 0.0 };
                r[i][j] = c * identity + s * cross + (1.0 - c) * a[i] * a[j];
            }
        }
    }
    r
}

fn rotate_nodal<const D: usize>(r: &[[f64; D]; D], v: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; v.len()];
    for n in 0..v.len() / D {
        for i in 0..D {
            out[n * D + i] = (0..D).map(|j| r[i][j] * v[n * D + j]).sum();
        }
    }
    out
}

/// Relative errors of f(Q(X+u)-X) = Q f(u) and K_T(u') Q v = Q K_T(u) v.
fn frame_indifference_errors<const D: usize>(
    mesh: Mesh<D>,
    formulation: Formulation,
) -> (f64, f64) {
    let assembler = HyperelasticAssembler::new(Assembler::new(mesh, formulation).unwrap()).unwrap();
    let mesh = assembler.mesh();
    let u = deformed_state(mesh, 11);
    let q = rotation::<D>(0.7);
    let positions: Vec<f64> = (0..u.len())
        .map(|d| mesh.node(d / D)[d % D] + u[d])
        .collect();
    let rotated: Vec<f64> = rotate_nodal(&q, &positions)
        .iter()
        .enumerate()
        .map(|(d, x)| x - mesh.node(d / D)[d % D])
        .collect();
    let force = assembler.internal_force(&materials(), &u).unwrap();
    let rotated_force = assembler.internal_force(&materials(), &rotated).unwrap();
    let expected = rotate_nodal(&q, &force);
    let relative = |a: &[f64], b: &[f64]| {
        let diff: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
        let size: f64 = b.iter().map(|y| y * y).sum();
        (diff / size).sqrt()
    };
    let force_error = relative(&rotated_force, &expected);
    let v: Vec<f64> = (0..u.len()).map(|d| jitter(13, d)).collect();
    let k = assembler.tangent(&materials(), &u).unwrap();
    let k_rotated = assembler.tangent(&materials(), &rotated).unwrap();
    let tangent_error = relative(
        &multiply(&k_rotated, &rotate_nodal(&q, &v)),
        &rotate_nodal(&q, &multiply(&k, &v)),
    );
    (force_error, tangent_error)
}

#[test]
fn internal_force_and_tangent_are_frame_indifferent() {
    let (f2, k2) = frame_indifference_errors(distorted_square(ElementKind::Tri6, 3, 0.2, 4), PLANE);
    assert!(f2 < 1e-12 && k2 < 1e-12, "2-D: {f2:e} {k2:e}");
    let (f3, k3) = frame_indifference_errors(
        distorted_cube(ElementKind::Tet10, 2, 0.2, 6),
        Formulation::Solid,
    );
    assert!(f3 < 1e-12 && k3 < 1e-12, "3-D: {f3:e} {k3:e}");
    // The check has teeth: the rotated state's force is not the unrotated one.
    let assembler = HyperelasticAssembler::new(
        Assembler::new(distorted_square(ElementKind::Tri6, 3, 0.2, 4), PLANE).unwrap(),
    )
    .unwrap();
    let u = deformed_state(assembler.mesh(), 11);
    let f = assembler.internal_force(&materials(), &u).unwrap();
    assert!(
        f.iter()
            .any(|v| v.abs() > 1e-3 * f.iter().fold(0.0_f64, |m, x| m.max(x.abs())))
    );
}

/// A 75 mm square T6 block fixed on its back face, pulled on its front face
/// by a nominal traction `traction` (Pa) along -y, per load case.
fn pulled_block(cells: usize, tractions: &[f64]) -> (HyperelasticProblem<2>, Vec<Vec<f64>>) {
    let mesh = RectangleMesh::uniform(0.075, 0.075, cells, cells)
        .unwrap()
        .build(ElementKind::Tri6)
        .unwrap();
    let fixed = Dirichlet::fixed_face(&mesh, Face::Back);
    let front = mesh.facets_on_face(Face::Front);
    let loads = tractions
        .iter()
        .map(|&t| {
            let mut f = vec![0.0; mesh.dof_count()];
            needle_fem::load::add_traction(&mesh, PLANE, &mut f, &front, |_| [0.0, -t]).unwrap();
            f
        })
        .collect();
    let linear = LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], fixed).unwrap();
    (HyperelasticProblem::new(linear).unwrap(), loads)
}

fn relative_difference(a: &[f64], b: &[f64]) -> f64 {
    let diff: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    let size: f64 = b.iter().map(|y| y * y).sum();
    (diff / size).sqrt()
}

#[test]
fn tiny_loads_give_the_linear_solution() {
    // 1 mPa: strains of order 1e-7, so the models differ by that relative amount.
    let (mut problem, loads) = pulled_block(4, &[1e-3]);
    problem.linear_mut().factorize(&materials()).unwrap();
    let linear = problem.linear().solve(&loads[0]).unwrap();
    let options = NonlinearOptions::default();
    let newton = problem
        .solve_newton(&materials(), &loads[0], None, &options)
        .unwrap();
    let difference = relative_difference(&newton.displacement, &linear.displacement);
    assert!(difference < 1e-6, "{difference:e}");
    let reactions = relative_difference(&newton.reactions, &linear.reactions);
    assert!(reactions < 1e-6, "{reactions:e}");
}

/// Lateral stretch that makes the lateral nominal stress vanish:
/// solves mu (l^2 - 1) + lambda ln(stretch * l^k) = 0 for l, with k = 1
/// (plane strain) or 2 (3-D uniaxial), by Newton's method.
fn lateral_stretch(stretch: f64, k: f64, mu: f64, lambda: f64) -> f64 {
    let mut l = 1.0;
    for _ in 0..50 {
        let g = mu * (l * l - 1.0) + lambda * (stretch * l.powf(k)).ln();
        let dg = 2.0 * mu * l + lambda * k / l;
        l -= g / dg;
    }
    l
}

#[test]
fn plane_strain_stretch_matches_the_closed_form_nominal_stress() {
    let (length, height, stretch) = (0.02, 0.01, 1.3);
    let material = Material::new(25.3e3, 0.48).unwrap();
    let (mu, lambda) = (material.shear_modulus(), material.lame_lambda());
    let mesh = RectangleMesh::uniform(length, height, 4, 2)
        .unwrap()
        .build(ElementKind::Tri6)
        .unwrap();
    let left = mesh.nodes_on_face(Face::Left);
    let right = mesh.nodes_on_face(Face::Right);
    let corner = mesh.nearest_node([0.0, 0.0]).unwrap();
    let mut dirichlet = Dirichlet::new();
    dirichlet.set_nodes(&mesh, &left, 0, 0.0).unwrap();
    dirichlet.set_nodes(&mesh, &[corner], 1, 0.0).unwrap();
    dirichlet
        .set_nodes(&mesh, &right, 0, (stretch - 1.0) * length)
        .unwrap();
    let linear =
        LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], dirichlet).unwrap();
    let problem = HyperelasticProblem::new(linear).unwrap();
    let options = NonlinearOptions {
        tolerance: 1e-12,
        load_steps: 3,
        ..NonlinearOptions::default()
    };
    let loads = vec![0.0; problem.linear().mesh().dof_count()];
    let solution = problem
        .solve_newton(&Materials::homogeneous(material), &loads, None, &options)
        .unwrap();

    let lateral = lateral_stretch(stretch, 1.0, mu, lambda);
    let j = stretch * lateral;
    let nominal = mu * (stretch - 1.0 / stretch) + lambda * j.ln() / stretch;
    let force: f64 = right.iter().map(|&n| solution.reactions[2 * n]).sum();
    let measured = force / (height * PLANE.thickness());
    assert!(
        (measured - nominal).abs() < 1e-8 * nominal,
        "{measured} vs {nominal}"
    );
    // The whole field is the homogeneous stretch.
    let mesh = problem.linear().mesh();
    for (n, x) in mesh.nodes().iter().enumerate() {
        let expected = [(stretch - 1.0) * x[0], (lateral - 1.0) * x[1]];
        for i in 0..2 {
            let error = (solution.displacement[2 * n + i] - expected[i]).abs();
            assert!(error < 1e-9 * length, "node {n} dof {i}: {error:e}");
        }
    }
    // Far from linear: the linear model's stress differs by more than 10 %.
    let linear_stress = (lambda + 2.0 * mu) * (stretch - 1.0) + lambda * (lateral - 1.0);
    assert!((linear_stress - nominal).abs() > 0.1 * nominal);
}

#[test]
fn uniaxial_stretch_of_a_tet10_block_matches_the_closed_form_nominal_stress() {
    let (length, width, thickness, stretch) = (0.02, 0.01, 0.01, 1.25);
    let material = Material::new(25.3e3, 0.45).unwrap();
    let (mu, lambda) = (material.shear_modulus(), material.lame_lambda());
    let plan = RectangleMesh::uniform(length, width, 2, 1).unwrap();
    let mesh = SlabMesh::new(plan, thickness, 1)
        .unwrap()
        .build(ElementKind::Tet10)
        .unwrap();
    let bottom = -0.5 * thickness;
    let left = mesh.nodes_on_face(Face::Left);
    let right = mesh.nodes_on_face(Face::Right);
    let origin = mesh.nearest_node([0.0, 0.0, bottom]).unwrap();
    let across = mesh.nearest_node([0.0, width, bottom]).unwrap();
    let mut dirichlet = Dirichlet::new();
    dirichlet.set_nodes(&mesh, &left, 0, 0.0).unwrap();
    dirichlet.set_nodes(&mesh, &[origin], 1, 0.0).unwrap();
    dirichlet
        .set_nodes(&mesh, &[origin, across], 2, 0.0)
        .unwrap();
    dirichlet
        .set_nodes(&mesh, &right, 0, (stretch - 1.0) * length)
        .unwrap();
    let linear = LinearProblem::new(
        Assembler::new(mesh, Formulation::Solid).unwrap(),
        vec![],
        dirichlet,
    )
    .unwrap();
    let problem = HyperelasticProblem::new(linear).unwrap();
    // The linear predictor over-contracts the bar laterally; in one step
    // the resulting compression makes the tangent indefinite (torsional
    // buckling of the non-equilibrium state), so go in four steps.
    let options = NonlinearOptions {
        tolerance: 1e-12,
        load_steps: 4,
        ..NonlinearOptions::default()
    };
    let loads = vec![0.0; problem.linear().mesh().dof_count()];
    let solution = problem
        .solve_newton(&Materials::homogeneous(material), &loads, None, &options)
        .unwrap();

    let lateral = lateral_stretch(stretch, 2.0, mu, lambda);
    let j = stretch * lateral * lateral;
    let nominal = mu * (stretch - 1.0 / stretch) + lambda * j.ln() / stretch;
    let force: f64 = right.iter().map(|&n| solution.reactions[3 * n]).sum();
    let measured = force / (width * thickness);
    assert!(
        (measured - nominal).abs() < 1e-8 * nominal,
        "{measured} vs {nominal}"
    );
    let mesh = problem.linear().mesh();
    for (n, x) in mesh.nodes().iter().enumerate() {
        let expected = [
            (stretch - 1.0) * x[0],
            (lateral - 1.0) * x[1],
            (lateral - 1.0) * (x[2] - bottom),
        ];
        for i in 0..3 {
            let error = (solution.displacement[3 * n + i] - expected[i]).abs();
            assert!(error < 1e-9 * length, "node {n} dof {i}: {error:e}");
        }
    }
}

/// A T6 block clamped on the left and stretched 20 % by its clamped right
/// face: a non-homogeneous large-strain state.
fn clamped_stretch() -> HyperelasticProblem<2> {
    let (length, height) = (0.02, 0.01);
    let mesh = RectangleMesh::uniform(length, height, 6, 3)
        .unwrap()
        .build(ElementKind::Tri6)
        .unwrap();
    let mut dirichlet = Dirichlet::fixed_face(&mesh, Face::Left);
    let right = mesh.nodes_on_face(Face::Right);
    dirichlet.set_nodes(&mesh, &right, 0, 0.2 * length).unwrap();
    dirichlet.set_nodes(&mesh, &right, 1, 0.0).unwrap();
    let linear =
        LinearProblem::new(Assembler::new(mesh, PLANE).unwrap(), vec![], dirichlet).unwrap();
    HyperelasticProblem::new(linear).unwrap()
}

#[test]
fn newton_converges_quadratically_at_twenty_percent_strain() {
    let problem = clamped_stretch();
    let loads = vec![0.0; problem.linear().mesh().dof_count()];
    let options = NonlinearOptions {
        tolerance: 1e-13,
        ..NonlinearOptions::default()
    };
    let solution = problem
        .solve_newton(&materials(), &loads, None, &options)
        .unwrap();
    let history = &solution.residual_history;
    assert!(solution.iterations <= 8, "{history:?}");
    // Once in the basin (residual below 1e-2), each iterate squares the
    // residual up to a moderate constant: r_{k+1} <= 10 r_k^2.
    let mut checked = 0;
    for pair in history.windows(2) {
        if pair[0] < 1e-2 && pair[1] > 1e-12 {
            assert!(pair[1] <= 10.0 * pair[0] * pair[0], "{history:?}");
            checked += 1;
        }
    }
    assert!(
        checked >= 2,
        "too few iterations to see the rate: {history:?}"
    );
}

#[test]
fn modified_newton_agrees_with_newton_for_several_load_cases() {
    // Nominal tractions of 1.5 and 3 kPa: about 5 % and 10 % strain. At
    // 4 kPa and above the initial-stiffness iteration no longer contracts
    // for this nearly incompressible block (nu = 0.48).
    let (mut problem, loads) = pulled_block(4, &[1.5e3, 3.0e3]);
    problem.linear_mut().factorize(&materials()).unwrap();
    let options = NonlinearOptions {
        tolerance: 1e-12,
        max_iterations: 300,
        ..NonlinearOptions::default()
    };
    let cases: Vec<&[f64]> = loads.iter().map(|f| f.as_slice()).collect();
    let linear = problem.linear().displacements_many(&cases).unwrap();
    let starts: Vec<&[f64]> = linear.iter().map(|u| u.as_slice()).collect();
    let modified = problem
        .solve_modified_newton(&materials(), &cases, Some(&starts), &options)
        .unwrap();
    for (case, f) in cases.iter().enumerate() {
        let newton = problem
            .solve_newton(&materials(), f, None, &options)
            .unwrap();
        let difference = relative_difference(&modified[case].displacement, &newton.displacement);
        assert!(difference < 1e-8, "case {case}: {difference:e}");
        // The answer is nonlinear: it is not the linear start.
        assert!(relative_difference(&newton.displacement, &linear[case]) > 1e-3);
        assert!(modified[case].iterations > newton.iterations);
    }
    // Strain reached in the larger case: |du_y/dy| near the loaded face.
    let mesh = problem.linear().mesh();
    let front = mesh.nearest_node([0.0375, 0.0]).unwrap();
    let inner = mesh.nearest_node([0.0375, 0.0375 / 2.0]).unwrap();
    let strain = (modified[1].displacement[2 * front + 1]
        - modified[1].displacement[2 * inner + 1])
        / (mesh.node(inner)[1] - mesh.node(front)[1]);
    assert!(strain.abs() > 0.08, "strain {strain}");
}

#[test]
fn failures_are_typed_errors() {
    let (mut problem, loads) = pulled_block(2, &[2.0e3]);
    problem.linear_mut().factorize(&materials()).unwrap();
    let few = NonlinearOptions {
        max_iterations: 2,
        ..NonlinearOptions::default()
    };
    let modified = problem.solve_modified_newton(&materials(), &[&loads[0]], None, &few);
    assert!(matches!(
        modified,
        Err(NonlinearError::NotConverged { iterations: 2, .. })
    ));
    let one = NonlinearOptions {
        max_iterations: 1,
        ..NonlinearOptions::default()
    };
    let newton = problem.solve_newton(&materials(), &loads[0], None, &one);
    assert!(matches!(
        newton,
        Err(NonlinearError::NotConverged { iterations: 1, .. })
    ));
    // Mirroring the body: u_x = -2 x gives F = diag(-1, 1), J = -1.
    let mesh = problem.linear().mesh();
    let inverted: Vec<f64> = (0..mesh.dof_count())
        .map(|d| {
            if d % 2 == 0 {
                -2.0 * mesh.node(d / 2)[0]
            } else {
                0.0
            }
        })
        .collect();
    assert!(matches!(
        problem.internal_force(&materials(), &inverted),
        Err(NonlinearError::InvertedElement { .. })
    ));
    let stress =
        Assembler::new(mesh.clone(), Formulation::PlaneStress { thickness: 0.0075 }).unwrap();
    assert!(matches!(
        HyperelasticAssembler::new(stress),
        Err(NonlinearError::UnsupportedFormulation(_))
    ));
    assert!(matches!(
        problem.solve_newton(&materials(), &loads[0][1..], None, &few),
        Err(NonlinearError::Fem(_))
    ));
}

#[test]
fn newton_steps_past_an_indefinite_tangent() {
    // At 6 kPa (about 20 % strain) the linear prediction of the nearly
    // incompressible block has an indefinite K_T; Newton falls back to K
    // there and still converges, to the answer of three load steps.
    let (problem, loads) = pulled_block(4, &[6.0e3]);
    let options = NonlinearOptions {
        tolerance: 1e-12,
        ..NonlinearOptions::default()
    };
    let direct = problem
        .solve_newton(&materials(), &loads[0], None, &options)
        .unwrap();
    let stepped = problem
        .solve_newton(
            &materials(),
            &loads[0],
            None,
            &NonlinearOptions {
                load_steps: 3,
                ..options
            },
        )
        .unwrap();
    let difference = relative_difference(&direct.displacement, &stepped.displacement);
    assert!(difference < 1e-8, "{difference:e}");
}
