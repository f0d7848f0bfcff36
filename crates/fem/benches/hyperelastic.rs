//! Cost of the neo-Hookean internal force $f_\text{int}(u)$ and tangent
//! $K_T(u)$ assemblies on a plane-strain T6 mesh of about 13k dofs, next to
//! the linear $K$ assembly of the same mesh.
//!
//! `cargo bench -p needle-fem --bench hyperelastic -- --warm-up-time 1 --measurement-time 5`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use needle_fem::{
    Assembler, ElementKind, Formulation, HyperelasticAssembler, Material, Materials, RectangleMesh,
};

fn bench_plane(c: &mut Criterion) {
    let materials = Materials::homogeneous(Material::new(25.3e3, 0.48).unwrap());
    // 40 x 40 cells: 2 * 81^2 = 13122 dofs.
    let cells = 40;
    let mesh = RectangleMesh::uniform(0.075, 0.075, cells, cells)
        .unwrap()
        .build(ElementKind::Tri6)
        .unwrap();
    let dofs = mesh.dof_count();
    let assembler = Assembler::new(mesh, Formulation::PlaneStrain { thickness: 0.0075 }).unwrap();
    let hyper = HyperelasticAssembler::new(assembler.clone()).unwrap();
    // A 10 % stretch along y with some shear, so that no shortcut applies.
    let u: Vec<f64> = (0..dofs)
        .map(|d| {
            let x = hyper.mesh().node(d / 2);
            if d % 2 == 1 { 0.1 * x[1] } else { 0.05 * x[1] }
        })
        .collect();
    let mut group = c.benchmark_group("hyperelastic_t6");
    group.sample_size(20);
    group.bench_function(format!("linear_stiffness/{dofs}"), |b| {
        let mut k = assembler.pattern().zeros();
        b.iter(|| assembler.stiffness_into(&materials, &mut k).unwrap())
    });
    group.bench_function(format!("internal_force/{dofs}"), |b| {
        let mut f = vec![0.0; dofs];
        b.iter(|| {
            hyper.assemble_into(&materials, &u, &mut f, None).unwrap();
            black_box(&f);
        })
    });
    group.bench_function(format!("internal_force_and_tangent/{dofs}"), |b| {
        let mut f = vec![0.0; dofs];
        let mut k = assembler.pattern().zeros();
        b.iter(|| {
            hyper
                .assemble_into(&materials, &u, &mut f, Some(&mut k))
                .unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, bench_plane);
criterion_main!(benches);
