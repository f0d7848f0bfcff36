//! Convergence against closed-form solutions, with measured rates asserted.
//!
//! The CI cases use small meshes. Longer sweeps are `#[ignore]`d; run them
//! in release with
//! `cargo test -p needle-fem --release --test convergence -- --ignored --nocapture`.

mod common;

use common::solve;

use needle_fem::analytic::{
    Cantilever, Flamant, LameCylinder, ManufacturedSquare, plane_strain_equivalent,
};
use needle_fem::load::{add_body_force, add_nodal_force, add_traction};
use needle_fem::norm::error_norms;
use needle_fem::{
    Dirichlet, ElementKind, Face, Formulation, Material, Materials, Mesh, RectangleMesh, SlabMesh,
};

const PLANE: Formulation = Formulation::PlaneStrain { thickness: 1.0 };

/// L2 and H1 errors of the manufactured solution on an `n x n` mesh.
fn manufactured_errors(kind: ElementKind, n: usize) -> (f64, f64) {
    let material = Material::new(1.0, 0.3).unwrap();
    let exact = ManufacturedSquare { material };
    let mesh = RectangleMesh::uniform(1.0, 1.0, n, n)
        .unwrap()
        .build(kind)
        .unwrap();
    let boundary = mesh.nodes_where(|p| {
        p.iter()
            .any(|&x| x.abs() < 1e-12 || (x - 1.0).abs() < 1e-12)
    });
    let mut dirichlet = Dirichlet::new();
    dirichlet.fix_nodes(&mesh, &boundary).unwrap();
    let mut loads = vec![0.0; mesh.dof_count()];
    add_body_force(&mesh, PLANE, &mut loads, |p| exact.body_force(p)).unwrap();
    let (mesh, u) = solve(mesh, PLANE, dirichlet, material, &loads);
    error_norms(&mesh, &u, |p| exact.displacement(p), |p| exact.gradient(p)).unwrap()
}

fn rates(kind: ElementKind, sizes: &[usize]) -> Vec<(usize, f64, f64, f64, f64)> {
    let errors: Vec<(f64, f64)> = sizes
        .iter()
        .map(|&n| manufactured_errors(kind, n))
        .collect();
    (1..sizes.len())
        .map(|k| {
            let ratio = (sizes[k] as f64 / sizes[k - 1] as f64).ln();
            let l2_rate = (errors[k - 1].0 / errors[k].0).ln() / ratio;
            let h1_rate = (errors[k - 1].1 / errors[k].1).ln() / ratio;
            (sizes[k], errors[k].0, errors[k].1, l2_rate, h1_rate)
        })
        .collect()
}

#[test]
fn manufactured_solution_t3_converges_at_orders_two_and_one() {
    let r = rates(ElementKind::Tri3, &[8, 16, 32]);
    let (_, _, _, l2, h1) = *r.last().unwrap();
    assert!((1.85..2.15).contains(&l2), "T3 L2 rate {l2}");
    assert!((0.9..1.1).contains(&h1), "T3 H1 rate {h1}");
}

#[test]
fn manufactured_solution_t6_converges_at_orders_three_and_two() {
    let r = rates(ElementKind::Tri6, &[4, 8, 16]);
    let (_, _, _, l2, h1) = *r.last().unwrap();
    assert!((2.85..3.15).contains(&l2), "T6 L2 rate {l2}");
    assert!((1.9..2.1).contains(&h1), "T6 H1 rate {h1}");
}

#[test]
#[ignore = "long sweep; run in release with --ignored --nocapture"]
fn manufactured_solution_rate_table() {
    for (kind, sizes) in [
        (ElementKind::Tri3, vec![4, 8, 16, 32, 64, 128]),
        (ElementKind::Tri6, vec![2, 4, 8, 16, 32, 64]),
    ] {
        for (n, l2, h1, l2_rate, h1_rate) in rates(kind, &sizes) {
            println!(
                "{kind:?} n={n:4} L2={l2:.3e} H1={h1:.3e} rates L2 {l2_rate:.3} H1 {h1_rate:.3}"
            );
        }
    }
}

