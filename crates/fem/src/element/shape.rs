//! Shape functions of the reference simplices and their gradients.
//!
//! Linear: $N_i = L_i$. Quadratic: corners $N_i = L_i(2L_i - 1)$ and mid-edge
//! nodes $N_{ij} = 4L_iL_j$, in the local order of [`super::ElementKind`].
//! Gradients with respect to the reference coordinates $\xi$ use
//! $\partial L_0/\partial\xi_j = -1$ and $\partial L_i/\partial\xi_j = \delta_{i-1,j}$.

use nalgebra::{SMatrix, SVector};

use super::{TETRAHEDRON_EDGES, TRIANGLE_EDGES};

/// Barycentric coordinates $[L_0, \dots, L_D]$ of reference point `xi`
/// (padded with zeros to length 4).
pub fn barycentric<const D: usize>(xi: &SVector<f64, D>) -> [f64; 4] {
    let mut l = [0.0; 4];
    l[0] = 1.0 - xi.sum();
    for j in 0..D {
        l[j + 1] = xi[j];
    }
    l
}

fn edges(dimension: usize) -> &'static [(usize, usize)] {
    match dimension {
        1 => &[(0, 1)],
        2 => &TRIANGLE_EDGES,
        _ => &TETRAHEDRON_EDGES,
    }
}

/// Gradient of $L_i$ with respect to $\xi_j$.
fn barycentric_gradient(i: usize, j: usize) -> f64 {
    if i == 0 {
        -1.0
    } else if i == j + 1 {
        1.0
    } else {
        0.0
    }
}

/// Values and reference gradients of the simplex shape functions of
/// parametric dimension `param_dim` (1, 2 or 3) with `node_count` nodes, for
/// code that handles edges, faces and cells alike. Gradients are
/// `gradient[a][j]` $= \partial N_a/\partial\xi_j$ (padded to 3).
pub fn values_and_gradients(
    param_dim: usize,
    node_count: usize,
    xi: &[f64],
) -> (Vec<f64>, Vec<[f64; 3]>) {
    fn pack<const D: usize, const N: usize>(xi: &[f64]) -> (Vec<f64>, Vec<[f64; 3]>) {
        let xi = SVector::<f64, D>::from_fn(|j, _| xi[j]);
        let n = values::<D, N>(&xi);
        let g = gradients::<D, N>(&xi);
        let grads = (0..N)
            .map(|a| {
                let mut row = [0.0; 3];
                for j in 0..D {
                    row[j] = g[(j, a)];
                }
                row
            })
            .collect();
        (n.iter().copied().collect(), grads)
    }
    match (param_dim, node_count) {
        (1, 2) => pack::<1, 2>(xi),
        (1, 3) => pack::<1, 3>(xi),
        (2, 3) => pack::<2, 3>(xi),
        (2, 6) => pack::<2, 6>(xi),
        (3, 4) => pack::<3, 4>(xi),
        (3, 10) => pack::<3, 10>(xi),
        _ => unreachable!("no simplex element with {node_count} nodes in {param_dim} dimensions"),
    }
}

/// Values $N_a(\xi)$ of the `N` shape functions of the `D`-simplex
/// (linear if `N == D + 1`, quadratic otherwise).
pub fn values<const D: usize, const N: usize>(xi: &SVector<f64, D>) -> SVector<f64, N> {
    let l = barycentric(xi);
    let mut n = SVector::<f64, N>::zeros();
    if N == D + 1 {
        for a in 0..N {
            n[a] = l[a];
        }
    } else {
        for a in 0..=D {
            n[a] = l[a] * (2.0 * l[a] - 1.0);
        }
        for (k, &(a, b)) in edges(D).iter().enumerate() {
            n[D + 1 + k] = 4.0 * l[a] * l[b];
        }
    }
    n
}

/// Reference gradients $\partial N_a/\partial\xi_j$ as a `D x N` matrix
/// (column `a` is the gradient of $N_a$).
pub fn gradients<const D: usize, const N: usize>(xi: &SVector<f64, D>) -> SMatrix<f64, D, N> {
    let l = barycentric(xi);
    let mut g = SMatrix::<f64, D, N>::zeros();
    if N == D + 1 {
        for a in 0..N {
            for j in 0..D {
                g[(j, a)] = barycentric_gradient(a, j);
            }
        }
    } else {
        for a in 0..=D {
            for j in 0..D {
                g[(j, a)] = (4.0 * l[a] - 1.0) * barycentric_gradient(a, j);
            }
        }
        for (k, &(a, b)) in edges(D).iter().enumerate() {
            for j in 0..D {
                g[(j, D + 1 + k)] =
                    4.0 * (l[b] * barycentric_gradient(a, j) + l[a] * barycentric_gradient(b, j));
            }
        }
    }
    g
}

/// Reference coordinates of the `N` nodes of the `D`-simplex, column per node.
pub fn reference_nodes<const D: usize, const N: usize>() -> SMatrix<f64, D, N> {
    let mut x = SMatrix::<f64, D, N>::zeros();
    for a in 1..=D {
        x[(a - 1, a)] = 1.0;
    }
    if N > D + 1 {
        for (k, &(a, b)) in edges(D).iter().enumerate() {
            let mid = (x.column(a) + x.column(b)) * 0.5;
            x.set_column(D + 1 + k, &mid);
        }
    }
    x
}
