//! What an identification returns: the estimates with their uncertainty,
//! the fit quality, the per-trial moduli and their drift, and flags for
//! everything a reader should not overlook.

use std::fmt;

use needle_fem::element::ElementKind;
use needle_lsq::{FitReport, Termination};
use serde::{Deserialize, Serialize};

use crate::options::PlaneModel;

/// Confidence level of the reported intervals.
pub const CONFIDENCE_LEVEL: f64 = 0.95;

/// One estimated quantity.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// The estimate.
    pub value: f64,
    /// Its standard error, when the fit determines it (not at a bound, not
    /// unidentifiable).
    pub standard_error: Option<f64>,
    /// The 95% Wald interval `value ± 1.96 σ`, when the standard error exists.
    pub interval: Option<(f64, f64)>,
}

impl Estimate {
    /// The estimate of parameter `index` of a fit report.
    pub fn from_report(report: &FitReport, index: usize) -> Self {
        Self {
            value: report.params[index],
            standard_error: report.standard_error(index),
            interval: report.confidence_interval(index, CONFIDENCE_LEVEL).ok(),
        }
    }
}

impl fmt::Display for Estimate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.standard_error {
            Some(se) => write!(f, "{:.6e} ± {:.2e}", self.value, se),
            None => write!(f, "{:.6e} (no standard error)", self.value),
        }
    }
}

/// Where the marker noise used for whitening came from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum NoiseSource {
    /// Stated (bundle manifest or options), m per coordinate.
    Stated(f64),
    /// Per-observation `sx,sy` columns of `markers.csv`.
    PerObservation,
    /// Not stated: estimated from the residuals of the best scan point
    /// (m per coordinate); covariances are scaled by chi2/dof.
    Estimated(f64),
}

/// The fit of a layered (multi-region) model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegionFit {
    /// Young's modulus of each region (Pa), region 0 first.
    pub youngs_moduli: Vec<Estimate>,
    /// The common Poisson's ratio of the region fit.
    pub poisson_ratio: Estimate,
    /// chi2 / dof of the region fit.
    pub reduced_chi2: f64,
    /// Residual evaluations of the region fit.
    pub evaluations: usize,
}

/// The modulus of one trial, Poisson's ratio held at the global estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialFit {
    /// Trial id.
    pub id: String,
    /// Days since casting.
    pub day: f64,
    /// Frames used.
    pub frames: usize,
    /// The trial's Young's modulus (Pa), homogeneous model.
    pub youngs_modulus: Estimate,
    /// chi2 / dof of the trial's residuals.
    pub reduced_chi2: f64,
}

/// A straight line through the per-trial moduli against the day.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriftFit {
    /// Modulus at `reference_day` (Pa).
    pub modulus_at_reference: Estimate,
    /// Change of modulus per day (Pa/day).
    pub slope: Estimate,
    /// The mean day of the trials, where the intercept is taken.
    pub reference_day: f64,
    /// chi2 / dof of the line (the trials' scatter around it in units of
    /// their standard errors); the slope's error is scaled by it.
    pub reduced_chi2: f64,
}

/// Something about a fit that its reader must know.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum FitFlag {
    /// A Probe trial contributed nothing, and why.
    TrialSkipped {
        /// Trial id.
        trial: String,
        /// Why.
        reason: String,
    },
    /// Frames whose time lies outside the trial's force record were skipped.
    FramesOutsideForceRecord {
        /// Trial id.
        trial: String,
        /// How many.
        count: usize,
    },
    /// No marker noise was stated: it was estimated from the residuals.
    NoiseEstimated {
        /// The estimate (m per coordinate).
        sigma: f64,
    },
    /// A parameter converged onto its search bound: the data want a value
    /// outside the interval, or do not determine it.
    AtBound {
        /// Which fit and parameter.
        parameter: String,
        /// The value.
        value: f64,
    },
    /// The least-squares iteration stopped on a limit, not on convergence.
    NotConverged {
        /// Which fit.
        fit: String,
        /// Why it stopped.
        termination: Termination,
    },
    /// The data do not determine some parameters (rank-deficient Jacobian).
    Unidentifiable {
        /// Which fit.
        fit: String,
        /// The parameters without a standard error.
        parameters: Vec<String>,
    },
    /// The residuals are much larger than the stated noise: the model does
    /// not explain the data (wrong geometry, fixed faces, force scale,
    /// nonlinearity, or drift between trials).
    PoorFit {
        /// chi2 / dof of the global fit.
        reduced_chi2: f64,
    },
    /// The per-trial moduli change with the day more than their scatter
    /// explains (|slope| > 3 standard errors).
    Drift {
        /// Pa per day.
        slope: f64,
        /// Slope over its standard error.
        z: f64,
    },
}