/// Quarter of the Lamé cylinder: an `nr x nt` (r, theta) grid mapped to the
/// annulus, symmetry rollers on the axes, pressure on the inner arc.
/// Returns the max nodal displacement error relative to the max exact value.
fn lame_error(kind: ElementKind, nr: usize, nt: usize, poisson_ratio: f64) -> f64 {
    let material = Material::new(1.0, poisson_ratio).unwrap();
    let cylinder = LameCylinder {
        inner_radius: 1.0,
        outer_radius: 2.0,
        pressure: 1e-3,
        material,
    };
    let grid = RectangleMesh::uniform(1.0, std::f64::consts::FRAC_PI_2, nr, nt)
        .unwrap()
        .build(kind)
        .unwrap();
    let nodes = grid.nodes().iter().map(|p| {
        let (r, t) = (1.0 + p[0], p[1]);
        [r * t.cos(), r * t.sin()]
    });
    let mesh = Mesh::new(
        kind,
        nodes.collect(),
        grid.connectivity().to_vec(),
        grid.regions().to_vec(),
    )
    .unwrap();
    let mut dirichlet = Dirichlet::new();
    let on_x_axis = mesh.nodes_where(|p| p[1].abs() < 1e-12);
    let on_y_axis = mesh.nodes_where(|p| p[0].abs() < 1e-12);
    dirichlet.set_nodes(&mesh, &on_x_axis, 1, 0.0).unwrap();
    dirichlet.set_nodes(&mesh, &on_y_axis, 0, 0.0).unwrap();
    let inner = mesh.facets_where(|p| (p[0].hypot(p[1]) - 1.0).abs() < 1e-9);
    let mut loads = vec![0.0; mesh.dof_count()];
    let p = cylinder.pressure;
    add_traction(&mesh, PLANE, &mut loads, &inner, |x| {
        let r = x[0].hypot(x[1]);
        [p * x[0] / r, p * x[1] / r]
    })
    .unwrap();
    let (mesh, u) = solve(mesh, PLANE, dirichlet, material, &loads);
    let mut worst: f64 = 0.0;
    let mut scale: f64 = 0.0;
    for (n, x) in mesh.nodes().iter().enumerate() {
        let exact = cylinder.displacement(*x);
        worst = worst.max((u[2 * n] - exact[0]).hypot(u[2 * n + 1] - exact[1]));
        scale = scale.max(exact[0].hypot(exact[1]));
    }
    worst / scale
}

#[test]
fn lame_cylinder_t6_converges() {
    let coarse = lame_error(ElementKind::Tri6, 2, 4, 0.3);
    let fine = lame_error(ElementKind::Tri6, 4, 8, 0.3);
    assert!(fine < 2e-3, "T6 Lamé error {fine:e}");
    let rate = (coarse / fine).log2();
    assert!(rate > 2.5, "T6 Lamé nodal rate {rate}");
}

#[test]
fn lame_cylinder_t3_converges() {
    let coarse = lame_error(ElementKind::Tri3, 4, 8, 0.3);
    let fine = lame_error(ElementKind::Tri3, 8, 16, 0.3);
    let rate = (coarse / fine).log2();
    assert!(rate > 1.8, "T3 Lamé nodal rate {rate}");
}

/// The rectangle generator alternates diagonals (a union-jack pattern),
/// which happens to relieve T3 locking. This mesh cuts every cell along the
/// same diagonal, the pattern in which T3 locks.
fn same_diagonal_mesh(kind: ElementKind, width: f64, height: f64, nx: usize, ny: usize) -> Mesh<2> {
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    let nodes: Vec<[f64; 2]> = (0..=ny)
        .flat_map(|j| {
            (0..=nx).map(move |i| [width * i as f64 / nx as f64, height * j as f64 / ny as f64])
        })
        .collect();
    let mut connectivity = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            connectivity.extend_from_slice(&[
                id(i, j),
                id(i + 1, j),
                id(i + 1, j + 1),
                id(i, j),
                id(i + 1, j + 1),
                id(i, j + 1),
            ]);
        }
    }
    let regions = vec![0; 2 * nx * ny];
    let linear = Mesh::new(ElementKind::Tri3, nodes, connectivity, regions).unwrap();
    if kind == ElementKind::Tri3 {
        linear
    } else {
        linear.to_quadratic().unwrap()
    }
}

