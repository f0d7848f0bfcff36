//! Structured triangulation of the rectangle $\[0,w\]\times\[0,d\]$ whose
//! nodes include every point of a marker grid.
//!
//! Grid lines are the marker coordinates plus the rectangle's edges; each
//! interval between consecutive lines is split into equal parts so that no
//! element is longer than the smallest marker spacing divided by the
//! refinement factor. Each grid cell is cut into two triangles along a
//! diagonal that alternates in a checkerboard ("union jack") pattern, so the
//! mesh has no preferred diagonal direction.

use super::Mesh;
use crate::element::ElementKind;
use crate::error::{FemError, finite, positive};

/// The distinct marker coordinates along x and y (a grid of
/// `x.len() * y.len()` markers), each inside the rectangle.
#[derive(Debug, Clone, PartialEq)]
pub struct MarkerGrid {
    /// Marker x coordinates (columns of the grid).
    pub x: Vec<f64>,
    /// Marker y coordinates (rows of the grid).
    pub y: Vec<f64>,
}

impl MarkerGrid {
    /// An evenly spaced grid of `nx x ny` markers from `(x0, y0)` to
    /// `(x1, y1)` inclusive.
    pub fn uniform(nx: usize, ny: usize, (x0, y0): (f64, f64), (x1, y1): (f64, f64)) -> Self {
        let line = |n: usize, a: f64, b: f64| -> Vec<f64> {
            if n == 1 {
                vec![0.5 * (a + b)]
            } else {
                (0..n)
                    .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
                    .collect()
            }
        };
        Self {
            x: line(nx, x0, x1),
            y: line(ny, y0, y1),
        }
    }

    /// All marker points in row-major order (x fastest), the order of
    /// `markers_rest.csv` ids.
    pub fn points(&self) -> Vec<[f64; 2]> {
        self.y
            .iter()
            .flat_map(|&y| self.x.iter().map(move |&x| [x, y]))
            .collect()
    }
}

/// Builder of a structured triangle mesh of the rectangle
/// $[0, \text{width}] \times [0, \text{depth}]$.
#[derive(Debug, Clone, PartialEq)]
pub struct RectangleMesh {
    /// Extent in x (m).
    pub width: f64,
    /// Extent in y (m).
    pub depth: f64,
    /// Grid lines in x, including 0 and `width`, strictly increasing.
    pub x_lines: Vec<f64>,
    /// Grid lines in y, including 0 and `depth`, strictly increasing.
    pub y_lines: Vec<f64>,
}

impl RectangleMesh {
    /// A uniform grid of `nx x ny` cells.
    pub fn uniform(width: f64, depth: f64, nx: usize, ny: usize) -> Result<Self, FemError> {
        positive("rectangle width", width)?;
        positive("rectangle depth", depth)?;
        if nx == 0 || ny == 0 {
            return Err(FemError::InvalidMesh(
                "a rectangle needs at least one cell per direction".into(),
            ));
        }
        Ok(Self {
            width,
            depth,
            x_lines: (0..=nx).map(|i| width * i as f64 / nx as f64).collect(),
            y_lines: (0..=ny).map(|j| depth * j as f64 / ny as f64).collect(),
        })
    }

    /// A grid with a node on every marker, refined so that every element
    /// edge along x and y is at most (smallest marker spacing) / `refinement`.
    pub fn with_markers(
        width: f64,
        depth: f64,
        markers: &MarkerGrid,
        refinement: usize,
    ) -> Result<Self, FemError> {
        positive("rectangle width", width)?;
        positive("rectangle depth", depth)?;
        if refinement == 0 {
            return Err(FemError::InvalidMesh(
                "refinement factor must be at least 1".into(),
            ));
        }
        let x_lines = lines("marker x", width, &markers.x)?;
        let y_lines = lines("marker y", depth, &markers.y)?;
        let spacing = |l: &[f64]| {
            l.windows(2)
                .map(|w| w[1] - w[0])
                .fold(f64::INFINITY, f64::min)
        };
        let marker_spacing = |m: &[f64]| {
            if m.len() < 2 {
                f64::INFINITY
            } else {
                m.windows(2)
                    .map(|w| w[1] - w[0])
                    .fold(f64::INFINITY, f64::min)
            }
        };
        let mut target = marker_spacing(&markers.x).min(marker_spacing(&markers.y));
        if !target.is_finite() {
            target = spacing(&x_lines).min(spacing(&y_lines));
        }
        let target = target / refinement as f64;
        Ok(Self {
            width,
            depth,
            x_lines: subdivide(&x_lines, target),
            y_lines: subdivide(&y_lines, target),
        })
    }

    /// Number of nodes of the linear mesh.
    pub fn corner_node_count(&self) -> usize {
        self.x_lines.len() * self.y_lines.len()
    }

    /// The triangle mesh with elements of `kind` (`Tri3` or `Tri6`), all in
    /// region 0.
    pub fn build(&self, kind: ElementKind) -> Result<Mesh<2>, FemError> {
        if kind.dimension() != 2 {
            return Err(FemError::InvalidMesh(format!(
                "a rectangle is meshed with triangles, not {kind:?}"
            )));
        }
        let (nx, ny) = (self.x_lines.len(), self.y_lines.len());
        let nodes: Vec<[f64; 2]> = self
            .y_lines
            .iter()
            .flat_map(|&y| self.x_lines.iter().map(move |&x| [x, y]))
            .collect();
        let id = |i: usize, j: usize| j * nx + i;
        let mut connectivity = Vec::with_capacity(6 * (nx - 1) * (ny - 1));
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                if (i + j) % 2 == 0 {
                    connectivity.extend_from_slice(&[a, b, c, a, c, d]);
                } else {
                    connectivity.extend_from_slice(&[a, b, d, b, c, d]);
                }
            }
        }
        let regions = vec![0; connectivity.len() / 3];
        let linear = Mesh::new(ElementKind::Tri3, nodes, connectivity, regions)?;
        if kind == ElementKind::Tri3 {
            Ok(linear)
        } else {
            linear.to_quadratic()
        }
    }
}

/// Sorted grid lines `0, markers..., extent`, checking that the markers are
/// finite, inside, and strictly increasing.
pub(crate) fn lines(
    field: &'static str,
    extent: f64,
    markers: &[f64],
) -> Result<Vec<f64>, FemError> {
    let mut lines = vec![0.0];
    for &m in markers {
        finite(field, m)?;
        if !(0.0..=extent).contains(&m) {
            return Err(FemError::InvalidValue {
                field,
                value: m,
                reason: "marker outside the rectangle",
            });
        }
        if m <= *lines.last().unwrap_or(&0.0) && !(lines.len() == 1 && m == 0.0) {
            return Err(FemError::InvalidValue {
                field,
                value: m,
                reason: "markers must be strictly increasing",
            });
        }
        if m > 0.0 {
            lines.push(m);
        }
    }
    if *lines.last().unwrap_or(&0.0) < extent {
        lines.push(extent);
    }
    Ok(lines)
}

/// Splits every interval between consecutive `lines` into the fewest equal
/// parts no longer than `target` (a small tolerance avoids an extra part
/// from round-off).
pub(crate) fn subdivide(lines: &[f64], target: f64) -> Vec<f64> {
    let mut out = vec![lines[0]];
    for w in lines.windows(2) {
        let parts = ((w[1] - w[0]) / target - 1e-9).ceil().max(1.0) as usize;
        for k in 1..=parts {
            out.push(if k == parts {
                w[1]
            } else {
                w[0] + (w[1] - w[0]) * k as f64 / parts as f64
            });
        }
    }
    out
}
