//! Error norms of a finite-element displacement against an exact field,
//! integrated element by element with a high-order collapsed Gauss rule
//! (independent of the rules used to build the system):
//! $\|u - u_h\|_{L^2} = \left(\int_\Omega |u - u_h|^2\right)^{1/2}$ and
//! $|u - u_h|_{H^1} = \left(\int_\Omega |\nabla u - \nabla u_h|^2\right)^{1/2}$.

use crate::element::facet::simplex_points;
use crate::error::FemError;
use crate::load::pad;
use crate::locate::Location;
use crate::mesh::Mesh;
use crate::stress::displacement_gradient;

/// $L^2$ norm of $u - u_h$ and $H^1$ seminorm of the error, in that order.
/// `exact` gives $u$ and `exact_gradient` gives $\partial u_i/\partial x_j$
/// (row `i`).
pub fn error_norms<const D: usize>(
    mesh: &Mesh<D>,
    displacement: &[f64],
    exact: impl Fn([f64; D]) -> [f64; D],
    exact_gradient: impl Fn([f64; D]) -> [[f64; D]; D],
) -> Result<(f64, f64), FemError> {
    if displacement.len() != mesh.dof_count() {
        return Err(FemError::DimensionMismatch {
            context: "displacement",
            expected: mesh.dof_count(),
            actual: displacement.len(),
        });
    }
    let (mut l2, mut h1) = (0.0, 0.0);
    for e in 0..mesh.element_count() {
        let nodes = mesh.element(e);
        let coordinates: Vec<[f64; 3]> = nodes.iter().map(|&n| pad(mesh.node(n))).collect();
        // Degree 8 rule: well above the degree of the FE error terms.
        let points = simplex_points(&coordinates, D, 8);
        let corners: Vec<[f64; D]> = nodes[..=D].iter().map(|&n| mesh.node(n)).collect();
        for ((n, position), w) in points
            .shape
            .iter()
            .zip(&points.position)
            .zip(&points.weight)
        {
            let mut x = [0.0; D];
            x.copy_from_slice(&position[..D]);
            let u = exact(x);
            for i in 0..D {
                let uh: f64 = nodes
                    .iter()
                    .enumerate()
                    .map(|(a, &node)| n[a] * displacement[node * D + i])
                    .sum();
                l2 += w * (u[i] - uh).powi(2);
            }
            let location = Location {
                element: e,
                reference: reference_of(&corners, x),
            };
            let gh = displacement_gradient(mesh, displacement, &location)?;
            let g = exact_gradient(x);
            for i in 0..D {
                for j in 0..D {
                    h1 += w * (g[i][j] - gh[(i, j)]).powi(2);
                }
            }
        }
    }
    Ok((l2.sqrt(), h1.sqrt()))
}

/// Reference coordinates of `x` in the straight-sided simplex with `corners`.
fn reference_of<const D: usize>(corners: &[[f64; D]], x: [f64; D]) -> [f64; D] {
    let jacobian =
        nalgebra::SMatrix::<f64, D, D>::from_fn(|i, j| corners[j + 1][i] - corners[0][i]);
    let (_, inverse) = crate::element::stiffness::determinant_and_inverse(&jacobian);
    let rhs = nalgebra::SVector::<f64, D>::from_fn(|i, _| x[i] - corners[0][i]);
    let xi = inverse * rhs;
    std::array::from_fn(|j| xi[j])
}
