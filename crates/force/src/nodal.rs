//! The paper's method as it is (section IV-A, equation (4)): the mesh nodes
//! are the markers, linear triangles on the marker grid (its Fig. 8), the
//! measured displacement of every node gives the external nodal forces
//!
//! $$f = K u$$
//!
//! with the plane model and no boundary condition: the forces at the nodes
//! along the needle are the shaft forces, those on the fixed face the
//! reactions, and since $K$ annihilates rigid motions they balance
//! ($\sum f = 0$). Nodes within half a grid spacing of the needle path (entry
//! to material tip) are shaft nodes; their force sum is compared with the
//! base force (Fig. 11).

use needle_fem::assemble::{Assembler, multiply};
use needle_fem::element::ElementKind;
use needle_fem::material::Materials;
use needle_fem::mesh::RectangleMesh;
use serde::{Deserialize, Serialize};

use crate::error::ForceError;
use crate::observe::{Frame, GridIndex, Insertion};
use crate::respond::{MaterialField, PlaneKind, fem_face};
use crate::shaft::ShaftPath;

/// Node forces of one frame by $f = K u$ on the marker mesh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PaperNodalForces {
    /// Frame time (s).
    pub t: f64,
    /// Node (marker rest) positions (m).
    pub nodes: Vec<[f64; 2]>,
    /// External force at every node (N).
    pub forces: Vec<[f64; 2]>,
    /// Shaft nodes, ordered from the entry to the tip.
    pub shaft_nodes: Vec<usize>,
    /// Their arc length from the entry along the needle (m).
    pub shaft_positions: Vec<f64>,
    /// Nodes on the mesh edge nearest each fixed face.
    pub reaction_nodes: Vec<usize>,
    /// Sum of the shaft node forces (N).
    pub shaft_force: [f64; 2],
    /// Sum of the reaction forces (N).
    pub reaction_force: [f64; 2],
    /// Axial component of the shaft force sum, $\sum f \cdot$ axis (N).
    pub integrated: f64,
    /// Axial base force measured by the sensor (N).
    pub base_force: f64,
    /// The needle path used (rest frame).
    pub entry: [f64; 2],
    /// Needle axis (unit).
    pub axis: [f64; 2],
    /// Shaft length, entry to material tip (m).
    pub length: f64,
}

impl PaperNodalForces {
    /// Axial force at each shaft node, entry first (N).
    pub fn shaft_axial_forces(&self) -> Vec<f64> {
        self.shaft_nodes
            .iter()
            .map(|&n| self.forces[n][0] * self.axis[0] + self.forces[n][1] * self.axis[1])
            .collect()
    }

    /// The axial force at the shaft node nearest the entry (where the
    /// plane model puts a spurious peak), if there is a shaft node.
    pub fn entry_node_force(&self) -> Option<f64> {
        self.shaft_axial_forces().first().copied()
    }
}

/// The marker mesh and its stiffness, built once per campaign layout.
#[derive(Debug, Clone)]
pub struct MarkerMeshModel {
    grid: GridIndex,
    /// Mesh node -> layout marker index.
    node_marker: Vec<usize>,
    nodes: Vec<[f64; 2]>,
    stiffness: faer::sparse::SparseColMat<usize, f64>,
    reaction_nodes: Vec<usize>,
}

impl MarkerMeshModel {
    /// Linear triangles with one node per marker (the grid's own lines, no
    /// refinement), `kind` plane strain (the paper) or stress, the phantom's
    /// thickness, and the reaction nodes on the fixed faces of `insertion`'s
    /// phantom.
    pub fn new(
        insertion: &Insertion,
        material: &MaterialField,
        kind: PlaneKind,
    ) -> Result<Self, ForceError> {
        let grid = insertion.layout.grid()?;
        let plan = RectangleMesh {
            width: grid.x[grid.x.len() - 1] - grid.x[0],
            depth: grid.y[grid.y.len() - 1] - grid.y[0],
            x_lines: grid.x.clone(),
            y_lines: grid.y.clone(),
        };
        let mut mesh = plan.build(ElementKind::Tri3)?;
        let materials = match material {
            MaterialField::Homogeneous(m) => Materials::homogeneous(*m),
            MaterialField::LayersInY {
                boundaries,
                materials,
            } => {
                mesh.assign_regions(|c| boundaries.partition_point(|&b| b <= c[1]));
                Materials(materials.clone())
            }
        };
        // `build` numbers nodes row-major over the grid lines, the grid's order.
        let node_marker = grid.marker.clone();
        let nodes = mesh.nodes().to_vec();
        let mut reaction_nodes: Vec<usize> = insertion
            .phantom
            .fixed
            .iter()
            .flat_map(|&f| mesh.nodes_on_face(fem_face(f)))
            .collect();
        reaction_nodes.sort_unstable();
        reaction_nodes.dedup();
        let assembler = Assembler::new(mesh, kind.formulation(insertion.phantom.thickness))?;
        let stiffness = assembler.stiffness(&materials)?;
        Ok(Self {
            grid,
            node_marker,
            nodes,
            stiffness,
            reaction_nodes,
        })
    }

