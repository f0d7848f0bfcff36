//! Synthetic symmetric positive definite models for tests, examples and
//! benchmarks: a vector graph Laplacian on a regular grid, one random SPD
//! `d x d` block per edge, with the nodes of the bottom layer fixed.

use faer::sparse::{SparseColMat, Triplet};

use crate::CondenseError;
use crate::drift::unit_random;

/// A stiffness matrix with its layout, ready for [`crate::FullModel::factor`].
#[derive(Debug, Clone)]
pub struct Lattice {
    /// Full stiffness (all dofs, both triangles).
    pub stiffness: SparseColMat<usize, f64>,
    /// Dofs per node, 2 or 3 (`shape.len()`).
    pub dofs_per_node: usize,
    /// Dofs of the fixed bottom layer (`y = 0`).
    pub fixed_dofs: Vec<usize>,
    /// Nodes along each axis.
    pub shape: Vec<usize>,
}

impl Lattice {
    /// A `shape[0] x shape[1] (x shape[2])` grid (2 or 3 axes, each at least 2)
    /// with edges to the axis and diagonal neighbours and edge blocks
    /// `L L^T + 0.1 I` (`L` uniform in [-1, 1] from `seed`).
    pub fn new(shape: &[usize], seed: u64) -> Result<Self, CondenseError> {
        if !matches!(shape.len(), 2 | 3) {
            return Err(CondenseError::Dimension(shape.len()));
        }
        if let Some(&short) = shape.iter().find(|&&s| s < 2) {
            return Err(CondenseError::Length {
                what: "lattice axis (nodes)",
                got: short,
                expected: 2,
            });
        }
        let d = shape.len();
        let n_nodes: usize = shape.iter().product();
        let index = |p: &[usize]| linear(p, shape);
        let mut state = seed;
        let mut triplets = Vec::new();
        let offsets: Vec<Vec<usize>> = (1..(1usize << d))
            .map(|mask| (0..d).map(|a| (mask >> a) & 1).collect())
            .collect();
        for node in 0..n_nodes {
            let p = position(node, shape);
            for offset in &offsets {
                let q: Vec<usize> = p.iter().zip(offset).map(|(a, b)| a + b).collect();
                if q.iter().zip(shape).any(|(c, s)| c >= s) {
                    continue;
                }
                let other = index(&q);
                let mut l = [[0.0; 3]; 3];
                for row in l.iter_mut().take(d) {
                    for v in row.iter_mut().take(d) {
                        *v = 2.0 * unit_random(&mut state) - 1.0;
                    }
                }
                for a in 0..d {
                    for b in 0..d {
                        let k: f64 = (0..d).map(|c| l[a][c] * l[b][c]).sum::<f64>()
                            + if a == b { 0.1 } else { 0.0 };
                        for (i, j, sign) in [
                            (node, node, 1.0),
                            (other, other, 1.0),
                            (node, other, -1.0),
                            (other, node, -1.0),
                        ] {
                            triplets.push(Triplet::new(i * d + a, j * d + b, sign * k));
                        }
                    }
                }
            }
        }
        let n = n_nodes * d;
        let stiffness =
            SparseColMat::try_new_from_triplets(n, n, &triplets).expect("valid triplets");
        let fixed_dofs = (0..n_nodes)
            .filter(|&node| position(node, shape)[1] == 0)
            .flat_map(|node| (0..d).map(move |a| node * d + a))
            .collect();
        Ok(Self {
            stiffness,
            dofs_per_node: d,
            fixed_dofs,
            shape: shape.to_vec(),
        })
    }

    /// Number of nodes.
    pub fn n_nodes(&self) -> usize {
        self.shape.iter().product()
    }

    /// Nodes with no fixed dof (those that may become working nodes).
    pub fn free_nodes(&self) -> Vec<usize> {
        (0..self.n_nodes())
            .filter(|&node| position(node, &self.shape)[1] != 0)
            .collect()
    }
}

fn linear(p: &[usize], shape: &[usize]) -> usize {
    p.iter()
        .zip(shape)
        .rev()
        .fold(0, |acc, (&c, &s)| acc * s + c)
}

fn position(node: usize, shape: &[usize]) -> Vec<usize> {
    let mut rest = node;
    shape
        .iter()
        .map(|&s| {
            let c = rest % s;
            rest /= s;
            c
        })
        .collect()
}
