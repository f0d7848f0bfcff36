//! One discretised body of the forward model: the paper's plane-strain T6
//! model of the slab, or the Tet10 slab through its thickness that the
//! `out_of_plane` effect brings in. Both read the markers on the top face
//! and take the needle load in the mid-plane; each keeps its own cache of
//! factorisations.
//!
//! In 3-D the slab spans $z \in [-t/2, t/2]$: markers at $z = t/2$, the
//! needle at $z = 0$, a probe force spread over its contact patch as under
//! a rigid flat punch (across the width, evenly through the thickness),
//! the foundation of `platform_friction` as springs on the bottom face and
//! compliant supports as springs on the fixed faces. In 2-D the foundation
//! acts over the plane's area, so one stiffness per unit area means the same
//! platform in both.

use std::sync::{Arc, Mutex};

use needle_fem::load::add_line_load;
use needle_fem::{
    Assembler, Dirichlet, Face, Formulation, LineDensity, LinearProblem, Locator, Material,
    Materials, Mesh, Support,
};

use crate::effect::SupportSpec;
use crate::error::DiagnoseError;
use crate::observe::Shaft;
use crate::place::Placement;

/// Factorisations kept per plane body (one per distinct normalised
/// material field and support).
const PLANE_CACHE_SIZE: usize = 48;
/// Factorisations kept per 3-D slab: each holds a Cholesky factor of
/// about 100 MB for the default marker grid, so 48 of them took 5 GB.
const SLAB_CACHE_SIZE: usize = 8;

/// Gauss-Chebyshev points across a probe's contact patch: the rigid flat
/// punch's pressure $p(s) \propto 1/\sqrt{1 - (2s/a)^2}$ is the rule's
/// weight, so equal forces at $s_i = \tfrac a2 \cos\frac{(2i+1)\pi}{2n}$
/// integrate it exactly for polynomial test functions of degree $< 2n$.
const PATCH_POINTS: usize = 8;

/// Identity of a factorisation: the exact bits of every normalised element
/// modulus, Poisson's ratio and the normalised supports.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Key(Vec<u64>);

/// Marker responses to unit probe forces on one contact patch, along x and
/// along y, keyed by the bits of the contact point and the patch width.
type ProbeResponses = ([u64; 3], [Vec<[f64; 2]>; 2]);

/// A kept factorisation with the probe responses already solved on it
/// (they depend on nothing else, so a fit solves each tip once per
/// material).
pub(crate) struct Entry<const D: usize> {
    pub problem: LinearProblem<D>,
    probes: Mutex<Vec<ProbeResponses>>,
}

/// A factorised problem and the factor its solutions are divided by.
pub(crate) struct Factorized<const D: usize> {
    pub entry: Arc<Entry<D>>,
    pub scale: f64,
}

pub(crate) struct Body<const D: usize> {
    mesh: Mesh<D>,
    formulation: Formulation,
    thickness: f64,
    /// Largest x and y of the mesh (the outline is `[0, x] x [0, y]`).
    extent: [f64; 2],
    /// In-plane centroid and y extent of every element (effects see these).
    pub centroids: Vec<[f64; 2]>,
    pub element_y: Vec<[f64; 2]>,
    marker_weights: Vec<Vec<(usize, f64)>>,
    fixed_faces: Vec<Face>,
    rigid: LinearProblem<D>,
    /// Unfactorised problems with unit springs, per support layout.
    templates: Mutex<Vec<([bool; 2], LinearProblem<D>)>>,
    cache: Mutex<Vec<(Key, Arc<Entry<D>>)>>,
}

/// A point of the plane at height `z` (ignored in 2-D).
fn lift<const D: usize>(xy: [f64; 2], z: f64) -> [f64; D] {
    std::array::from_fn(|i| if i < 2 { xy[i] } else { z })
}

fn fixed_dirichlet<const D: usize>(mesh: &Mesh<D>, faces: &[Face]) -> Dirichlet {
    let mut dirichlet = Dirichlet::new();
    for &face in faces {
        for (dof, value) in Dirichlet::fixed_face(mesh, face).iter() {
            // Values are zero and dofs valid: setting cannot fail.
            let _ = dirichlet.set(dof, value);
        }
    }
    dirichlet
}

