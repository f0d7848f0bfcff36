//! Test support: an independent direct solver for the mixed boundary-value
//! problem with rotated node frames on the full mesh (dense nalgebra Cholesky
//! on the assembled matrix; it shares nothing with the condensed machinery).

#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};
use needle_condense::Frame;
use needle_condense::lattice::Lattice;

/// One working node as the test sees it.
#[derive(Debug, Clone)]
pub struct WorkingNode {
    pub node: usize,
    pub frame: Frame,
    /// true: displacement given on that local axis.
    pub displacement_given: [bool; 3],
    pub prescribed: [f64; 3],
}

/// Dense free-dof stiffness with its layout.
pub struct Reference {
    pub stiffness: DMatrix<f64>,
    pub free_index: Vec<Option<usize>>,
    pub d: usize,
}

impl Reference {
    pub fn new(lattice: &Lattice) -> Self {
        Self::from_stiffness(
            &lattice.stiffness,
            lattice.dofs_per_node,
            &lattice.fixed_dofs,
        )
    }

    pub fn from_stiffness(
        matrix: &faer::sparse::SparseColMat<usize, f64>,
        d: usize,
        fixed_dofs: &[usize],
    ) -> Self {
        let n = matrix.nrows();
        let mut free_index = vec![None; n];
        let mut next = 0;
        for (dof, slot) in free_index.iter_mut().enumerate() {
            if !fixed_dofs.contains(&dof) {
                *slot = Some(next);
                next += 1;
            }
        }
        let mut stiffness = DMatrix::zeros(next, next);
        for t in matrix.triplet_iter() {
            if let (Some(i), Some(j)) = (free_index[t.row], free_index[t.col]) {
                stiffness[(i, j)] += *t.val;
            }
        }
        Self {
            stiffness,
            free_index,
            d,
        }
    }

    /// Solves the mixed problem; returns, per working node and local axis, the
    /// (displacement, force) pair in the node frame.
    pub fn solve(&self, working: &[WorkingNode]) -> Vec<[(f64, f64); 3]> {
        let d = self.d;
        let n = self.stiffness.nrows();
        // K_l = A^T K A with A the node rotations.
        let mut a = DMatrix::<f64>::identity(n, n);
        for w in working {
            for r in 0..d {
                for c in 0..d {
                    let (i, j) = (self.dof(w.node, r), self.dof(w.node, c));
                    a[(i, j)] = w.frame[r][c];
                }
            }
        }
        let k_local = a.transpose() * &self.stiffness * &a;
        let mut given_u = vec![None; n];
        let mut force = DVector::<f64>::zeros(n);
        for w in working {
            for axis in 0..d {
                let i = self.dof(w.node, axis);
                if w.displacement_given[axis] {
                    given_u[i] = Some(w.prescribed[axis]);
                } else {
                    force[i] = w.prescribed[axis];
                }
            }
        }
        let free: Vec<usize> = (0..n).filter(|&i| given_u[i].is_none()).collect();
        let fixed: Vec<usize> = (0..n).filter(|&i| given_u[i].is_some()).collect();
        let mut u = DVector::<f64>::zeros(n);
        for &i in &fixed {
            u[i] = given_u[i].unwrap();
        }
        let k_ff = DMatrix::from_fn(free.len(), free.len(), |r, c| k_local[(free[r], free[c])]);
        let rhs = DVector::from_fn(free.len(), |r, _| {
            force[free[r]]
                - fixed
                    .iter()
                    .map(|&j| k_local[(free[r], j)] * u[j])
                    .sum::<f64>()
        });
        let u_f = k_ff.cholesky().expect("SPD reduced stiffness").solve(&rhs);
        for (r, &i) in free.iter().enumerate() {
            u[i] = u_f[r];
        }
        let f_all = &k_local * &u;
        working
            .iter()
            .map(|w| {
                let mut out = [(0.0, 0.0); 3];
                for (axis, o) in out.iter_mut().enumerate().take(d) {
                    let i = self.dof(w.node, axis);
                    *o = (u[i], f_all[i]);
                }
                out
            })
            .collect()
    }

    fn dof(&self, node: usize, axis: usize) -> usize {
        self.free_index[node * self.d + axis].expect("working nodes are free")
    }
}

/// Rotation about a unit axis (3-D) or in the plane (2-D, `axis` ignored).
pub fn rotation(d: usize, angle: f64, axis: [f64; 3]) -> Frame {
    let (s, c) = angle.sin_cos();
    let mut r = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    if d == 2 {
        r[0][0] = c;
        r[0][1] = -s;
        r[1][0] = s;
        r[1][1] = c;
        return r;
    }
    let norm = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let k = [axis[0] / norm, axis[1] / norm, axis[2] / norm];
    for i in 0..3 {
        for j in 0..3 {
            let cross = match (i, j) {
                (0, 1) => -k[2],
                (0, 2) => k[1],
                (1, 0) => k[2],
                (1, 2) => -k[0],
                (2, 0) => -k[1],
                (2, 1) => k[0],
                _ => 0.0,
            };
            r[i][j] = if i == j { c } else { 0.0 } + s * cross + (1.0 - c) * k[i] * k[j];
        }
    }
    r
}

pub fn compose(a: &Frame, b: &Frame) -> Frame {
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}

/// nalgebra copy of a faer matrix.
pub fn to_nalgebra(m: &faer::Mat<f64>) -> DMatrix<f64> {
    DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

/// max |a - b| / max |b|.
pub fn relative_difference(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax()
}
