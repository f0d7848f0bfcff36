//! The integrated shaft force against the measured base force over an
//! insertion (the paper's Figs. 11 and 13), averaging over repeated
//! insertions, and the error metrics of the force estimates.

use serde::{Deserialize, Serialize};

use crate::error::ForceError;
use crate::estimate::{EstimatorOptions, ShaftDistribution, ShaftEstimator};
use crate::nodal::MarkerMeshModel;
use crate::observe::Insertion;
use crate::respond::{MaterialField, PlaneKind};

/// Which estimate of the shaft force.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Method {
    /// The paper's node forces $f = Ku$ summed over the shaft nodes.
    PaperNodal(PlaneKind),
    /// The regularised distribution, integrated along the shaft.
    Regularised(EstimatorOptions),
}

impl Method {
    /// A short label for plots and tables.
    pub fn label(&self) -> String {
        match self {
            Method::PaperNodal(PlaneKind::Strain) => "paper f = Ku, plane strain".into(),
            Method::PaperNodal(PlaneKind::Stress) => "paper f = Ku, plane stress".into(),
            Method::Regularised(o) => match o.model.model {
                crate::respond::Model::Plane(PlaneKind::Strain) => {
                    "regularised, plane strain".into()
                }
                crate::respond::Model::Plane(PlaneKind::Stress) => {
                    "regularised, plane stress".into()
                }
                crate::respond::Model::Slab { .. } => "regularised, 3-D slab (eq. 6)".into(),
            },
        }
    }
}

/// One frame of an integrated-force series.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct IntegratedPoint {
    /// Frame time (s).
    pub t: f64,
    /// Shaft length in the rest frame, entry to tip (m).
    pub depth: f64,
    /// Estimated integrated axial shaft force (N).
    pub integrated: f64,
    /// One standard deviation of `integrated` from marker noise (N); zero
    /// when the method gives none.
    pub integrated_sigma: f64,
    /// Measured axial base force (N).
    pub base_force: f64,
    /// The estimate is flagged (model does not fit to the noise).
    pub flagged: bool,
}

impl IntegratedPoint {
    /// $(F_{est} - F_{base}) / F_{base}$.
    pub fn relative_error(&self) -> f64 {
        (self.integrated - self.base_force) / self.base_force
    }
}

/// Integrated shaft force against base force over one insertion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntegratedSeries {
    /// Trial id (or a label for an average).
    pub trial: String,
    /// The method's label.
    pub method: String,
    /// Frames in time order.
    pub points: Vec<IntegratedPoint>,
}

impl IntegratedSeries {
    /// Mean of $F_{est}/F_{base} - 1$ over the frames deeper than
    /// `min_depth`: negative when the method underestimates.
    pub fn mean_relative_error(&self, min_depth: f64) -> Option<f64> {
        let errors: Vec<f64> = self
            .points
            .iter()
            .filter(|p| p.depth > min_depth)
            .map(|p| p.relative_error())
            .collect();
        (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64)
    }

    /// Largest $|F_{est}/F_{base} - 1|$ over the frames deeper than `min_depth`.
    pub fn max_relative_error(&self, min_depth: f64) -> Option<f64> {
        self.points
            .iter()
            .filter(|p| p.depth > min_depth)
            .map(|p| p.relative_error().abs())
            .reduce(f64::max)
    }
}

/// The integrated shaft force of every frame of `insertion` by `method`,
/// with the measured base force.
pub fn integrated_vs_base(
    insertion: &Insertion,
    material: &MaterialField,
    method: Method,
) -> Result<IntegratedSeries, ForceError> {
    let points = match method {
        Method::PaperNodal(kind) => {
            let model = MarkerMeshModel::new(insertion, material, kind)?;
            insertion
                .frames
                .iter()
                .map(|f| {
                    model.nodal_forces(insertion, f).map(|n| IntegratedPoint {
                        t: n.t,
                        depth: n.length,
                        integrated: n.integrated,
                        integrated_sigma: 0.0,
                        base_force: n.base_force,
                        flagged: false,
                    })
                })
                .collect::<Result<Vec<_>, _>>()?
        }
        Method::Regularised(options) => {
            let estimator = ShaftEstimator::new(insertion, material, options)?;
            insertion
                .frames
                .iter()
                .map(|f| estimator.estimate(insertion, f).map(|d| point_of(&d)))
                .collect::<Result<Vec<_>, _>>()?
        }
    };
    Ok(IntegratedSeries {
        trial: insertion.trial.clone(),
        method: method.label(),
        points,
    })
}

/// The integrated-force point of a distribution.
pub fn point_of(distribution: &ShaftDistribution) -> IntegratedPoint {
    IntegratedPoint {
        t: distribution.t,
        depth: distribution.length,
        integrated: distribution.integrated,
        integrated_sigma: distribution.integrated_sigma,
        base_force: distribution.base_force,
        flagged: distribution.is_flagged(),
    }
}

