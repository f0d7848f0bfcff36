//! The needle shaft in the material (rest) frame and the piecewise-linear
//! discretisation of the shaft force density along it.
//!
//! The shaft runs from the entry point on the front face $y = 0$ to the
//! material point at the tip, $X_{tip} = x_{tip} - u(X_{tip})$: the tool
//! reports the tip where it is (spatial), while the linear model applies
//! loads in the rest frame. The fixed point is solved with the measured
//! marker displacements interpolated at the tip.
//!
//! The density is $q(s) = \sum_j q_j \varphi_j(s)$ with hat functions
//! $\varphi_j$ on equally spaced stations $0 = s_0 < \dots < s_n = L$, so the
//! integrated shaft force is $F = \int_0^L q\,ds = \sum_j w_j q_j$ with the
//! trapezoid weights $w_j$.

use crate::error::ForceError;
use crate::observe::{Frame, GridIndex, MarkerLayout};

/// A straight needle path in the rest frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShaftPath {
    /// Entry point on the front face (m).
    pub entry: [f64; 2],
    /// Unit vector of the axis, into the phantom.
    pub axis: [f64; 2],
    /// Length from the entry to the tip, in the rest frame (m).
    pub length: f64,
}

impl ShaftPath {
    /// The point at arc length `s` from the entry.
    pub fn point(&self, s: f64) -> [f64; 2] {
        [
            self.entry[0] + s * self.axis[0],
            self.entry[1] + s * self.axis[1],
        ]
    }

    /// The material tip.
    pub fn tip(&self) -> [f64; 2] {
        self.point(self.length)
    }

    /// The path of a frame: the entry where the tool axis crosses $y = 0$ and
    /// the material tip $X = x_{tip} - u(X)$, with $u$ the measured marker
    /// displacement interpolated bilinearly on the marker grid (three
    /// fixed-point steps; the displacement varies slowly on the scale of its
    /// own size).
    pub fn from_frame(
        frame: &Frame,
        layout: &MarkerLayout,
        grid: &GridIndex,
    ) -> Result<Self, ForceError> {
        let axis = frame.axis();
        if axis[1] <= 1e-3 {
            return Err(ForceError::InvalidValue {
                field: "tool theta",
                value: frame.theta,
                reason: "the needle axis must point into the phantom (|theta| < 90 degrees)",
            });
        }
        let mut tip = frame.tip;
        for _ in 0..3 {
            let u = interpolate_displacement(frame, layout, grid, tip).unwrap_or([0.0, 0.0]);
            tip = [frame.tip[0] - u[0], frame.tip[1] - u[1]];
        }
        let reach = tip[1] / axis[1];
        let entry = [tip[0] - reach * axis[0], 0.0];
        if reach.is_nan() || reach <= 0.0 {
            return Err(ForceError::BadShaft {
                length: reach,
                reason: "the material tip is not inside the phantom",
            });
        }
        Ok(Self {
            entry,
            axis,
            length: reach,
        })
    }
}

/// Measured displacement at `point`, bilinear in the grid cell around it;
/// `None` when a corner marker was not tracked.
pub(crate) fn interpolate_displacement(
    frame: &Frame,
    layout: &MarkerLayout,
    grid: &GridIndex,
    point: [f64; 2],
) -> Option<[f64; 2]> {
    debug_assert_eq!(layout.len(), frame.displacement.len());
    let cell = |lines: &[f64], v: f64| {
        let k = lines.partition_point(|&l| l <= v).clamp(1, lines.len() - 1) - 1;
        let w = ((v - lines[k]) / (lines[k + 1] - lines[k])).clamp(0.0, 1.0);
        (k, w)
    };
    let (i, wx) = cell(&grid.x, point[0]);
    let (j, wy) = cell(&grid.y, point[1]);
    let nx = grid.x.len();
    let mut u = [0.0; 2];
    for (di, dj, w) in [
        (0, 0, (1.0 - wx) * (1.0 - wy)),
        (1, 0, wx * (1.0 - wy)),
        (0, 1, (1.0 - wx) * wy),
        (1, 1, wx * wy),
    ] {
        let d = frame.displacement[grid.marker[(j + dj) * nx + i + di]]?;
        u[0] += w * d[0];
        u[1] += w * d[1];
    }
    Some(u)
}