impl fmt::Display for FitFlag {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FitFlag::TrialSkipped { trial, reason } => {
                write!(f, "trial `{trial}` skipped: {reason}")
            }
            FitFlag::FramesOutsideForceRecord { trial, count } => {
                write!(
                    f,
                    "trial `{trial}`: {count} frame(s) outside the tool.csv time range skipped"
                )
            }
            FitFlag::NoiseEstimated { sigma } => {
                write!(
                    f,
                    "no marker noise stated: estimated {sigma:.3e} m from the residuals"
                )
            }
            FitFlag::AtBound { parameter, value } => {
                write!(f, "{parameter} = {value} is on its search bound")
            }
            FitFlag::NotConverged { fit, termination } => {
                write!(f, "{fit}: not converged ({termination:?})")
            }
            FitFlag::Unidentifiable { fit, parameters } => {
                write!(
                    f,
                    "{fit}: not determined by the data: {}",
                    parameters.join(", ")
                )
            }
            FitFlag::PoorFit { reduced_chi2 } => {
                write!(
                    f,
                    "chi2/dof = {reduced_chi2:.2}: residuals exceed the stated noise, the model misses something"
                )
            }
            FitFlag::Drift { slope, z } => {
                write!(
                    f,
                    "modulus drifts by {slope:.4e} Pa/day ({z:.1} standard errors)"
                )
            }
        }
    }
}

/// The size of the fitted problem.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelSummary {
    /// Element kind.
    pub element: ElementKind,
    /// Plane strain or stress.
    pub plane: PlaneModel,
    /// Mesh nodes.
    pub nodes: usize,
    /// Mesh elements.
    pub elements: usize,
    /// Distinct load points.
    pub load_points: usize,
    /// Frames used.
    pub frames: usize,
    /// Distinct markers with at least one residual.
    pub markers: usize,
    /// Residuals (two per marker per frame, minus exclusions).
    pub residuals: usize,
}

/// The result of [`identify_material`](crate::identify_material).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MaterialFit {
    /// Young's modulus of the homogeneous model (Pa).
    pub youngs_modulus: Estimate,
    /// Poisson's ratio of the homogeneous model.
    pub poisson_ratio: Estimate,
    /// Contact width of the flat punch (m), fitted or held; `None` with the
    /// point-force model.
    #[serde(default)]
    pub probe_width: Option<Estimate>,
    /// Per-region moduli when regions were asked for.
    pub regions: Option<RegionFit>,
    /// chi2 of the homogeneous fit (whitened residuals).
    pub chi2: f64,
    /// Degrees of freedom (residuals minus parameters).
    pub dof: usize,
    /// chi2 / dof.
    pub reduced_chi2: f64,
    /// Where the marker noise came from.
    pub noise: NoiseSource,
    /// Per-trial moduli (empty when not asked for).
    pub trials: Vec<TrialFit>,
    /// Drift of the per-trial modulus with the day (three or more trials on
    /// at least two days).
    pub drift: Option<DriftFit>,
    /// The fitted problem.
    pub model: ModelSummary,
    /// Residual evaluations of the homogeneous fit: scan plus polish.
    pub evaluations: usize,
    /// Jacobian evaluations of the polish.
    pub jacobians: usize,
    /// Everything the reader should know.
    pub flags: Vec<FitFlag>,
}

impl fmt::Display for MaterialFit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let m = &self.model;
        writeln!(
            f,
            "Material identification ({:?}, plane {:?}; {} nodes, {} load points, {} frames, {} markers, {} residuals)",
            m.element, m.plane, m.nodes, m.load_points, m.frames, m.markers, m.residuals
        )?;
        writeln!(f, "  Young's modulus  E  = {} Pa", self.youngs_modulus)?;
        writeln!(f, "  Poisson's ratio  nu = {}", self.poisson_ratio)?;
        if let Some(width) = &self.probe_width {
            writeln!(f, "  probe width      a  = {width} m")?;
        }
        writeln!(
            f,
            "  chi2/dof = {:.3} (dof {}), noise {:?}",
            self.reduced_chi2, self.dof, self.noise
        )?;
        writeln!(
            f,
            "  evaluations: {} residual, {} Jacobian",
            self.evaluations, self.jacobians
        )?;
        if let Some(regions) = &self.regions {
            writeln!(f, "  regions (chi2/dof {:.3}):", regions.reduced_chi2)?;
            for (r, e) in regions.youngs_moduli.iter().enumerate() {
                writeln!(f, "    E[{r}] = {e} Pa")?;
            }
            writeln!(f, "    nu   = {}", regions.poisson_ratio)?;
        }
        if !self.trials.is_empty() {
            writeln!(
                f,
                "  per trial (nu held at {:.4}):",
                self.poisson_ratio.value
            )?;
            writeln!(
                f,
                "    {:<16} {:>8} {:>7} {:>28} {:>9}",
                "trial", "day", "frames", "E (Pa)", "chi2/dof"
            )?;
            for t in &self.trials {
                writeln!(
                    f,
                    "    {:<16} {:>8.3} {:>7} {:>28} {:>9.3}",
                    t.id,
                    t.day,
                    t.frames,
                    t.youngs_modulus.to_string(),
                    t.reduced_chi2
                )?;
            }
        }
        if let Some(drift) = &self.drift {
            writeln!(
                f,
                "  drift: E(day {:.2}) = {} Pa, slope {} Pa/day",
                drift.reference_day, drift.modulus_at_reference, drift.slope
            )?;
        }
        for flag in &self.flags {
            writeln!(f, "  FLAG: {flag}")?;
        }
        Ok(())
    }
}
