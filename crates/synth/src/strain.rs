//! The largest small-strain magnitude in the phantom, to check that a
//! trial stays in the linear range (the paper: below 15%).
//!
//! For each element, the displacement gradient $H = \nabla u$ at its
//! centroid gives $\varepsilon = (H + H^T)/2$; the value reported is the
//! largest absolute principal strain over all elements. Elements that
//! touch the needle line see its concentrated load and give the largest
//! values (mesh dependent, since a line load has a logarithmic singularity).

use needle_fem::element::shape::values_and_gradients;

use crate::body::Body;

/// Largest absolute principal strain over the element centroids.
pub(crate) fn peak_strain(body: &Body, u: &[f64]) -> f64 {
    let dim = body.dim;
    let centroid = vec![1.0 / (dim + 1) as f64; dim];
    let (_, reference) = values_and_gradients(dim, body.npe, &centroid);
    let mut peak = 0.0f64;
    for e in 0..body.element_count() {
        let nodes = body.element(e);
        // J_ij = sum_a x_a,i dN_a/dxi_j.
        let mut jac = nalgebra::Matrix3::<f64>::identity();
        for i in 0..dim {
            for j in 0..dim {
                jac[(i, j)] = nodes
                    .iter()
                    .zip(&reference)
                    .map(|(&n, g)| body.nodes[n][i] * g[j])
                    .sum();
            }
        }
        let Some(inverse) = jac.try_inverse() else {
            continue;
        };
        let mut h = nalgebra::Matrix3::<f64>::zeros();
        for (a, &n) in nodes.iter().enumerate() {
            // Physical gradient of N_a: J^-T times its reference gradient.
            let g = inverse.transpose()
                * nalgebra::Vector3::new(reference[a][0], reference[a][1], reference[a][2]);
            for i in 0..dim {
                for j in 0..dim {
                    h[(i, j)] += u[n * dim + i] * g[j];
                }
            }
        }
        let strain = 0.5 * (h + h.transpose());
        let eigen = strain.symmetric_eigenvalues();
        peak = eigen.iter().fold(peak, |m, v| m.max(v.abs()));
    }
    peak
}