/// Averages series of repeated insertions point by point (same number of
/// frames; depths within `depth_tolerance`): the noise of the average falls
/// as $1/\sqrt n$.
pub fn average_series(
    series: &[IntegratedSeries],
    depth_tolerance: f64,
) -> Result<IntegratedSeries, ForceError> {
    let first = series
        .first()
        .ok_or(ForceError::Empty("average of integrated series"))?;
    for s in &series[1..] {
        if s.points.len() != first.points.len() {
            return Err(ForceError::Mismatch(format!(
                "series `{}` has {} frames, `{}` has {}",
                s.trial,
                s.points.len(),
                first.trial,
                first.points.len()
            )));
        }
        if let Some(p) = s
            .points
            .iter()
            .zip(&first.points)
            .find(|(a, b)| (a.depth - b.depth).abs() > depth_tolerance)
        {
            return Err(ForceError::Mismatch(format!(
                "series `{}` reaches depth {} m where `{}` is at {} m",
                s.trial, p.0.depth, first.trial, p.1.depth
            )));
        }
    }
    let n = series.len() as f64;
    let points = (0..first.points.len())
        .map(|i| {
            let mean = |f: &dyn Fn(&IntegratedPoint) -> f64| {
                series.iter().map(|s| f(&s.points[i])).sum::<f64>() / n
            };
            IntegratedPoint {
                t: mean(&|p| p.t),
                depth: mean(&|p| p.depth),
                integrated: mean(&|p| p.integrated),
                integrated_sigma: (series
                    .iter()
                    .map(|s| s.points[i].integrated_sigma.powi(2))
                    .sum::<f64>())
                .sqrt()
                    / n,
                base_force: mean(&|p| p.base_force),
                flagged: series.iter().any(|s| s.points[i].flagged),
            }
        })
        .collect();
    Ok(IntegratedSeries {
        trial: format!("mean of {} insertions", series.len()),
        method: first.method.clone(),
        points,
    })
}

/// Averages distributions of repeated insertions at the same depth (same
/// stations within `tolerance`).
pub fn average_distributions(
    distributions: &[ShaftDistribution],
    tolerance: f64,
) -> Result<ShaftDistribution, ForceError> {
    let first = distributions
        .first()
        .ok_or(ForceError::Empty("average of distributions"))?;
    for d in &distributions[1..] {
        let same = d.stations.len() == first.stations.len()
            && d.stations
                .iter()
                .zip(&first.stations)
                .all(|(a, b)| (a - b).abs() <= tolerance);
        if !same {
            return Err(ForceError::Mismatch(
                "distributions to average must share their stations".into(),
            ));
        }
    }
    let n = distributions.len() as f64;
    let mut out = first.clone();
    for j in 0..out.density.len() {
        out.density[j] = distributions.iter().map(|d| d.density[j]).sum::<f64>() / n;
        out.density_sigma[j] = distributions
            .iter()
            .map(|d| d.density_sigma[j].powi(2))
            .sum::<f64>()
            .sqrt()
            / n;
    }
    out.integrated = distributions.iter().map(|d| d.integrated).sum::<f64>() / n;
    out.integrated_sigma = distributions
        .iter()
        .map(|d| d.integrated_sigma.powi(2))
        .sum::<f64>()
        .sqrt()
        / n;
    out.base_force = distributions.iter().map(|d| d.base_force).sum::<f64>() / n;
    Ok(out)
}

/// Error of an estimated distribution against a known density $q(s)$:
///
/// - `density`: relative $L^2$ error over the shaft,
///   $\|\hat q - q\|_{L^2(0,L)} / \|q\|_{L^2(0,L)}$, by composite Simpson
///   quadrature on 400 panels;
/// - `integral`: $(\int \hat q - \int q)/\int q$.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DistributionError {
    /// Relative $L^2$ error of the density.
    pub density: f64,
    /// Relative error of the integrated force.
    pub integral: f64,
}

/// The [`DistributionError`] of `estimate` against `truth`.
pub fn distribution_error(
    estimate: &ShaftDistribution,
    truth: impl Fn(f64) -> f64,
) -> DistributionError {
    let length = estimate.length;
    let panels = 400;
    let h = length / panels as f64;
    let simpson = |f: &dyn Fn(f64) -> f64| {
        (0..=panels)
            .map(|k| {
                let w = if k == 0 || k == panels {
                    1.0
                } else if k % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                w * f(k as f64 * h)
            })
            .sum::<f64>()
            * h
            / 3.0
    };
    let difference = simpson(&|s| (estimate.density_at(s) - truth(s)).powi(2)).sqrt();
    let norm = simpson(&|s| truth(s).powi(2)).sqrt();
    let total = simpson(&|s| truth(s));
    DistributionError {
        density: difference / norm,
        integral: (estimate.integrated - total) / total,
    }
}