    /// $f = K u$ at one frame. Every marker must have been tracked.
    pub fn nodal_forces(
        &self,
        insertion: &Insertion,
        frame: &Frame,
    ) -> Result<PaperNodalForces, ForceError> {
        let mut u = vec![0.0; 2 * self.nodes.len()];
        for (n, &k) in self.node_marker.iter().enumerate() {
            let d = frame.displacement[k].ok_or(ForceError::MissingMarker {
                t: frame.t,
                id: insertion.layout.ids[k],
            })?;
            u[2 * n] = d[0];
            u[2 * n + 1] = d[1];
        }
        let f = multiply(&self.stiffness, &u);
        let forces: Vec<[f64; 2]> = (0..self.nodes.len())
            .map(|n| [f[2 * n], f[2 * n + 1]])
            .collect();
        let path = ShaftPath::from_frame(frame, &insertion.layout, &self.grid)?;
        let radius = 0.5 * self.grid.spacing() * (1.0 + 1e-9);
        let mut shaft: Vec<(usize, f64)> = (0..self.nodes.len())
            .filter_map(|n| {
                let p = self.nodes[n];
                let along =
                    (p[0] - path.entry[0]) * path.axis[0] + (p[1] - path.entry[1]) * path.axis[1];
                let s = along.clamp(0.0, path.length);
                let closest = path.point(s);
                let distance = ((p[0] - closest[0]).powi(2) + (p[1] - closest[1]).powi(2)).sqrt();
                (distance <= radius).then_some((n, along))
            })
            .collect();
        shaft.sort_by(|a, b| a.1.total_cmp(&b.1));
        let sum = |nodes: &mut dyn Iterator<Item = usize>| {
            nodes.fold([0.0, 0.0], |acc, n| {
                [acc[0] + forces[n][0], acc[1] + forces[n][1]]
            })
        };
        let shaft_force = sum(&mut shaft.iter().map(|&(n, _)| n));
        let reaction_force = sum(&mut self.reaction_nodes.iter().copied());
        let axis = path.axis;
        Ok(PaperNodalForces {
            t: frame.t,
            nodes: self.nodes.clone(),
            forces,
            shaft_nodes: shaft.iter().map(|&(n, _)| n).collect(),
            shaft_positions: shaft.iter().map(|&(_, s)| s).collect(),
            reaction_nodes: self.reaction_nodes.clone(),
            shaft_force,
            reaction_force,
            integrated: shaft_force[0] * axis[0] + shaft_force[1] * axis[1],
            base_force: frame.base_force[0] * axis[0] + frame.base_force[1] * axis[1],
            entry: path.entry,
            axis,
            length: path.length,
        })
    }
}

/// The paper's node forces $f = Ku$ at frame `frame_index` of an insertion
/// (plane strain as in the paper, or plane stress).
pub fn paper_nodal_forces(
    insertion: &Insertion,
    frame_index: usize,
    material: &MaterialField,
    kind: PlaneKind,
) -> Result<PaperNodalForces, ForceError> {
    let frame = insertion.frames.get(frame_index).ok_or_else(|| {
        ForceError::Mismatch(format!(
            "frame {frame_index} requested, the insertion has {}",
            insertion.frames.len()
        ))
    })?;
    MarkerMeshModel::new(insertion, material, kind)?.nodal_forces(insertion, frame)
}

/// Averages node forces of repeated insertions frame by frame (the paper's
/// remedy for marker noise): every input must have the same nodes and the
/// same shaft nodes (same needle line and depth).
pub fn average_nodal_forces(repeats: &[PaperNodalForces]) -> Result<PaperNodalForces, ForceError> {
    let first = repeats
        .first()
        .ok_or(ForceError::Empty("average of node forces"))?;
    for other in &repeats[1..] {
        if other.nodes.len() != first.nodes.len() || other.shaft_nodes != first.shaft_nodes {
            return Err(ForceError::Mismatch(
                "node forces to average must come from the same mesh, needle line and depth".into(),
            ));
        }
    }
    let n = repeats.len() as f64;
    let mean2 = |pick: &dyn Fn(&PaperNodalForces) -> [f64; 2]| {
        let s = repeats
            .iter()
            .map(pick)
            .fold([0.0, 0.0], |a, v| [a[0] + v[0], a[1] + v[1]]);
        [s[0] / n, s[1] / n]
    };
    let mean = |pick: &dyn Fn(&PaperNodalForces) -> f64| repeats.iter().map(pick).sum::<f64>() / n;
    let mut out = first.clone();
    for (i, force) in out.forces.iter_mut().enumerate() {
        *force = mean2(&|r| r.forces[i]);
    }
    out.shaft_force = mean2(&|r| r.shaft_force);
    out.reaction_force = mean2(&|r| r.reaction_force);
    out.integrated = mean(&|r| r.integrated);
    out.base_force = mean(&|r| r.base_force);
    out.t = mean(&|r| r.t);
    out.length = mean(&|r| r.length);
    Ok(out)
}
