//! The records of a measurement bundle, one type per thing the format names.
//!
//! `Bundle` and its parts mirror `bundle.ron` field for field (serde rejects
//! unknown fields); the row types mirror one CSV row each. All quantities are
//! SI: metres, newtons, seconds, pascals, radians.

use serde::{Deserialize, Serialize};

/// The only bundle format version this crate reads and writes.
pub const FORMAT_VERSION: u32 = 1;

/// The manifest, `bundle.ron`: what was measured and on which phantom.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bundle {
    /// Format version; must be [`FORMAT_VERSION`].
    pub format: u32,
    /// Campaign name, free text.
    pub name: String,
    /// The slab the campaign was measured on.
    pub phantom: Phantom,
    /// Stated measurement noise (one standard deviation), if known.
    #[serde(default)]
    pub noise: Option<Noise>,
    /// The trials, in the order the campaign ran them.
    pub trials: Vec<Trial>,
}

/// The phantom: a slab `width` (x) by `depth` (y) by `thickness` (z), metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Phantom {
    /// Extent along x, across the phantom (m).
    pub width: f64,
    /// Extent along y, the insertion direction (m).
    pub depth: f64,
    /// Extent along z, through the thickness (m).
    pub thickness: f64,
    /// Faces held fixed during the trials.
    pub fixed: Vec<Face>,
}

/// A side face of the phantom.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Face {
    /// `y = 0`, where the needle enters.
    Front,
    /// `y = depth`.
    Back,
    /// `x = 0`.
    Left,
    /// `x = width`.
    Right,
}

/// Stated measurement noise, one standard deviation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// Marker position noise per coordinate (m).
    pub marker_sigma: f64,
    /// Force noise per component (N).
    pub force_sigma: f64,
}

/// One trial as the manifest lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Trial {
    /// Identifier, also the name of the folder `trials/ID/`.
    pub id: String,
    /// What tool was used.
    pub kind: TrialKind,
    /// Commanded tool speed along its axis (m/s).
    pub velocity: f64,
    /// Time of the trial in days since the phantom was cast.
    pub day: f64,
}

/// What kind of tool a trial used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum TrialKind {
    /// A blunt probe pressing on the boundary at one point.
    Probe,
    /// A needle inserted along its axis.
    Needle,
    /// An unconfined compression test.
    Compression,
}

/// One row of `markers_rest.csv`: a marker and its undeformed position on the
/// top face (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarkerRest {
    /// Marker id, unique in the bundle.
    pub id: u32,
    /// Rest position x (m).
    pub x: f64,
    /// Rest position y (m).
    pub y: f64,
}

/// One row of `tool.csv`: a force sensor sample with the tool pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolSample {
    /// Time since the trial began (s).
    pub t: f64,
    /// Tip position x in the mid-plane (m).
    pub tip_x: f64,
    /// Tip position y in the mid-plane (m).
    pub tip_y: f64,
    /// Tool axis angle from `+y`, counter-clockwise positive (rad).
    pub theta: f64,
    /// Force the tool applies to the phantom, x component (N).
    pub fx: f64,
    /// Force the tool applies to the phantom, y component (N).
    pub fy: f64,
    /// Moment about z the tool applies, taken about the tip (N m).
    pub mz: f64,
}

/// One row of `markers.csv`: where one marker was seen in one camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MarkerObservation {
    /// Camera frame number.
    pub frame: u64,
    /// Time of the frame since the trial began (s).
    pub t: f64,
    /// Marker id, as in `markers_rest.csv`.
    pub id: u32,
    /// Tracked position x on the top face (m).
    pub x: f64,
    /// Tracked position y on the top face (m).
    pub y: f64,
    /// Tracking standard deviation `(sx, sy)` (m), when the file gives it.
    pub sigma: Option<[f64; 2]>,
}

/// One row of `compression.csv`: a point of the unconfined compression curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompressionPoint {
    /// Engineering strain (dimensionless).
    pub strain: f64,
    /// Stress (Pa).
    pub stress: f64,
}