/// Relative tip-deflection error of the plane-strain cantilever.
fn cantilever_tip_error(
    kind: ElementKind,
    nx: usize,
    ny: usize,
    poisson_ratio: f64,
    same_diagonal: bool,
) -> f64 {
    let mesh = if same_diagonal {
        same_diagonal_mesh(kind, 10.0, 2.0, nx, ny)
    } else {
        RectangleMesh::uniform(10.0, 2.0, nx, ny)
            .unwrap()
            .build(kind)
            .unwrap()
    };
    cantilever_on(mesh, PLANE, poisson_ratio)
}

#[test]
fn near_incompressibility_locks_t3_but_not_t6() {
    // Plane-strain cantilever, T3 and T6 on the same nodes (T3 on a grid
    // twice as fine), every cell cut along the same diagonal.
    let t3 = cantilever_tip_error(ElementKind::Tri3, 40, 8, 0.499, true);
    let t6 = cantilever_tip_error(ElementKind::Tri6, 20, 4, 0.499, true);
    assert!(t6 < 5e-3, "T6 at nu = 0.499: {t6:e}");
    assert!(t3 > 0.3, "T3 at nu = 0.499 should lock: {t3:e}");
    let t3_phantom = cantilever_tip_error(ElementKind::Tri3, 40, 8, 0.48, true);
    let t6_phantom = cantilever_tip_error(ElementKind::Tri6, 20, 4, 0.48, true);
    assert!(
        t6_phantom < t3_phantom / 10.0,
        "at nu = 0.48 T3 {t3_phantom:e} vs T6 {t6_phantom:e}"
    );
}

#[test]
#[ignore = "long sweep for docs/locking.md; run in release with --ignored --nocapture"]
fn locking_table() {
    for same_diagonal in [true, false] {
        println!(
            "cantilever tip deflection, plane strain, relative error, same diagonal: {same_diagonal}"
        );
        println!("| nu | T3 20x4 | T3 40x8 | T3 80x16 | T6 10x2 | T6 20x4 | T6 40x8 |");
        for nu in [0.3, 0.45, 0.48, 0.499] {
            let t3: Vec<f64> = [(20, 4), (40, 8), (80, 16)]
                .iter()
                .map(|&(a, b)| cantilever_tip_error(ElementKind::Tri3, a, b, nu, same_diagonal))
                .collect();
            let t6: Vec<f64> = [(10, 2), (20, 4), (40, 8)]
                .iter()
                .map(|&(a, b)| cantilever_tip_error(ElementKind::Tri6, a, b, nu, same_diagonal))
                .collect();
            println!(
                "| {nu} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {:.2e} |",
                t3[0], t3[1], t3[2], t6[0], t6[1], t6[2]
            );
        }
    }
    println!(
        "Lamé cylinder (alternating diagonals), max nodal displacement error relative to max displacement"
    );
    println!("| nu | T3 8x16 | T3 16x32 | T3 32x64 | T6 4x8 | T6 8x16 | T6 16x32 |");
    for nu in [0.3, 0.45, 0.48, 0.499] {
        let t3: Vec<f64> = [(8, 16), (16, 32), (32, 64)]
            .iter()
            .map(|&(a, b)| lame_error(ElementKind::Tri3, a, b, nu))
            .collect();
        let t6: Vec<f64> = [(4, 8), (8, 16), (16, 32)]
            .iter()
            .map(|&(a, b)| lame_error(ElementKind::Tri6, a, b, nu))
            .collect();
        println!(
            "| {nu} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {:.2e} |",
            t3[0], t3[1], t3[2], t6[0], t6[1], t6[2]
        );
    }
}