impl<const D: usize> Body<D> {
    /// A body on `mesh` (every element its own region) with the markers at
    /// `rest` on the top face (`z = thickness / 2` in 3-D).
    pub fn new(
        mesh: Mesh<D>,
        formulation: Formulation,
        thickness: f64,
        fixed_faces: Vec<Face>,
        rest: &[[f64; 2]],
    ) -> Result<Self, DiagnoseError> {
        let element_count = mesh.element_count();
        let mesh = Mesh::new(
            mesh.kind(),
            mesh.nodes().to_vec(),
            mesh.connectivity().to_vec(),
            (0..element_count).collect(),
        )?;
        let element_y = (0..element_count)
            .map(|e| {
                let ys = mesh.element(e).iter().map(|&n| mesh.node(n)[1]);
                let lo = ys.clone().fold(f64::INFINITY, f64::min);
                let hi = ys.fold(f64::NEG_INFINITY, f64::max);
                [lo, hi]
            })
            .collect();
        let centroids = (0..element_count)
            .map(|e| {
                let c = mesh.centroid(e);
                [c[0], c[1]]
            })
            .collect();
        let locator = Locator::new(&mesh);
        let marker_weights = rest
            .iter()
            .enumerate()
            .map(|(index, &p)| {
                let point = lift::<D>(p, 0.5 * thickness);
                locator
                    .weights(point)
                    .ok_or_else(|| needle_fem::FemError::PointOutsideMesh {
                        index,
                        coordinates: point.to_vec(),
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let rigid = LinearProblem::new(
            Assembler::new(mesh.clone(), formulation)?,
            vec![],
            fixed_dirichlet(&mesh, &fixed_faces),
        )?;
        let extent = mesh
            .nodes()
            .iter()
            .fold([0.0f64; 2], |e, x| [e[0].max(x[0]), e[1].max(x[1])]);
        Ok(Self {
            mesh,
            formulation,
            thickness,
            extent,
            centroids,
            element_y,
            marker_weights,
            fixed_faces,
            rigid,
            templates: Mutex::new(Vec::new()),
            cache: Mutex::new(Vec::new()),
        })
    }

    /// The factorised problem for element `moduli` and `supports`.
    ///
    /// $K = c\,(K_\text{el}(E/c) + K_\text{springs}/c)$ for any $c > 0$: the
    /// problem is factorised with the moduli and spring stiffnesses divided
    /// by $c$ = the first element's modulus, so fields that differ by a
    /// uniform factor (a finite-difference step in $E$, a stiffening over
    /// days) share one factorisation.
    pub fn factorized(
        &self,
        moduli: &[f64],
        poisson_ratio: f64,
        supports: SupportSpec,
    ) -> Result<Factorized<D>, DiagnoseError> {
        let scale = moduli.first().copied().unwrap_or(1.0);
        let moduli: Vec<f64> = moduli.iter().map(|e| e / scale).collect();
        let supports = SupportSpec {
            fixed_face_compliance: supports.fixed_face_compliance * scale,
            foundation: supports.foundation / scale,
        };
        let mut bits: Vec<u64> = moduli.iter().map(|e| e.to_bits()).collect();
        bits.push(poisson_ratio.to_bits());
        bits.push(supports.fixed_face_compliance.to_bits());
        bits.push(supports.foundation.to_bits());
        let key = Key(bits);
        if let Some((_, p)) = self
            .cache
            .lock()
            .expect("cache lock")
            .iter()
            .find(|(k, _)| *k == key)
        {
            return Ok(Factorized {
                entry: Arc::clone(p),
                scale,
            });
        }
        let materials = Materials(
            moduli
                .iter()
                .enumerate()
                .map(|(e, &m)| Material::for_region(e, m, poisson_ratio))
                .collect::<Result<_, _>>()?,
        );
        let mut problem = if supports.fixed_face_compliance <= 0.0 && supports.foundation <= 0.0 {
            self.rigid.clone()
        } else {
            self.supported(supports)?
        };
        problem.factorize(&materials)?;
        let entry = Arc::new(Entry {
            problem,
            probes: Mutex::new(Vec::new()),
        });
        let mut cache = self.cache.lock().expect("cache lock");
        let capacity = if D == 2 {
            PLANE_CACHE_SIZE
        } else {
            SLAB_CACHE_SIZE
        };
        if cache.len() >= capacity {
            cache.remove(0);
        }
        cache.push((key, Arc::clone(&entry)));
        Ok(Factorized { entry, scale })
    }

    /// The unfactorised problem with elastic supports: a clone of the
    /// template of their layout (compliant fixed faces, foundation), built
    /// once with unit springs, with the springs scaled, so that a new
    /// stiffness costs no new ordering or symbolic analysis.
    fn supported(&self, supports: SupportSpec) -> Result<LinearProblem<D>, DiagnoseError> {
        let compliant = supports.fixed_face_compliance > 0.0;
        let founded = supports.foundation > 0.0;
        let mut problem = {
            let mut templates = self.templates.lock().expect("template lock");
            match templates
                .iter()
                .find(|(layout, _)| *layout == [compliant, founded])
            {
                Some((_, template)) => template.clone(),
                None => {
                    let template = self.unit_springs(compliant, founded)?;
                    templates.push(([compliant, founded], template.clone()));
                    template
                }
            }
        };
        let mut index = 0;
        if compliant {
            for _ in &self.fixed_faces {
                problem.scale_support(index, 1.0 / supports.fixed_face_compliance)?;
                index += 1;
            }
        }
        if founded {
            problem.scale_support(index, supports.foundation)?;
        }
        Ok(problem)
    }

    /// The problem with springs of unit stiffness per unit area on the
    /// fixed faces (instead of holding them) if `compliant`, and under the
    /// body if `founded`, in that order.
    fn unit_springs(
        &self,
        compliant: bool,
        founded: bool,
    ) -> Result<LinearProblem<D>, DiagnoseError> {
        let mut springs = Vec::new();
        let dirichlet = if compliant {
            for &face in &self.fixed_faces {
                springs.push(Support::Boundary {
                    facets: self.mesh.facets_on_face(face),
                    stiffness: [1.0; D],
                });
            }
            Dirichlet::new()
        } else {
            fixed_dirichlet(&self.mesh, &self.fixed_faces)
        };
        if founded {
            springs.push(if D == 2 {
                Support::Foundation {
                    stiffness: [1.0; D],
                }
            } else {
                Support::Boundary {
                    facets: self.mesh.facets_on_face(Face::Bottom),
                    stiffness: [1.0; D],
                }
            });
        }
        Ok(LinearProblem::new(
            Assembler::new(self.mesh.clone(), self.formulation)?,
            springs,
            dirichlet,
        )?)
    }

    /// A point locator on the body's mesh (for the load functions).
    pub fn locator(&self) -> Locator<'_, D> {
        Locator::new(&self.mesh)
    }

    /// Marker displacements under unit probe forces along x and y at `tip`
    /// (divided by the factorisation's scale), solved once per
    /// factorisation and tip.
    pub fn probe_responses(
        &self,
        locator: &Locator<'_, D>,
        factorized: &Factorized<D>,
        contact: [f64; 2],
        width: f64,
    ) -> Result<[Vec<[f64; 2]>; 2], DiagnoseError> {
        let bits = [contact[0].to_bits(), contact[1].to_bits(), width.to_bits()];
        let scaled = |responses: &[Vec<[f64; 2]>; 2]| {
            responses.clone().map(|r| {
                r.iter()
                    .map(|u| [u[0] / factorized.scale, u[1] / factorized.scale])
                    .collect()
            })
        };
        let probes = &factorized.entry.probes;
        if let Some((_, r)) = probes
            .lock()
            .expect("probe cache lock")
            .iter()
            .find(|(k, _)| *k == bits)
        {
            return Ok(scaled(r));
        }
        let loads = [
            self.unit_probe_load(locator, contact, width, 0)?,
            self.unit_probe_load(locator, contact, width, 1)?,
        ];
        let solved = factorized
            .entry
            .problem
            .displacements_many(&[&loads[0], &loads[1]])?;
        let responses = [0, 1].map(|k| self.markers(&solved[k], 1.0));
        let out = scaled(&responses);
        probes
            .lock()
            .expect("probe cache lock")
            .push((bits, responses));
        Ok(out)
    }

    /// Load vector of a unit force along `axis` (0: x, 1: y) on the
    /// probe's contact patch: a rigid flat punch of `width` along the
    /// boundary through `contact` (through the whole thickness in 3-D),
    /// whose contact pressure is $p(s) \propto 1/\sqrt{1 - (2s/a)^2}$.
    fn unit_probe_load(
        &self,
        locator: &Locator<'_, D>,
        contact: [f64; 2],
        width: f64,
        axis: usize,
    ) -> Result<Vec<f64>, DiagnoseError> {
        let mut load = vec![0.0; self.mesh.dof_count()];
        let mut unit = [0.0; D];
        unit[axis] = 1.0 / PATCH_POINTS as f64;
        // The patch runs along the face the contact lies on.
        let along = if contact[1] <= 0.0 || contact[1] >= self.extent[1] {
            [1.0, 0.0]
        } else {
            [0.0, 1.0]
        };
        for i in 0..PATCH_POINTS {
            let angle = (2 * i + 1) as f64 * std::f64::consts::PI / (2 * PATCH_POINTS) as f64;
            let s = 0.5 * width * angle.cos();
            // A patch reaching past a corner is cut at the outline.
            let point = [
                (contact[0] + s * along[0]).clamp(0.0, self.extent[0]),
                (contact[1] + s * along[1]).clamp(0.0, self.extent[1]),
            ];
            if D == 2 {
                needle_fem::load::add_point_force(locator, &mut load, lift(point, 0.0), unit)?;
            } else {
                let per_length = unit.map(|v| v / self.thickness);
                let density = move |_: f64| per_length;
                add_line_load(
                    locator,
                    &mut load,
                    lift(point, -0.5 * self.thickness),
                    lift(point, 0.5 * self.thickness),
                    &LineDensity::Function {
                        density: &density,
                        breakpoints: Vec::new(),
                    },
                )?;
            }
        }
        Ok(load)
    }

    /// Load vector of the needle's shaft load in the mid-plane: along each
    /// material piece of `placement`, the density $q(s)\,\hat d$ of the
    /// spatial arclength $s$ rescaled by the piece's spatial over material
    /// length (see `place`); `breakpoints` are where $q$ kinks.
    pub fn needle_load(
        &self,
        locator: &Locator<'_, D>,
        shaft: &Shaft,
        placement: &Placement,
        density: &(dyn Fn(f64) -> f64 + Sync),
        breakpoints: &[f64],
    ) -> Result<Vec<f64>, DiagnoseError> {
        let mut load = vec![0.0; self.mesh.dof_count()];
        let direction = shaft.direction;
        for piece in placement.pieces(shaft) {
            let material_length =
                (piece.end[0] - piece.start[0]).hypot(piece.end[1] - piece.start[1]);
            let spatial_length = piece.s_end - piece.s_start;
            if material_length == 0.0 || spatial_length <= 0.0 {
                continue;
            }
            let stretch = spatial_length / material_length;
            // `m` is the material arclength along the piece.
            let along = |m: f64| -> [f64; D] {
                let q = stretch * density(piece.s_start + m * stretch);
                lift([q * direction[0], q * direction[1]], 0.0)
            };
            let kinks = breakpoints
                .iter()
                .filter(|&&b| b > piece.s_start && b < piece.s_end)
                .map(|b| (b - piece.s_start) / stretch)
                .collect();
            add_line_load(
                locator,
                &mut load,
                lift(piece.start, 0.0),
                lift(piece.end, 0.0),
                &LineDensity::Function {
                    density: &along,
                    breakpoints: kinks,
                },
            )?;
        }
        Ok(load)
    }

    /// In-plane displacement of the mid-plane point `xy` (clamped into the
    /// outline) in the solution `u`, divided by the factorisation's `scale`.
    pub fn mid_plane_displacement(
        &self,
        locator: &Locator<'_, D>,
        u: &[f64],
        scale: f64,
        xy: [f64; 2],
    ) -> Result<[f64; 2], DiagnoseError> {
        let inside = [
            xy[0].clamp(0.0, self.extent[0]),
            xy[1].clamp(0.0, self.extent[1]),
        ];
        let point = lift::<D>(inside, 0.0);
        let weights =
            locator
                .weights(point)
                .ok_or_else(|| needle_fem::FemError::PointOutsideMesh {
                    index: 0,
                    coordinates: point.to_vec(),
                })?;
        let mut v = [0.0; 2];
        for (n, w) in weights {
            v[0] += w * u[D * n];
            v[1] += w * u[D * n + 1];
        }
        Ok([v[0] / scale, v[1] / scale])
    }

    /// Largest x and y of the outline.
    pub fn extent(&self) -> [f64; 2] {
        self.extent
    }

    /// In-plane displacement of every marker in the solution `u`, divided
    /// by the factorisation's `scale`.
    pub fn markers(&self, u: &[f64], scale: f64) -> Vec<[f64; 2]> {
        self.marker_weights
            .iter()
            .map(|weights| {
                let mut v = [0.0; 2];
                for &(n, w) in weights {
                    v[0] += w * u[D * n];
                    v[1] += w * u[D * n + 1];
                }
                [v[0] / scale, v[1] / scale]
            })
            .collect()
    }
}