/// Hat-function discretisation of the shaft force density on equally spaced
/// stations from the entry ($s = 0$) to the tip ($s = L$).
#[derive(Debug, Clone, PartialEq)]
pub struct ShaftBasis {
    /// Station arc lengths $s_j$ (m), ascending, first 0, last $L$.
    pub stations: Vec<f64>,
}

impl ShaftBasis {
    /// Stations no further apart than `spacing` over `[0, length]`, at least
    /// two elements.
    pub fn new(length: f64, spacing: f64) -> Result<Self, ForceError> {
        crate::error::positive("shaft spacing", spacing)?;
        if !(length.is_finite() && length > 0.0) {
            return Err(ForceError::BadShaft {
                length,
                reason: "the shaft must have positive length",
            });
        }
        let elements = ((length / spacing - 1e-9).ceil() as usize).max(2);
        Ok(Self {
            stations: (0..=elements)
                .map(|k| length * k as f64 / elements as f64)
                .collect(),
        })
    }

    /// Number of basis functions (stations).
    pub fn len(&self) -> usize {
        self.stations.len()
    }

    /// Always false: a basis has at least three stations.
    pub fn is_empty(&self) -> bool {
        self.stations.is_empty()
    }

    /// Shaft length $L$ (m).
    pub fn length(&self) -> f64 {
        *self.stations.last().unwrap_or(&0.0)
    }

    /// The station spacing (m).
    pub fn spacing(&self) -> f64 {
        self.length() / (self.len() - 1) as f64
    }

    /// Trapezoid weights $w_j = \int_0^L \varphi_j\,ds$, so that
    /// $\int_0^L q\,ds = \sum_j w_j q_j$.
    pub fn weights(&self) -> Vec<f64> {
        let h = self.spacing();
        let n = self.len();
        (0..n)
            .map(|j| if j == 0 || j == n - 1 { 0.5 * h } else { h })
            .collect()
    }

    /// The density $q(s)$ of station values `values` at arc length `s`
    /// (zero outside the shaft).
    pub fn evaluate(&self, values: &[f64], s: f64) -> f64 {
        let n = self.len();
        if !(0.0..=self.length()).contains(&s) {
            return 0.0;
        }
        let k = (self.stations.partition_point(|&t| t <= s)).clamp(1, n - 1) - 1;
        let w = (s - self.stations[k]) / (self.stations[k + 1] - self.stations[k]);
        values[k] * (1.0 - w) + values[k + 1] * w
    }

    /// Hat function $\varphi_j(s)$.
    pub fn hat(&self, j: usize, s: f64) -> f64 {
        let h = self.spacing();
        if !(0.0..=self.length()).contains(&s) {
            return 0.0;
        }
        (1.0 - (s - self.stations[j]).abs() / h).max(0.0)
    }

    /// The difference operator $L$ of the smoothness prior: rows
    /// $(q_{j+1} - q_j)/h$ (first order) or $(q_{j+1} - 2q_j + q_{j-1})/h^2$
    /// (second order), scaled by $\sqrt{h}$ so that $|Lq|^2$ approximates
    /// $\int |q'|^2 ds$ or $\int |q''|^2 ds$ whatever the spacing.
    pub fn difference_operator(&self, smoothness: Smoothness) -> nalgebra::DMatrix<f64> {
        let n = self.len();
        let h = self.spacing();
        match smoothness {
            Smoothness::FirstDifference => {
                let scale = h.sqrt() / h;
                nalgebra::DMatrix::from_fn(n - 1, n, |r, c| {
                    if c == r + 1 {
                        scale
                    } else if c == r {
                        -scale
                    } else {
                        0.0
                    }
                })
            }
            Smoothness::SecondDifference => {
                let scale = h.sqrt() / (h * h);
                nalgebra::DMatrix::from_fn(n - 2, n, |r, c| match c as isize - r as isize {
                    0 | 2 => scale,
                    1 => -2.0 * scale,
                    _ => 0.0,
                })
            }
        }
    }
}

/// Which derivative of the density the smoothness prior penalises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Smoothness {
    /// $\int |q'|^2 ds$: pulls towards a constant density.
    FirstDifference,
    /// $\int |q''|^2 ds$: pulls towards a linear density.
    SecondDifference,
}