/// Max relative stress error of Flamant's solution at sample points at
/// distance >= 0.3 from the load, on a `[-1, 1] x [0, 1]` domain with the
/// exact tractions on the far sides and a minimal pinning.
fn flamant_error(kind: ElementKind, n: usize) -> f64 {
    let material = Material::new(1.0, 0.3).unwrap();
    let flamant = Flamant {
        force: 1e-3,
        position: 0.0,
    };
    let grid = RectangleMesh::uniform(2.0, 1.0, 2 * n, n)
        .unwrap()
        .build(kind)
        .unwrap();
    let nodes: Vec<[f64; 2]> = grid.nodes().iter().map(|p| [p[0] - 1.0, p[1]]).collect();
    let mesh = Mesh::new(
        kind,
        nodes,
        grid.connectivity().to_vec(),
        grid.regions().to_vec(),
    )
    .unwrap();
    let mut loads = vec![0.0; mesh.dof_count()];
    let load_node = mesh.nearest_node([0.0, 0.0]).unwrap();
    add_nodal_force(&mut loads, load_node, [0.0, flamant.force]).unwrap();
    let sides = [
        (Face::Left, [-1.0, 0.0]),
        (Face::Right, [1.0, 0.0]),
        (Face::Back, [0.0, 1.0]),
    ];
    for (face, normal) in sides {
        let facets = mesh.facets_on_face(face);
        add_traction(&mesh, PLANE, &mut loads, &facets, |x| {
            let s = flamant.stress(x);
            [
                s[0] * normal[0] + s[2] * normal[1],
                s[2] * normal[0] + s[1] * normal[1],
            ]
        })
        .unwrap();
    }
    let corner_left = mesh.nearest_node([-1.0, 1.0]).unwrap();
    let corner_right = mesh.nearest_node([1.0, 1.0]).unwrap();
    let mut dirichlet = Dirichlet::new();
    dirichlet.fix_nodes(&mesh, &[corner_left]).unwrap();
    dirichlet.set(2 * corner_right + 1, 0.0).unwrap();
    let (mesh, u) = solve(mesh, PLANE, dirichlet, material, &loads);
    let locator = needle_fem::Locator::new(&mesh);
    let materials = Materials::homogeneous(material);
    let samples = [
        [0.0, 0.4],
        [0.3, 0.4],
        [-0.4, 0.3],
        [0.5, 0.6],
        [0.0, 0.7],
        [-0.6, 0.5],
    ];
    let mut worst: f64 = 0.0;
    for p in samples {
        let location = locator.locate(p).unwrap();
        let s = needle_fem::stress::stress(&mesh, PLANE, &materials, &u, &location).unwrap();
        let exact = flamant.stress(p);
        let scale = exact.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for i in 0..3 {
            worst = worst.max((s[i] - exact[i]).abs() / scale);
        }
    }
    worst
}

#[test]
fn flamant_stresses_away_from_the_load() {
    let coarse = flamant_error(ElementKind::Tri6, 8);
    let fine = flamant_error(ElementKind::Tri6, 16);
    assert!(fine < 0.03, "Flamant T6 stress error {fine}");
    assert!(
        fine < coarse / 2.0,
        "Flamant error should fall with refinement: {coarse} -> {fine}"
    );
}

/// Relative tip-deflection error of the cantilever on `grid` (which spans
/// `[0, 10] x [0, 2]`) against Timoshenko's solution.
fn cantilever_on(grid: Mesh<2>, formulation: Formulation, nu: f64) -> f64 {
    let e = 1.0e3;
    let (e_beam, nu_beam) = match formulation {
        Formulation::PlaneStrain { .. } => plane_strain_equivalent(e, nu),
        _ => (e, nu),
    };
    let beam = Cantilever {
        length: 10.0,
        height: 2.0,
        force: 1.0,
        youngs_modulus: e_beam,
        poisson_ratio: nu_beam,
    };
    let kind = grid.kind();
    let nodes: Vec<[f64; 2]> = grid.nodes().iter().map(|p| [p[0], p[1] - 1.0]).collect();
    let mesh = Mesh::new(
        kind,
        nodes,
        grid.connectivity().to_vec(),
        grid.regions().to_vec(),
    )
    .unwrap();
    let mut dirichlet = Dirichlet::new();
    for n in mesh.nodes_on_face(Face::Left) {
        let u = beam.displacement(mesh.node(n));
        dirichlet.set(2 * n, u[0]).unwrap();
        dirichlet.set(2 * n + 1, u[1]).unwrap();
    }
    let mut loads = vec![0.0; mesh.dof_count()];
    add_traction(
        &mesh,
        formulation,
        &mut loads,
        &mesh.facets_on_face(Face::Right),
        |x| [0.0, beam.end_shear(x[1])],
    )
    .unwrap();
    let tip = mesh.nearest_node([10.0, 0.0]).unwrap();
    let (_, u) = solve(
        mesh,
        formulation,
        dirichlet,
        Material::new(e, nu).unwrap(),
        &loads,
    );
    let exact = beam.displacement([10.0, 0.0])[1];
    (u[2 * tip + 1] - exact).abs() / exact.abs()
}

