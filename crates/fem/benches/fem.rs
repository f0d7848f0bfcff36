//! Assembly, factorisation and solve of plane-strain T6 problems of about
//! 10k, 100k and 1M dofs and of a Tet10 slab of about 100k dofs.
//!
//! Run with short times on the shared machine, e.g.
//! `cargo bench -p needle-fem --bench fem -- --warm-up-time 1 --measurement-time 5`.
//! Set `NEEDLE_FEM_BENCH_MAX_DOFS` to skip the larger sizes.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, LinearProblem, Material, Materials,
    RectangleMesh, SlabMesh,
};

fn materials() -> Materials {
    Materials::homogeneous(Material::new(25.3e3, 0.48).unwrap())
}

fn max_dofs() -> usize {
    std::env::var("NEEDLE_FEM_BENCH_MAX_DOFS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(usize::MAX)
}

/// A square T6 mesh with `cells x cells` grid cells: 2 (2 cells + 1)^2 dofs.
fn plane_problem(cells: usize) -> LinearProblem<2> {
    let mesh = RectangleMesh::uniform(0.075, 0.075, cells, cells)
        .unwrap()
        .build(ElementKind::Tri6)
        .unwrap();
    let fixed = Dirichlet::fixed_face(&mesh, Face::Back);
    let assembler = Assembler::new(mesh, Formulation::PlaneStrain { thickness: 0.0075 }).unwrap();
    LinearProblem::new(assembler, vec![], fixed).unwrap()
}

fn bench_plane(c: &mut Criterion) {
    let mut group = c.benchmark_group("plane_strain_t6");
    group.sample_size(10);
    for cells in [35, 112, 353] {
        let dofs = 2 * (2 * cells + 1) * (2 * cells + 1);
        if dofs > max_dofs() {
            continue;
        }
        let mut problem = plane_problem(cells);
        let loads: Vec<f64> = (0..problem.mesh().dof_count())
            .map(|d| if d % 2 == 1 { -1e-3 } else { 0.0 })
            .collect();
        group.bench_function(format!("assemble/{dofs}"), |b| {
            let mut k = problem.assembler().pattern().zeros();
            b.iter(|| {
                problem
                    .assembler()
                    .stiffness_into(&materials(), &mut k)
                    .unwrap()
            })
        });
        group.bench_function(format!("assemble_factorize/{dofs}"), |b| {
            b.iter(|| problem.factorize(&materials()).unwrap())
        });
        problem.factorize(&materials()).unwrap();
        group.bench_function(format!("solve/{dofs}"), |b| {
            b.iter(|| black_box(problem.solve(&loads).unwrap()))
        });
        group.bench_function(format!("setup_assemble_factorize_solve/{dofs}"), |b| {
            b.iter(|| {
                let mut p = plane_problem(cells);
                p.factorize(&materials()).unwrap();
                black_box(p.solve(&loads).unwrap())
            })
        });
    }
    group.finish();
}

fn bench_slab(c: &mut Criterion) {
    let mut group = c.benchmark_group("slab_tet10");
    group.sample_size(10);
    // 20 x 20 plan cells, 4 layers: 3 * 41 * 41 * 9 = 45k dofs; 30 x 30 x 4: 100k.
    for (cells, layers) in [(30, 4)] {
        let dofs = 3 * (2 * cells + 1) * (2 * cells + 1) * (2 * layers + 1);
        if dofs > max_dofs() {
            continue;
        }
        let plan = RectangleMesh::uniform(0.075, 0.075, cells, cells).unwrap();
        let mesh = SlabMesh::new(plan, 0.0075, layers)
            .unwrap()
            .build(ElementKind::Tet10)
            .unwrap();
        let fixed = Dirichlet::fixed_face(&mesh, Face::Back);
        let mut problem = LinearProblem::new(
            Assembler::new(mesh, Formulation::Solid).unwrap(),
            vec![],
            fixed,
        )
        .unwrap();
        let loads: Vec<f64> = (0..problem.mesh().dof_count())
            .map(|d| if d % 3 == 1 { -1e-4 } else { 0.0 })
            .collect();
        group.bench_function(format!("assemble/{dofs}"), |b| {
            let mut k = problem.assembler().pattern().zeros();
            b.iter(|| {
                problem
                    .assembler()
                    .stiffness_into(&materials(), &mut k)
                    .unwrap()
            })
        });
        // The same matrix element by element: what a body with several
        // materials costs, and the homogeneous path's peer.
        group.bench_function(format!("assemble_elementwise/{dofs}"), |b| {
            let mut k = problem.assembler().pattern().zeros();
            let constitutive = [Some(materials().0[0].constitutive(Formulation::Solid))];
            b.iter(|| {
                problem
                    .assembler()
                    .assemble_into(&constitutive, &mut k)
                    .unwrap()
            })
        });
        group.bench_function(format!("assemble_factorize/{dofs}"), |b| {
            b.iter(|| problem.factorize(&materials()).unwrap())
        });
        problem.factorize(&materials()).unwrap();
        group.bench_function(format!("solve/{dofs}"), |b| {
            b.iter(|| black_box(problem.solve(&loads).unwrap()))
        });
    }
    group.finish();
}

/// The diagnosis's `out_of_plane` slab (the default 21 x 21 marker grid:
/// 20 x 20 plan cells, two layers): the whole slab mirrored in its
/// mid-plane against its upper half with u_z held on z = 0, which gives
/// the same displacement. Factorisation, and a block of 160 right-hand
/// sides (a fit evaluation's needle frames times their placement rounds).
fn bench_slab_halves(c: &mut Criterion) {
    let mut group = c.benchmark_group("slab_mirrored");
    group.sample_size(10);
    let slab = SlabMesh::new(
        RectangleMesh::uniform(0.075, 0.075, 20, 20).unwrap(),
        0.0075,
        2,
    )
    .unwrap();
    for (name, mesh) in [
        ("whole", slab.build_symmetric(ElementKind::Tet10).unwrap()),
        (
            "upper_half",
            slab.build_upper_half(ElementKind::Tet10).unwrap(),
        ),
    ] {
        let mut held = Dirichlet::fixed_face(&mesh, Face::Back);
        if name == "upper_half" {
            held.set_nodes(&mesh, &mesh.nodes_on_face(Face::Bottom), 2, 0.0)
                .unwrap();
        }
        let mut problem = LinearProblem::new(
            Assembler::new(mesh, Formulation::Solid).unwrap(),
            vec![],
            held,
        )
        .unwrap();
        let dofs = problem.mesh().dof_count();
        let loads: Vec<Vec<f64>> = (0..160)
            .map(|k| {
                (0..dofs)
                    .map(|d| {
                        if d % 3 == 1 && d % 160 == k {
                            -1e-3
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
            .collect();
        let refs: Vec<&[f64]> = loads.iter().map(Vec::as_slice).collect();
        group.bench_function(format!("assemble_factorize/{name}/{dofs}"), |b| {
            b.iter(|| problem.factorize(&materials()).unwrap())
        });
        problem.factorize(&materials()).unwrap();
        group.bench_function(format!("solve_160/{name}/{dofs}"), |b| {
            b.iter(|| black_box(problem.displacements_many(&refs).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_plane, bench_slab, bench_slab_halves);
criterion_main!(benches);
