//! Probing data as plain arrays: the phantom, the markers at rest, and per
//! camera frame the probe force, its load point and the measured marker
//! displacements. [`extract_probe_data`](crate::extract_probe_data) builds it
//! from a bundle; a lab without bundles fills it directly.

use needle_fem::mesh::Face;
use serde::{Deserialize, Serialize};

use crate::error::IdentifyError;

/// The phantom's top face and its markers at rest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeSetup {
    /// Extent in x (m).
    pub width: f64,
    /// Extent in y (m).
    pub depth: f64,
    /// Slab thickness (m): plane models carry loads per this thickness.
    pub thickness: f64,
    /// Faces held fixed (only `Left`, `Right`, `Front`, `Back` apply).
    pub fixed: Vec<Face>,
    /// Marker rest positions (m); a frame refers to markers by index here.
    pub markers: Vec<[f64; 2]>,
}

/// One probing trial.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeTrial {
    /// Trial id.
    pub id: String,
    /// Days since the phantom was cast (for drift).
    pub day: f64,
}

/// One marker's measured displacement in one frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MarkerDisplacement {
    /// Index into [`ProbeSetup::markers`].
    pub marker: usize,
    /// Tracked position minus rest position (m).
    pub displacement: [f64; 2],
    /// Per-coordinate standard deviation of this observation (m), if known.
    pub sigma: Option<[f64; 2]>,
}

/// One camera frame with the probe in contact.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeFrame {
    /// Index into [`ProbeData::trials`].
    pub trial: usize,
    /// Frame time (s), for messages.
    pub t: f64,
    /// Where the probe tip is (m); the load is applied at the nearest point
    /// of the phantom's boundary (the tip may sit inside by the indentation).
    pub tip: [f64; 2],
    /// Force the probe applies to the phantom (N), total over the thickness.
    pub force: [f64; 2],
    /// Markers tracked in this frame.
    pub displacements: Vec<MarkerDisplacement>,
}

/// Everything a fit of equation (5) needs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeData {
    /// Geometry and markers.
    pub setup: ProbeSetup,
    /// The trials.
    pub trials: Vec<ProbeTrial>,
    /// Frames in contact, any order.
    pub frames: Vec<ProbeFrame>,
    /// Stated marker noise (m, per coordinate); used for observations
    /// without their own `sigma`. `None` with no per-observation sigma
    /// either: the noise is estimated from the fit and flagged.
    pub marker_sigma: Option<f64>,
}

/// Fewest distinct markers that can determine a modulus and a ratio.
pub const MIN_MARKERS: usize = 3;

impl ProbeData {
    /// Checks sizes, indices and finiteness, naming the first problem.
    pub fn validate(&self) -> Result<(), IdentifyError> {
        let setup = &self.setup;
        for (field, value) in [
            ("setup.width", setup.width),
            ("setup.depth", setup.depth),
            ("setup.thickness", setup.thickness),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(IdentifyError::InvalidValue {
                    field,
                    value,
                    reason: "must be positive and finite",
                });
            }
        }
        if let Some(face) = setup
            .fixed
            .iter()
            .find(|f| matches!(f, Face::Top | Face::Bottom))
        {
            return Err(IdentifyError::Inconsistent(format!(
                "setup.fixed: face {face:?} is not a side face of the 2-D model"
            )));
        }
        if setup.fixed.is_empty() {
            return Err(IdentifyError::Inconsistent(
                "setup.fixed: no fixed face, so the phantom could move as a rigid body and the stiffness matrix is singular"
                    .into(),
            ));
        }
        if setup.markers.len() < MIN_MARKERS {
            return Err(IdentifyError::TooFewMarkers {
                context: "markers at rest".into(),
                needed: MIN_MARKERS,
                found: setup.markers.len(),
            });
        }
        for (i, m) in setup.markers.iter().enumerate() {
            let inside = m[0].is_finite()
                && m[1].is_finite()
                && (0.0..=setup.width).contains(&m[0])
                && (0.0..=setup.depth).contains(&m[1]);
            if !inside {
                return Err(IdentifyError::Inconsistent(format!(
                    "marker {i} at rest ({}, {}) m is not inside the {} x {} m phantom",
                    m[0], m[1], setup.width, setup.depth
                )));
            }
        }
        if let Some(s) = self.marker_sigma
            && !(s.is_finite() && s > 0.0)
        {
            return Err(IdentifyError::InvalidValue {
                field: "marker_sigma",
                value: s,
                reason: "must be positive and finite",
            });
        }
        for (k, frame) in self.frames.iter().enumerate() {
            if frame.trial >= self.trials.len() {
                return Err(IdentifyError::Inconsistent(format!(
                    "frame {k} refers to trial {} but there are {} trials",
                    frame.trial,
                    self.trials.len()
                )));
            }
            let values = [
                frame.t,
                frame.tip[0],
                frame.tip[1],
                frame.force[0],
                frame.force[1],
            ];
            if values.iter().any(|v| !v.is_finite()) {
                return Err(IdentifyError::Inconsistent(format!(
                    "frame {k} (trial `{}`): time, tip or force is not finite",
                    self.trials[frame.trial].id
                )));
            }
            for d in &frame.displacements {
                if d.marker >= setup.markers.len() {
                    return Err(IdentifyError::Inconsistent(format!(
                        "frame {k}: marker index {} but only {} markers",
                        d.marker,
                        setup.markers.len()
                    )));
                }
                let finite = d.displacement.iter().all(|v| v.is_finite());
                let sigma_ok = d
                    .sigma
                    .is_none_or(|s| s.iter().all(|v| v.is_finite() && *v > 0.0));
                if !finite || !sigma_ok {
                    return Err(IdentifyError::Inconsistent(format!(
                        "frame {k}, marker {}: displacement not finite or sigma not positive",
                        d.marker
                    )));
                }
            }
        }
        for trial in &self.trials {
            if !trial.day.is_finite() {
                return Err(IdentifyError::InvalidValue {
                    field: "trials.day",
                    value: trial.day,
                    reason: "must be finite",
                });
            }
        }
        Ok(())
    }
}
