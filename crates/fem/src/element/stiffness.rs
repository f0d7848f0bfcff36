//! Element (local) stiffness matrices
//! $K^e = \int_{\Omega^e} B^T D B \, d\Omega$ (times the out-of-plane
//! thickness in 2-D), the $A^e$ of the paper's equation (3).
//!
//! $B$ maps the element's interleaved nodal displacements
//! $[u_{x,0}, u_{y,0}(, u_{z,0}), u_{x,1}, \dots]$ to Voigt strains; its
//! block for node $a$ is, with $N_{a,x} = \partial N_a/\partial x$,
//! $\begin{bmatrix} N_{a,x} & 0 \\ 0 & N_{a,y} \\ N_{a,y} & N_{a,x}\end{bmatrix}$ in 2-D and
//! the analogous 6x3 block in 3-D.

use nalgebra::SMatrix;

use super::{quadrature, shape};

/// Reference gradients and weights at the quadrature points of a rule,
/// precomputed once per element kind.
#[derive(Debug, Clone)]
pub struct ReferenceGradients<const D: usize, const N: usize> {
    /// `(dN/dxi, weight)` at each quadrature point.
    pub points: Vec<(SMatrix<f64, D, N>, f64)>,
}

impl<const D: usize, const N: usize> ReferenceGradients<D, N> {
    /// Gradients at the points of the rule exact for the stiffness of a
    /// straight-sided element of this kind (degree $2(p-1)$).
    pub fn for_stiffness() -> Self {
        let degree = if N == D + 1 { 0 } else { 2 };
        Self::for_degree(degree)
    }

    /// Gradients at the points of a rule exact for polynomials of `degree`.
    pub fn for_degree(degree: usize) -> Self {
        let points = quadrature::simplex_rule::<D>(degree)
            .iter()
            .map(|(xi, w)| (shape::gradients::<D, N>(xi), *w))
            .collect();
        Self { points }
    }
}

/// Physical shape-function gradients $\nabla_x N$ (`D x N`) and the
/// Jacobian determinant at one point, from nodal coordinates (`D x N`,
/// column per node) and reference gradients.
pub fn physical_gradients<const D: usize, const N: usize>(
    coordinates: &SMatrix<f64, D, N>,
    reference: &SMatrix<f64, D, N>,
) -> (SMatrix<f64, D, N>, f64) {
    // J_ij = dx_i/dxi_j = sum_a x_{a,i} dN_a/dxi_j.
    let jacobian: SMatrix<f64, D, D> = coordinates * reference.transpose();
    let (determinant, inverse) = determinant_and_inverse(&jacobian);
    (inverse.transpose() * reference, determinant)
}

/// Determinant and inverse of a 1x1, 2x2 or 3x3 matrix by cofactors (the
/// inverse is zero when the determinant is zero). Written out because
/// nalgebra's generic versions need dimension bounds that a const-generic
/// `D` cannot state.
pub fn determinant_and_inverse<const D: usize>(
    m: &SMatrix<f64, D, D>,
) -> (f64, SMatrix<f64, D, D>) {
    let mut inverse = SMatrix::<f64, D, D>::zeros();
    let determinant = match D {
        1 => {
            let det = m[(0, 0)];
            if det != 0.0 {
                inverse[(0, 0)] = 1.0 / det;
            }
            det
        }
        2 => {
            let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
            if det != 0.0 {
                inverse[(0, 0)] = m[(1, 1)] / det;
                inverse[(0, 1)] = -m[(0, 1)] / det;
                inverse[(1, 0)] = -m[(1, 0)] / det;
                inverse[(1, 1)] = m[(0, 0)] / det;
            }
            det
        }
        _ => {
            let c = |i: usize, j: usize| {
                let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
                let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
                m[(i1, j1)] * m[(i2, j2)] - m[(i1, j2)] * m[(i2, j1)]
            };
            let det = m[(0, 0)] * c(0, 0) + m[(0, 1)] * c(0, 1) + m[(0, 2)] * c(0, 2);
            if det != 0.0 {
                for i in 0..3 {
                    for j in 0..3 {
                        inverse[(j, i)] = c(i, j) / det;
                    }
                }
            }
            det
        }
    };
    (determinant, inverse)
}

/// The strain-displacement matrix $B$ (`S x (D*N)`) from physical gradients.
pub fn strain_displacement<const D: usize, const N: usize, const S: usize, const NDOF: usize>(
    gradients: &SMatrix<f64, D, N>,
) -> SMatrix<f64, S, NDOF> {
    let mut b = SMatrix::<f64, S, NDOF>::zeros();
    for a in 0..N {
        let c = a * D;
        if D == 2 {
            let (gx, gy) = (gradients[(0, a)], gradients[(1, a)]);
            b[(0, c)] = gx;
            b[(1, c + 1)] = gy;
            b[(2, c)] = gy;
            b[(2, c + 1)] = gx;
        } else {
            let (gx, gy, gz) = (gradients[(0, a)], gradients[(1, a)], gradients[(2, a)]);
            b[(0, c)] = gx;
            b[(1, c + 1)] = gy;
            b[(2, c + 2)] = gz;
            b[(3, c + 1)] = gz;
            b[(3, c + 2)] = gy;
            b[(4, c)] = gz;
            b[(4, c + 2)] = gx;
            b[(5, c)] = gy;
            b[(5, c + 1)] = gx;
        }
    }
    b
}

/// Element stiffness $K^e = s \sum_q w_q B_q^T D B_q \det J_q$ with scale
/// $s$ (the out-of-plane thickness in 2-D). Returns the smallest Jacobian
/// determinant as the error if it is not positive (inverted or degenerate
/// element), relative to the element's size.
pub fn element_stiffness<const D: usize, const N: usize, const S: usize, const NDOF: usize>(
    coordinates: &SMatrix<f64, D, N>,
    reference: &ReferenceGradients<D, N>,
    constitutive: &SMatrix<f64, S, S>,
    scale: f64,
) -> Result<SMatrix<f64, NDOF, NDOF>, f64> {
    let mut k = SMatrix::<f64, NDOF, NDOF>::zeros();
    let size = characteristic_volume(coordinates);
    for (grad_ref, weight) in &reference.points {
        let (gradients, determinant) = physical_gradients(coordinates, grad_ref);
        if determinant.partial_cmp(&(1e-12 * size)) != Some(std::cmp::Ordering::Greater) {
            return Err(determinant);
        }
        let b = strain_displacement::<D, N, S, NDOF>(&gradients);
        let db = constitutive * b;
        k += b.transpose() * db * (weight * determinant * scale);
    }
    Ok(k)
}

/// A volume scale of the element (bounding-box extent to the power `D`),
/// used to make the degeneracy test scale-free.
fn characteristic_volume<const D: usize, const N: usize>(coordinates: &SMatrix<f64, D, N>) -> f64 {
    let mut extent: f64 = 0.0;
    for i in 0..D {
        let row = coordinates.row(i);
        extent = extent.max(row.max() - row.min());
    }
    extent.powi(D as i32)
}
