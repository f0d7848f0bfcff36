//! Element shape quality: a scale-free measure that is 1 for the regular
//! simplex and tends to 0 as an element degenerates.
//!
//! For a triangle with area $A$ and edge lengths $l_k$,
//! $q = 4\sqrt{3}\,A / \sum_k l_k^2$; for a tetrahedron with volume $V$ and
//! edge lengths $l_k$, $q = 6\sqrt{2}\,V / l_{\text{rms}}^3$ with
//! $l_{\text{rms}}^2 = \tfrac16 \sum_k l_k^2$. Both are computed on the
//! corner nodes (the meshes built here have straight-sided elements).
//! Badly shaped elements degrade the conditioning of $K$ and the accuracy of
//! stresses long before they invert, so meshes of user geometry should be
//! checked.

use super::Mesh;

/// Quality figures of a whole mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct QualityReport {
    /// Smallest element quality.
    pub worst: f64,
    /// Element with the smallest quality.
    pub worst_element: usize,
    /// Mean element quality.
    pub mean: f64,
    /// Elements whose quality is below `threshold`.
    pub below_threshold: Vec<usize>,
}

impl<const D: usize> Mesh<D> {
    /// Shape quality of element `e` (1 for a regular simplex, 0 when flat).
    pub fn element_quality(&self, e: usize) -> f64 {
        let corners = &self.element(e)[..=D];
        let point = |k: usize| self.node(corners[k]);
        let mut squared_edges = 0.0;
        for a in 0..=D {
            for b in a + 1..=D {
                let (p, q) = (point(a), point(b));
                squared_edges += (0..D).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>();
            }
        }
        // |det| of the edge vectors from corner 0: 2 A in 2-D, 6 V in 3-D.
        let origin = point(0);
        let edge = |k: usize| -> [f64; 3] {
            let p = point(k);
            let mut v = [0.0; 3];
            for i in 0..D {
                v[i] = p[i] - origin[i];
            }
            v
        };
        match D {
            2 => {
                let (u, v) = (edge(1), edge(2));
                let area = 0.5 * (u[0] * v[1] - u[1] * v[0]).abs();
                4.0 * 3f64.sqrt() * area / squared_edges
            }
            _ => {
                let (u, v, w) = (edge(1), edge(2), edge(3));
                let determinant = u[0] * (v[1] * w[2] - v[2] * w[1])
                    - u[1] * (v[0] * w[2] - v[2] * w[0])
                    + u[2] * (v[0] * w[1] - v[1] * w[0]);
                let volume = determinant.abs() / 6.0;
                let rms_edge = (squared_edges / 6.0).sqrt();
                6.0 * 2f64.sqrt() * volume / rms_edge.powi(3)
            }
        }
    }

    /// Quality of every element, with the elements below `threshold` listed
    /// (0.1 flags slivers that usually deserve remeshing).
    pub fn quality(&self, threshold: f64) -> QualityReport {
        let mut report = QualityReport {
            worst: f64::INFINITY,
            worst_element: 0,
            mean: 0.0,
            below_threshold: Vec::new(),
        };
        let count = self.element_count();
        for e in 0..count {
            let q = self.element_quality(e);
            if q < report.worst {
                report.worst = q;
                report.worst_element = e;
            }
            if q < threshold {
                report.below_threshold.push(e);
            }
            report.mean += q / count as f64;
        }
        report
    }
}
