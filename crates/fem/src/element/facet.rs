//! Integrals over simplices embedded in space: element edges and faces
//! (facets) and whole 2-D elements. Used for distributed springs
//! (elastic supports, foundations) and distributed loads (tractions).
//!
//! For a simplex with nodes $x_a$ and shape functions $N_a$ of parametric
//! dimension $P$, the measure is $dA = \sqrt{\det(J^TJ)}\,d\xi$ with
//! $J = \partial x/\partial\xi$ ($D \times P$).

use super::{quadrature, shape};

/// Quadrature points on a simplex: shape values and measure weight.
pub struct SimplexPoints {
    /// Shape function values at each point.
    pub shape: Vec<Vec<f64>>,
    /// Physical position of each point (padded to 3).
    pub position: Vec<[f64; 3]>,
    /// Quadrature weight times the measure element $dA$ at each point.
    pub weight: Vec<f64>,
}

/// Quadrature points on the simplex with the given node coordinates
/// (each padded to 3) and parametric dimension, using a rule exact for
/// polynomials of `degree` on straight-sided simplices.
pub fn simplex_points(coordinates: &[[f64; 3]], param_dim: usize, degree: usize) -> SimplexPoints {
    let rule: Vec<(Vec<f64>, f64)> = match param_dim {
        1 => quadrature::collapsed_rule::<1>((degree + 2).div_ceil(2))
            .into_iter()
            .map(|(x, w)| (x.iter().copied().collect(), w))
            .collect(),
        2 => quadrature::collapsed_rule::<2>((degree + 2).div_ceil(2))
            .into_iter()
            .map(|(x, w)| (x.iter().copied().collect(), w))
            .collect(),
        _ => quadrature::collapsed_rule::<3>((degree + 3).div_ceil(2))
            .into_iter()
            .map(|(x, w)| (x.iter().copied().collect(), w))
            .collect(),
    };
    let m = coordinates.len();
    let mut points = SimplexPoints {
        shape: Vec::new(),
        position: Vec::new(),
        weight: Vec::new(),
    };
    for (xi, w) in rule {
        let (n, g) = shape::values_and_gradients(param_dim, m, &xi);
        let mut position = [0.0; 3];
        // Columns of J: tangent vectors dx/dxi_j.
        let mut tangents = [[0.0; 3]; 3];
        for a in 0..m {
            for i in 0..3 {
                position[i] += n[a] * coordinates[a][i];
                for j in 0..param_dim {
                    tangents[j][i] += g[a][j] * coordinates[a][i];
                }
            }
        }
        let mut gram = [[0.0; 3]; 3];
        for p in 0..param_dim {
            for q in 0..param_dim {
                gram[p][q] = (0..3).map(|i| tangents[p][i] * tangents[q][i]).sum();
            }
        }
        let measure = match param_dim {
            1 => gram[0][0].sqrt(),
            2 => (gram[0][0] * gram[1][1] - gram[0][1] * gram[1][0])
                .max(0.0)
                .sqrt(),
            _ => {
                let t = &tangents;
                let det = t[0][0] * (t[1][1] * t[2][2] - t[1][2] * t[2][1])
                    - t[0][1] * (t[1][0] * t[2][2] - t[1][2] * t[2][0])
                    + t[0][2] * (t[1][0] * t[2][1] - t[1][1] * t[2][0]);
                det.abs()
            }
        };
        points.shape.push(n);
        points.position.push(position);
        points.weight.push(w * measure);
    }
    points
}

/// The consistent "mass" matrix $M_{ab} = \int N_a N_b \, dA$ of a simplex
/// (row-major, `m x m`): the spring matrix of a unit distributed support.
pub fn simplex_mass(coordinates: &[[f64; 3]], param_dim: usize, degree: usize) -> Vec<f64> {
    let m = coordinates.len();
    let points = simplex_points(coordinates, param_dim, 2 * degree);
    let mut mass = vec![0.0; m * m];
    for (n, w) in points.shape.iter().zip(&points.weight) {
        for a in 0..m {
            for b in 0..m {
                mass[a * m + b] += w * n[a] * n[b];
            }
        }
    }
    mass
}
