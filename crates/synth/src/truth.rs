//! The ground truth of a generated campaign: which effects are present and
//! every true parameter value, written as RON beside (never inside) the
//! bundle, for scoring a diagnosis.

use serde::{Deserialize, Serialize};

use crate::effect::EffectId;
use crate::frames::CameraTruth;
use crate::scenario::Scenario;

/// Everything true about a generated campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundTruth {
    /// Bundle name.
    pub bundle: String,
    /// Effects present in the truth, in catalog order.
    pub effects: Vec<EffectId>,
    /// The scenario, with every true parameter.
    pub scenario: Scenario,
    /// The truth's discretisation.
    pub discretisation: Discretisation,
    /// Stated noise: marker sigma (m) and force sigma (N).
    pub stated_noise: (f64, f64),
    /// Per trial, the values that follow from the scenario.
    pub trials: Vec<TrialTruth>,
    /// The compression test's modulus, if the test was done.
    pub compression_modulus: Option<f64>,
    /// The true camera and calibration target, when frames were rendered.
    #[serde(default)]
    pub camera: Option<CameraTruth>,
}

/// The truth's mesh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Discretisation {
    /// 2 (plane strain, 6-node triangles) or 3 (slab, 10-node tetrahedra).
    pub dimension: usize,
    /// Number of nodes.
    pub nodes: usize,
    /// Number of elements.
    pub elements: usize,
    /// Largest element edge in the plane (m).
    pub element_size: f64,
    /// Whether the slab was solved as its upper half (nodes and elements
    /// are the half's); see `slab_mesh`.
    #[serde(default)]
    pub upper_half: bool,
    /// Nodes of the finer mesh the needle trials were settled on
    /// (`resolution.marker_grading`), if any; the counts above are then
    /// those of the mesh the needle was first placed on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub marker_mesh_nodes: Option<usize>,
    /// Nodes of the slab each needle trial was settled on alone, in the
    /// trials' order, when `resolution.marker_grading` refines locally
    /// (each along its own material path); empty otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub needle_mesh_nodes: Vec<usize>,
    /// Nodes of the slab each probe was pressed on alone
    /// (`resolution.probe_grading`), in the probes' order; empty when
    /// they were pressed on the mesh above.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub probe_mesh_nodes: Vec<usize>,
}

/// True values of one trial.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrialTruth {
    /// Trial id in the bundle.
    pub id: String,
    /// Day of the trial.
    pub day: f64,
    /// Young's modulus of each layer that day (Pa).
    pub youngs_moduli: Vec<f64>,
    /// Needle: insertion line x (m); probe: probe centre x (m).
    pub x: f64,
    /// Needle: shaft force density behind the tip peak (N/m).
    pub shaft_density: Option<f64>,
    /// Needle: spatial y of the entry point at the last state (m).
    pub final_entry: Option<f64>,
    /// Needle: material point of the tip at the last state (m).
    pub final_tip_material: Option<[f64; 3]>,
    /// True (noise-free) force at the tool base at the end (N).
    pub final_force: f64,
    /// Largest principal strain in the phantom at the end.
    pub peak_strain: f64,
}
