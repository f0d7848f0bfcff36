//! Helpers shared by the test binaries.
#![allow(dead_code)]

use needle_fem::{
    Assembler, Dirichlet, ElementKind, Formulation, LinearProblem, Material, Materials, Mesh,
    RectangleMesh, SlabMesh,
};

/// Deterministic pseudo-random numbers in [-1, 1) from a seed (splitmix64).
pub fn jitter(seed: u64, index: usize) -> f64 {
    let mut z = seed.wrapping_add((index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// A unit-square mesh of `n x n` cells with interior corner nodes moved by up
/// to `amount` times the cell size `h` in each coordinate (mid-edge nodes stay
/// at edge midpoints).
///
/// Every element stays valid for `amount` up to 1/4: a node moves at most
/// $\sqrt2\,a h$, so a vertex and the line of its opposite edge approach by
/// at most $2\sqrt2\,a h$, the smallest height of the undistorted right
/// triangles, $h/\sqrt2$, at $a = 1/4$ (reached only if all three nodes moved
/// their whole way). At 0.3 a seed of the patch test inverted an element
/// (session 33).
pub fn distorted_square(kind: ElementKind, n: usize, amount: f64, seed: u64) -> Mesh<2> {
    assert!(amount <= 0.25, "distortion {amount} may invert an element");
    let linear = RectangleMesh::uniform(1.0, 1.0, n, n)
        .unwrap()
        .build(ElementKind::Tri3)
        .unwrap();
    let h = 1.0 / n as f64;
    let nodes: Vec<[f64; 2]> = linear
        .nodes()
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let interior = p.iter().all(|&x| x > 1e-12 && x < 1.0 - 1e-12);
            if interior {
                [
                    p[0] + amount * h * jitter(seed, 2 * k),
                    p[1] + amount * h * jitter(seed, 2 * k + 1),
                ]
            } else {
                *p
            }
        })
        .collect();
    let mesh = Mesh::new(
        ElementKind::Tri3,
        nodes,
        linear.connectivity().to_vec(),
        linear.regions().to_vec(),
    )
    .unwrap();
    if kind == ElementKind::Tri3 {
        mesh
    } else {
        mesh.to_quadratic().unwrap()
    }
}

/// A unit-cube-ish slab mesh with interior corner nodes moved.
pub fn distorted_cube(kind: ElementKind, n: usize, amount: f64, seed: u64) -> Mesh<3> {
    let plan = RectangleMesh::uniform(1.0, 1.0, n, n).unwrap();
    let linear = SlabMesh::new(plan, 1.0, n)
        .unwrap()
        .build(ElementKind::Tet4)
        .unwrap();
    let h = 1.0 / n as f64;
    let nodes: Vec<[f64; 3]> = linear
        .nodes()
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let interior = p[0] > 1e-12
                && p[0] < 1.0 - 1e-12
                && p[1] > 1e-12
                && p[1] < 1.0 - 1e-12
                && p[2].abs() < 0.5 - 1e-12;
            if interior {
                std::array::from_fn(|i| p[i] + amount * h * jitter(seed, 3 * k + i))
            } else {
                *p
            }
        })
        .collect();
    let mesh = Mesh::new(
        ElementKind::Tet4,
        nodes,
        linear.connectivity().to_vec(),
        linear.regions().to_vec(),
    )
    .unwrap();
    if kind == ElementKind::Tet4 {
        mesh
    } else {
        mesh.to_quadratic().unwrap()
    }
}

/// Dense copy of a sparse matrix.
pub fn dense(matrix: &faer::sparse::SparseColMat<usize, f64>) -> nalgebra::DMatrix<f64> {
    let s = matrix.symbolic();
    let mut d = nalgebra::DMatrix::zeros(s.nrows(), s.ncols());
    for j in 0..s.ncols() {
        for p in s.col_ptr()[j]..s.col_ptr()[j + 1] {
            d[(s.row_idx()[p], j)] += matrix.val()[p];
        }
    }
    d
}

/// The displacement of `mesh` under nodal `loads` with `dirichlet` held,
/// one homogeneous `material`; the mesh is handed back.
pub fn solve<const D: usize>(
    mesh: Mesh<D>,
    formulation: Formulation,
    dirichlet: Dirichlet,
    material: Material,
    loads: &[f64],
) -> (Mesh<D>, Vec<f64>) {
    let mut problem = LinearProblem::new(
        Assembler::new(mesh, formulation).unwrap(),
        vec![],
        dirichlet,
    )
    .unwrap();
    problem
        .factorize(&Materials::homogeneous(material))
        .unwrap();
    let u = problem.solve(loads).unwrap().displacement;
    (problem.mesh().clone(), u)
}