fn cantilever_problem(kind: ElementKind, nx: usize, ny: usize, formulation: Formulation) -> f64 {
    cantilever_on(
        RectangleMesh::uniform(10.0, 2.0, nx, ny)
            .unwrap()
            .build(kind)
            .unwrap(),
        formulation,
        0.3,
    )
}

#[test]
fn cantilever_matches_timoshenko_in_plane_stress_and_plane_strain() {
    for formulation in [Formulation::PlaneStress { thickness: 1.0 }, PLANE] {
        let coarse = cantilever_problem(ElementKind::Tri6, 10, 2, formulation);
        let fine = cantilever_problem(ElementKind::Tri6, 20, 4, formulation);
        assert!(fine < 2e-3, "{formulation:?}: tip error {fine:e}");
        assert!(
            fine < coarse / 3.0,
            "{formulation:?}: {coarse:e} -> {fine:e}"
        );
    }
    let t3_coarse = cantilever_problem(ElementKind::Tri3, 20, 4, PLANE);
    let t3_fine = cantilever_problem(ElementKind::Tri3, 40, 8, PLANE);
    assert!(
        t3_fine < t3_coarse / 3.0,
        "T3 cantilever {t3_coarse:e} -> {t3_fine:e}"
    );
}

/// Tip deflection of a 3-D plate cantilever of thickness `t` relative to
/// the plane-stress Timoshenko solution.
fn slab_cantilever_error(
    kind: ElementKind,
    thickness: f64,
    nx: usize,
    ny: usize,
    layers: usize,
) -> f64 {
    let (e, nu) = (1.0e3, 0.3);
    let beam = Cantilever {
        length: 10.0,
        height: 2.0,
        force: 1.0,
        youngs_modulus: e,
        poisson_ratio: nu,
    };
    let plan = RectangleMesh::uniform(10.0, 2.0, nx, ny).unwrap();
    let grid = SlabMesh::new(plan, thickness, layers)
        .unwrap()
        .build(kind)
        .unwrap();
    let nodes: Vec<[f64; 3]> = grid
        .nodes()
        .iter()
        .map(|p| [p[0], p[1] - 1.0, p[2]])
        .collect();
    let mesh = Mesh::new(
        kind,
        nodes,
        grid.connectivity().to_vec(),
        grid.regions().to_vec(),
    )
    .unwrap();
    let mut dirichlet = Dirichlet::new();
    for n in mesh.nodes_on_face(Face::Left) {
        let p = mesh.node(n);
        let u = beam.displacement([p[0], p[1]]);
        dirichlet.set(3 * n, u[0]).unwrap();
        dirichlet.set(3 * n + 1, u[1]).unwrap();
        // Plane stress lets the clamped section thin freely: pin z only on
        // the mid-plane.
        if p[2].abs() < 1e-12 {
            dirichlet.set(3 * n + 2, 0.0).unwrap();
        }
    }
    let mut loads = vec![0.0; mesh.dof_count()];
    // Shear resultant per unit thickness times the thickness.
    add_traction(
        &mesh,
        Formulation::Solid,
        &mut loads,
        &mesh.facets_on_face(Face::Right),
        |x| [0.0, beam.end_shear(x[1]), 0.0],
    )
    .unwrap();
    let tip = mesh.nearest_node([10.0, 0.0, 0.0]).unwrap();
    let (_, u) = solve(
        mesh,
        Formulation::Solid,
        dirichlet,
        Material::new(e, nu).unwrap(),
        &loads,
    );
    let exact = beam.displacement([10.0, 0.0])[1];
    (u[3 * tip + 1] - exact).abs() / exact.abs()
}

#[test]
fn thin_slab_tends_to_plane_stress() {
    let thick = slab_cantilever_error(ElementKind::Tet10, 2.0, 10, 2, 2);
    let thin = slab_cantilever_error(ElementKind::Tet10, 0.1, 10, 2, 2);
    assert!(thin < 5e-3, "thin slab error {thin:e}");
    assert!(thin < thick, "thick {thick:e} thin {thin:e}");
}
