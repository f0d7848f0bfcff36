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
//!
//! The slab is symmetric about its mid-plane and so is every load on it
//! (the needle in the mid-plane, a probe evenly through the thickness) and
//! every support but the foundation under its bottom face, so its
//! displacement is symmetric: $u_x, u_y$ even in $z$, $u_z$ odd. A body
//! spanning [`Span::UpperHalf`] meshes $z \in [0, t/2]$ only (the top half
//! of needle-fem's mirrored slab), holds $u_z = 0$ on $z = 0$ and takes
//! half of each mid-plane load: the mirrored whole slab's displacement
//! exactly, on three node planes instead of five (needle-fem's test
//! `upper_half_of_the_mirrored_slab_gives_its_displacement`). A foundation
//! needs the whole slab.
//!
//! For `material_nonlinearity` a body also gives the neo-Hookean terms of
//! its solutions to third order in the load (see `series`), on the same
//! factorisation.

use std::sync::{Arc, Mutex, OnceLock};

use needle_fem::load::add_line_load;
use needle_fem::{
    Assembler, Dirichlet, Face, Formulation, HyperelasticAssembler, LineDensity, LinearProblem,
    Locator, Material, Materials, Mesh, Support,
};

use crate::effect::SupportSpec;
use crate::error::DiagnoseError;
use crate::observe::Shaft;
use crate::place::Placement;
use crate::series::{ProbeSeries, Series};

/// Factorisations kept per plane body (one per distinct normalised
/// material field and support). An evaluation needs one per group of
/// trials with proportional material fields (one group unless an effect
/// makes the trials' fields differ other than by a factor), and a fit
/// evaluates on every thread of the pool; entries a parameter point needs
/// again are needed within a few evaluations. Until the cache is full every new
/// factorisation clears fresh pages, and after, it takes over an evicted
/// entry's storage: on the default diagnosis 16 entries (and 4 per slab)
/// made the same 93 plane factorisations as 48 (and 8), but 22 instead of
/// 51 on fresh storage, and the run took 31.2 and 33.1 s against 38.0 and
/// 37.0 s, with 2.5 to 2.9 s of system time against 11 to 12 s and a peak
/// of 3.0 GB against 4.3 to 4.5 GB (`docs/benchmarks.md`, session 33).
const PLANE_CACHE_SIZE: usize = 16;
/// Factorisations kept per 3-D slab: each holds a Cholesky factor of
/// about 100 MB for the default marker grid (48 of them took 5 GB). At 4
/// the default diagnosis made 38 half-slab factorisations against 36 at 8,
/// 7 of them on fresh storage against 10 or 11 (see [`PLANE_CACHE_SIZE`]).
const SLAB_CACHE_SIZE: usize = 4;

/// Points of a needle's surface, on the half circle above the mid-plane,
/// over which [`Body::needle_drag`] averages: with the mirrored half, twelve
/// around the needle (the truth's count; three per half moved the truth's
/// markers by up to 2.9 um against twelve).
const RIM_POINTS: usize = 6;

/// Gauss-Chebyshev points across a probe's contact patch: the rigid flat
/// punch's pressure $p(s) \propto 1/\sqrt{1 - (2s/a)^2}$ is the rule's
/// weight, so equal forces at $s_i = \tfrac a2 \cos\frac{(2i+1)\pi}{2n}$
/// integrate it exactly for polynomial test functions of degree $< 2n$.
const PATCH_POINTS: usize = 8;

/// Identity of a factorisation: the exact bits of every normalised element
/// modulus, Poisson's ratio and the normalised supports.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Key(Vec<u64>);

/// Marker responses to a unit probe force along x, one along y and a unit
/// moment about z on one contact patch, keyed by the bits of the contact
/// point and the patch width.
type ProbeResponses = ([u64; 3], [Vec<[f64; 2]>; 3]);

/// The nonlinear terms of one contact patch (see [`Body::probe_series`]),
/// same key.
type ProbeSeriesEntry = ([u64; 3], ProbeSeries);

/// A kept factorisation with the probe responses already solved on it
/// (they depend on nothing else, so a fit solves each tip once per
/// material).
pub(crate) struct Entry<const D: usize> {
    pub problem: LinearProblem<D>,
    /// The normalised materials it was factorised with.
    materials: Materials,
    probes: Mutex<Vec<ProbeResponses>>,
    series: Mutex<Vec<ProbeSeriesEntry>>,
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
    span: Span,
    rigid: LinearProblem<D>,
    /// Shortest y extent of an element (m).
    element_size: f64,
    /// Neo-Hookean internal forces, built on first use.
    hyperelastic: OnceLock<HyperelasticAssembler<D>>,
    /// Unfactorised problems with unit springs, per support layout.
    templates: Mutex<Vec<([bool; 2], LinearProblem<D>)>>,
    cache: Mutex<Vec<(Key, Arc<Entry<D>>)>>,
}

/// Which part of the phantom's thickness a body meshes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Span {
    /// All of it: the plane model, or a slab with a foundation.
    Whole,
    /// The half above the mid-plane of a slab symmetric about it (see the
    /// module doc).
    UpperHalf,
}

/// A point of the plane at height `z` (ignored in 2-D).
fn lift<const D: usize>(xy: [f64; 2], z: f64) -> [f64; D] {
    std::array::from_fn(|i| if i < 2 { xy[i] } else { z })
}

/// The in-plane components of the solution `u` interpolated at `point`.
fn in_plane_at<const D: usize>(
    locator: &Locator<'_, D>,
    u: &[f64],
    point: [f64; D],
) -> Result<[f64; 2], DiagnoseError> {
    let weights = locator
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
    Ok(v)
}

/// The held dofs: every dof of the `faces`, and on a body of the upper
/// half $u_z$ on its bottom face, the mid-plane.
fn held<const D: usize>(mesh: &Mesh<D>, faces: &[Face], span: Span) -> Dirichlet {
    let mut dirichlet = Dirichlet::new();
    // Values are zero and dofs valid: setting cannot fail.
    for &face in faces {
        for (dof, value) in Dirichlet::fixed_face(mesh, face).iter() {
            let _ = dirichlet.set(dof, value);
        }
    }
    if span == Span::UpperHalf && D == 3 {
        let _ = dirichlet.set_nodes(mesh, &mesh.nodes_on_face(Face::Bottom), 2, 0.0);
    }
    dirichlet
}

impl<const D: usize> Body<D> {
    /// A body on `mesh` (every element its own region) spanning `span` of
    /// the `thickness`, with the markers at `rest` on the top face
    /// (`z = thickness / 2` in 3-D).
    pub fn new(
        mesh: Mesh<D>,
        formulation: Formulation,
        thickness: f64,
        span: Span,
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
        let element_y: Vec<[f64; 2]> = (0..element_count)
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
            held(&mesh, &fixed_faces, span),
        )?;
        let element_size = element_y
            .iter()
            .map(|[lo, hi]| hi - lo)
            .fold(f64::INFINITY, f64::min);
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
            span,
            rigid,
            element_size,
            hyperelastic: OnceLock::new(),
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
        let capacity = if D == 2 {
            PLANE_CACHE_SIZE
        } else {
            SLAB_CACHE_SIZE
        };
        // An entry leaves the cache now rather than once this one is in:
        // the oldest that no evaluation holds any more (else the oldest),
        // whose storage (the assembled matrix and the factor, 74 MB on the
        // default campaign's graded slab) the new problem takes over
        // instead of clearing fresh pages, every value of which the
        // factorisation would overwrite.
        let evicted = {
            let mut cache = self.cache.lock().expect("cache lock");
            (cache.len() >= capacity).then(|| {
                let idle = cache
                    .iter()
                    .position(|(_, entry)| Arc::strong_count(entry) == 1)
                    .unwrap_or(0);
                cache.remove(idle).1
            })
        };
        let recycled = evicted
            .and_then(|entry| Arc::try_unwrap(entry).ok())
            .map(|entry| entry.problem);
        let mut problem = self.unfactorised(supports, recycled)?;
        problem.factorize(&materials)?;
        let entry = Arc::new(Entry {
            problem,
            materials,
            probes: Mutex::new(Vec::new()),
            series: Mutex::new(Vec::new()),
        });
        let mut cache = self.cache.lock().expect("cache lock");
        if cache.len() >= capacity {
            cache.remove(0);
        }
        cache.push((key, Arc::clone(&entry)));
        Ok(Factorized { entry, scale })
    }

    /// The unfactorised problem with `supports`: a copy of the rigid
    /// problem, or of the template of their layout (compliant fixed faces,
    /// foundation), built once with unit springs, with the springs scaled,
    /// so that a new stiffness costs no new ordering or symbolic analysis.
    /// The copy goes into `recycled`'s storage where it has the same
    /// layout (see [`LinearProblem`]'s `clone_from`).
    fn unfactorised(
        &self,
        supports: SupportSpec,
        recycled: Option<LinearProblem<D>>,
    ) -> Result<LinearProblem<D>, DiagnoseError> {
        let copy = |template: &LinearProblem<D>| match recycled {
            Some(mut problem) => {
                problem.clone_from(template);
                problem
            }
            None => template.clone(),
        };
        let compliant = supports.fixed_face_compliance > 0.0;
        let founded = supports.foundation > 0.0;
        if !(compliant || founded) {
            return Ok(copy(&self.rigid));
        }
        let mut problem = self.with_template([compliant, founded], copy)?;
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

    /// Builds the template of the spring `layout` (compliant fixed faces,
    /// foundation) if it is not there yet, ahead of its first use.
    pub fn prepare_template(&self, layout: [bool; 2]) -> Result<(), DiagnoseError> {
        self.with_template(layout, |_| ())
    }

    /// The spring layouts whose templates are built.
    #[cfg(test)]
    pub fn template_layouts(&self) -> Vec<[bool; 2]> {
        let templates = self.templates.lock().expect("template lock");
        templates.iter().map(|(layout, _)| *layout).collect()
    }

    /// `use_template` on the template of the spring `layout`, built first
    /// if need be. A template being built holds the lock: a second caller
    /// waits for it instead of building it again.
    fn with_template<R>(
        &self,
        layout: [bool; 2],
        use_template: impl FnOnce(&LinearProblem<D>) -> R,
    ) -> Result<R, DiagnoseError> {
        let mut templates = self.templates.lock().expect("template lock");
        if let Some((_, template)) = templates.iter().find(|(kept, _)| *kept == layout) {
            return Ok(use_template(template));
        }
        // Used before it is kept, not kept as a copy: one copy of a problem
        // as large as the whole slab's instead of two.
        let template = self.unit_springs(layout[0], layout[1])?;
        let used = use_template(&template);
        templates.push((layout, template));
        Ok(used)
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
            held(&self.mesh, &[], self.span)
        } else {
            held(&self.mesh, &self.fixed_faces, self.span)
        };
        if founded && self.span == Span::UpperHalf {
            return Err(DiagnoseError::InvalidOption {
                field: "foundation",
                reason: "a foundation under the slab breaks its symmetry about the mid-plane; \
                         it needs the whole slab"
                    .into(),
            });
        }
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

    /// Marker displacements under a unit probe force along x, one along y
    /// and a unit moment about z on the patch at `contact` (divided by the
    /// factorisation's scale), solved once per factorisation and tip.
    pub fn probe_responses(
        &self,
        locator: &Locator<'_, D>,
        factorized: &Factorized<D>,
        contact: [f64; 2],
        width: f64,
    ) -> Result<[Vec<[f64; 2]>; 3], DiagnoseError> {
        let bits = [contact[0].to_bits(), contact[1].to_bits(), width.to_bits()];
        let scaled = |responses: &[Vec<[f64; 2]>; 3]| {
            responses.clone().map(|r| {
                r.iter()
                    .map(|u| [u[0] / factorized.scale, u[1] / factorized.scale])
                    .collect()
            })
        };
        self.solve_probe_responses(locator, factorized, &[contact], width)?;
        let probes = factorized.entry.probes.lock().expect("probe cache lock");
        let (_, responses) = probes
            .iter()
            .find(|(k, _)| *k == bits)
            .expect("solved above");
        Ok(scaled(responses))
    }

    /// Solves the unit responses (see [`Body::probe_responses`]) of every
    /// patch of `contacts` not solved on this factorisation yet, all in one
    /// blocked solve: three loads at a time used the factor's kernels at a
    /// quarter of the rate forty did (`docs/benchmarks.md`, session 29).
    pub fn solve_probe_responses(
        &self,
        locator: &Locator<'_, D>,
        factorized: &Factorized<D>,
        contacts: &[[f64; 2]],
        width: f64,
    ) -> Result<(), DiagnoseError> {
        let mut missing: Vec<[u64; 3]> = Vec::new();
        {
            let probes = factorized.entry.probes.lock().expect("probe cache lock");
            for contact in contacts {
                let bits = [contact[0].to_bits(), contact[1].to_bits(), width.to_bits()];
                if !missing.contains(&bits) && !probes.iter().any(|(k, _)| *k == bits) {
                    missing.push(bits);
                }
            }
        }
        if missing.is_empty() {
            return Ok(());
        }
        let mut loads = Vec::with_capacity(3 * missing.len());
        for bits in &missing {
            let contact = [f64::from_bits(bits[0]), f64::from_bits(bits[1])];
            for axis in 0..3 {
                loads.push(self.unit_probe_load(locator, contact, width, axis)?);
            }
        }
        let loads: Vec<&[f64]> = loads.iter().map(Vec::as_slice).collect();
        let solved = factorized.entry.problem.displacements_many(&loads)?;
        let mut probes = factorized.entry.probes.lock().expect("probe cache lock");
        for (bits, solved) in missing.into_iter().zip(solved.chunks_exact(3)) {
            let responses = [0, 1, 2].map(|k| self.markers(&solved[k], 1.0));
            probes.push((bits, responses));
        }
        Ok(())
    }

    /// The neo-Hookean terms $u_2 + u_3$ of the marker displacements under
    /// a probe on the patch at `contact`, as forms in the probe force (see
    /// [`ProbeSeries`]). Solved once per factorisation and tip, like
    /// [`Body::probe_responses`].
    pub fn probe_series(
        &self,
        locator: &Locator<'_, D>,
        factorized: &Factorized<D>,
        contact: [f64; 2],
        width: f64,
    ) -> Result<ProbeSeries, DiagnoseError> {
        let bits = [contact[0].to_bits(), contact[1].to_bits(), width.to_bits()];
        let cache = &factorized.entry.series;
        if let Some((_, series)) = cache
            .lock()
            .expect("series cache lock")
            .iter()
            .find(|(k, _)| *k == bits)
        {
            return Ok(series.scaled(factorized.scale));
        }
        let solved = self.unit_probe_solutions(locator, factorized, contact, width, &[0, 1])?;
        let (gx, gy) = (&solved[0], &solved[1]);
        let sum: Vec<f64> = gx.iter().zip(gy).map(|(a, b)| a + b).collect();
        let difference: Vec<f64> = gx.iter().zip(gy).map(|(a, b)| a - b).collect();
        let terms = self.nonlinear_terms(factorized, &[gx, gy, &sum, &difference])?;
        let at_markers: Vec<[Vec<[f64; 2]>; 2]> = terms
            .iter()
            .map(|pair| pair.each_ref().map(|u| self.markers(u, 1.0)))
            .collect();
        let directions: [[Vec<[f64; 2]>; 2]; 4] = at_markers
            .try_into()
            .unwrap_or_else(|_| unreachable!("four directions give four terms"));
        let series = ProbeSeries::from_directions(directions);
        let out = series.scaled(factorized.scale);
        cache
            .lock()
            .expect("series cache lock")
            .push((bits, series));
        Ok(out)
    }

    /// The neo-Hookean terms $[c^2 u_2, c^3 u_3]$ of the solutions
    /// $c\,u_1$ of `factorized` as it returns them ($c$ its scale; see
    /// `series`).
    pub fn nonlinear_terms(
        &self,
        factorized: &Factorized<D>,
        solutions: &[&[f64]],
    ) -> Result<Vec<[Vec<f64>; 2]>, DiagnoseError> {
        Series {
            assembler: self.hyperelastic()?,
            materials: &factorized.entry.materials,
            problem: &factorized.entry.problem,
            element_size: self.element_size,
        }
        .terms(solutions)
    }

    /// The neo-Hookean assembler of the body's mesh.
    fn hyperelastic(&self) -> Result<&HyperelasticAssembler<D>, DiagnoseError> {
        if let Some(assembler) = self.hyperelastic.get() {
            return Ok(assembler);
        }
        let built = HyperelasticAssembler::new(self.rigid.assembler().clone())?;
        Ok(self.hyperelastic.get_or_init(|| built))
    }

    /// Solutions (not divided by the factorisation's scale) under the
    /// unit loads `axes` (see [`Body::unit_probe_load`]) on the patch at
    /// `contact`.
    fn unit_probe_solutions(
        &self,
        locator: &Locator<'_, D>,
        factorized: &Factorized<D>,
        contact: [f64; 2],
        width: f64,
        axes: &[usize],
    ) -> Result<Vec<Vec<f64>>, DiagnoseError> {
        let loads = axes
            .iter()
            .map(|&axis| self.unit_probe_load(locator, contact, width, axis))
            .collect::<Result<Vec<_>, _>>()?;
        let loads: Vec<&[f64]> = loads.iter().map(Vec::as_slice).collect();
        Ok(factorized.entry.problem.displacements_many(&loads)?)
    }

    /// Load vector on the probe's contact patch, a rigid flat punch of
    /// `width` $a$ along the boundary through `contact` (through the whole
    /// thickness in 3-D): for `axis` 0 or 1 a unit force along x or y,
    /// whose pressure is the punch's $p(s) \propto 1/\sqrt{1 - (2s/a)^2}$;
    /// for `axis` 2 a unit moment about z at `contact`, as the tilted
    /// punch's normal pressure $p(s) \propto s/\sqrt{1 - (2s/a)^2}$ (no net
    /// force). On the Gauss-Chebyshev points the latter is a force
    /// $8 s_i / (n a^2)$ at each, whose moment $\sum 8 s_i^2 / (n a^2)$ is
    /// exactly 1.
    fn unit_probe_load(
        &self,
        locator: &Locator<'_, D>,
        contact: [f64; 2],
        width: f64,
        axis: usize,
    ) -> Result<Vec<f64>, DiagnoseError> {
        let mut load = vec![0.0; self.mesh.dof_count()];
        // The patch runs along the face the contact lies on.
        let along = if contact[1] <= 0.0 || contact[1] >= self.extent[1] {
            [1.0, 0.0]
        } else {
            [0.0, 1.0]
        };
        // Turned a quarter anticlockwise, so that `along` x `normal` = +z.
        let normal = [-along[1], along[0]];
        for i in 0..PATCH_POINTS {
            let angle = (2 * i + 1) as f64 * std::f64::consts::PI / (2 * PATCH_POINTS) as f64;
            let s = 0.5 * width * angle.cos();
            let mut unit = [0.0; D];
            if axis < 2 {
                unit[axis] = 1.0 / PATCH_POINTS as f64;
            } else {
                let force = 8.0 * s / (PATCH_POINTS as f64 * width * width);
                unit[0] = force * normal[0];
                unit[1] = force * normal[1];
            }
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
                    lift(point, self.bottom()),
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
        let share = self.mid_plane_share();
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
                let q = share * stretch * density(piece.s_start + m * stretch);
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
        let v = in_plane_at(locator, u, lift::<D>(inside, 0.0))?;
        Ok([v[0] / scale, v[1] / scale])
    }

    /// The drag that places a needle's load at the mid-plane point `xy`
    /// (clamped into the outline), for a needle along `direction` of
    /// `radius`: in the slab the mean in-plane displacement over
    /// [`RIM_POINTS`] points of its surface, at angles
    /// $\theta_k = (k + \tfrac12)\pi/n$ on the half circle around the axis
    /// in the plane normal to the needle (the upper half's; the whole
    /// slab lists the mirrored half too), else [`Body::mid_plane_displacement`].
    /// In 3-D a line load's displacement grows as $\ln r$ towards the
    /// line, so a drag read on the axis grows as the slab is refined
    /// towards the needle; read on its surface it settles.
    pub fn needle_drag(
        &self,
        locator: &Locator<'_, D>,
        u: &[f64],
        scale: f64,
        xy: [f64; 2],
        direction: [f64; 2],
        radius: f64,
    ) -> Result<[f64; 2], DiagnoseError> {
        if D == 2 || radius == 0.0 {
            return self.mid_plane_displacement(locator, u, scale, xy);
        }
        let normal = [direction[1], -direction[0]];
        let sides: &[f64] = match self.span {
            Span::UpperHalf => &[1.0],
            Span::Whole => &[1.0, -1.0],
        };
        let top = 0.5 * self.thickness;
        let count = (RIM_POINTS * sides.len()) as f64;
        let mut v = [0.0; 2];
        for &side in sides {
            for k in 0..RIM_POINTS {
                let t = (k as f64 + 0.5) * std::f64::consts::PI / RIM_POINTS as f64;
                let plan = [
                    (xy[0] + radius * t.cos() * normal[0]).clamp(0.0, self.extent[0]),
                    (xy[1] + radius * t.cos() * normal[1]).clamp(0.0, self.extent[1]),
                ];
                let z = (side * radius * t.sin()).clamp(-top, top);
                let at = in_plane_at(locator, u, lift::<D>(plan, z))?;
                v[0] += at[0] / count;
                v[1] += at[1] / count;
            }
        }
        Ok([v[0] / scale, v[1] / scale])
    }

    /// The dofs of the elements within `reach` (in plan, and of the
    /// mid-plane in depth) of the box that holds the material line of
    /// `placement`: where a re-placement of its load reads the
    /// displacement (see [`Body::needle_drag`]; the entry's Newton steps
    /// along the front face too) while the load moves by less than
    /// `reach` less the needle's radius.
    pub fn needle_dofs(
        &self,
        locator: &Locator<'_, D>,
        placement: &Placement,
        reach: f64,
    ) -> Vec<usize> {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for xy in &placement.material {
            for axis in 0..2 {
                lo[axis] = lo[axis].min(xy[axis] - reach);
                hi[axis] = hi[axis].max(xy[axis] + reach);
            }
        }
        let mut near = vec![false; self.mesh.node_count()];
        for e in locator.candidates(lift(lo, -reach), lift(hi, reach)) {
            for &n in self.mesh.element(e) {
                near[n] = true;
            }
        }
        (near.iter().enumerate())
            .filter(|(_, near)| **near)
            .flat_map(|(n, _)| D * n..D * (n + 1))
            .collect()
    }

    /// Largest x and y of the outline.
    pub fn extent(&self) -> [f64; 2] {
        self.extent
    }

    /// z of the bottom face (3-D).
    fn bottom(&self) -> f64 {
        match self.span {
            Span::Whole => -0.5 * self.thickness,
            Span::UpperHalf => 0.0,
        }
    }

    /// The share of a load in the mid-plane that this body carries.
    fn mid_plane_share(&self) -> f64 {
        match self.span {
            Span::Whole => 1.0,
            Span::UpperHalf => 0.5,
        }
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

#[cfg(test)]
mod tests {
    use needle_fem::{ElementKind, HyperelasticProblem, NonlinearOptions, RectangleMesh, SlabMesh};

    use super::*;
    use crate::series::ProbeSeries;

    const MODULUS: f64 = 25.0e3;
    const POISSON: f64 = 0.45;
    const THICKNESS: f64 = 0.0075;
    const WIDTH: f64 = 0.003;

    /// A plane-strain body of the paper's phantom, back face fixed, with
    /// markers on a 3 x 3 grid.
    fn plane_body() -> Body<2> {
        let mesh = RectangleMesh::uniform(0.075, 0.075, 12, 12)
            .unwrap()
            .build(ElementKind::Tri6)
            .unwrap();
        let rest: Vec<[f64; 2]> = [0.02, 0.0375, 0.055]
            .iter()
            .flat_map(|&y| [0.02, 0.0375, 0.055].map(|x| [x, y]))
            .collect();
        Body::new(
            mesh,
            Formulation::PlaneStrain {
                thickness: THICKNESS,
            },
            THICKNESS,
            Span::Whole,
            vec![Face::Back],
            &rest,
        )
        .unwrap()
    }

    /// A Tet10 slab of two layers on an 8 x 8 plan, one marker.
    fn slab_body() -> Body<3> {
        let plan = RectangleMesh::uniform(0.075, 0.075, 8, 8).unwrap();
        let slab = SlabMesh::new(plan, THICKNESS, 2)
            .unwrap()
            .build(ElementKind::Tet10)
            .unwrap();
        Body::new(
            slab,
            Formulation::Solid,
            THICKNESS,
            Span::Whole,
            vec![Face::Back],
            &[[0.0375, 0.0375]],
        )
        .unwrap()
    }

    /// On `body` under a needle along y, 30 mm into it at x = 30 mm, the
    /// drag of a needle of `radius` halfway along it, and the mid-plane
    /// displacement on its axis there.
    fn drag_and_axis<const D: usize>(body: &Body<D>, radius: f64) -> ([f64; 2], [f64; 2]) {
        let shaft = Shaft {
            entry: [0.03, 0.0],
            direction: [0.0, 1.0],
            length: 0.03,
        };
        let point = [0.03, 0.015];
        let locator = body.locator();
        let load = body
            .needle_load(&locator, &shaft, &Placement::spatial(&shaft), &|_| 5.0, &[])
            .unwrap();
        let moduli = vec![MODULUS; body.centroids.len()];
        let factorized = body
            .factorized(&moduli, POISSON, SupportSpec::default())
            .unwrap();
        let u = factorized
            .entry
            .problem
            .displacements_many(&[&load])
            .unwrap();
        let scale = factorized.scale;
        let drag = body
            .needle_drag(&locator, &u[0], scale, point, shaft.direction, radius)
            .unwrap();
        let axis = body
            .mid_plane_displacement(&locator, &u[0], scale, point)
            .unwrap();
        (drag, axis)
    }

    /// On a slab the drag read on the needle's surface is smaller than on
    /// its axis (in 3-D the displacement grows towards a line load), and
    /// tends to the axis's as the radius shrinks; the plane body ignores
    /// the radius.
    #[test]
    fn a_needles_drag_on_its_surface_is_below_its_axis_and_shrinks_to_it() {
        let slab = slab_body();
        let (surface, axis) = drag_and_axis(&slab, 0.001);
        assert!(axis[1] > 0.0, "the needle drags the tissue along: {axis:?}");
        assert!(surface[1] < 0.99 * axis[1], "{surface:?} against {axis:?}");
        let (thin, _) = drag_and_axis(&slab, 1e-9);
        assert!(
            (thin[1] - axis[1]).abs() < 1e-6 * axis[1],
            "{thin:?} against {axis:?}"
        );
        assert_eq!(drag_and_axis(&slab, 0.0).0, axis);

        let plane = Body::new(
            RectangleMesh::uniform(0.075, 0.075, 8, 8)
                .unwrap()
                .build(ElementKind::Tri6)
                .unwrap(),
            Formulation::PlaneStrain {
                thickness: THICKNESS,
            },
            THICKNESS,
            Span::Whole,
            vec![Face::Back],
            &[[0.0375, 0.0375]],
        )
        .unwrap();
        let (drag, axis) = drag_and_axis(&plane, 0.001);
        assert_eq!(drag, axis);
    }

    /// Once the cache is full, a new factorisation takes over the storage
    /// of an entry no evaluation holds; it solves to the bit as a
    /// factorisation on a fresh body, whether the storage was of its own
    /// support layout or of another.
    #[test]
    fn a_factorisation_on_recycled_storage_solves_as_a_fresh_one() {
        let slab = slab_body();
        let moduli = vec![MODULUS; slab.centroids.len()];
        let shaft = Shaft {
            entry: [0.03, 0.0],
            direction: [0.0, 1.0],
            length: 0.03,
        };
        let load = slab
            .needle_load(
                &slab.locator(),
                &shaft,
                &Placement::spatial(&shaft),
                &|_| 5.0,
                &[],
            )
            .unwrap();
        let solve = |body: &Body<3>, nu: f64, supports: SupportSpec| {
            let factorized = body.factorized(&moduli, nu, supports).unwrap();
            let u = factorized
                .entry
                .problem
                .displacements_many(&[&load])
                .unwrap();
            u.into_iter().next().unwrap()
        };
        let rigid = SupportSpec::default();
        for k in 0..SLAB_CACHE_SIZE {
            solve(&slab, 0.30 + 0.01 * k as f64, rigid);
        }
        let compliance = |c: f64| SupportSpec {
            fixed_face_compliance: c,
            ..SupportSpec::default()
        };
        // Rigid storage, then (once compliant entries fill the cache)
        // compliant storage, each taken over by both layouts.
        let filling = (2..=SLAB_CACHE_SIZE).map(|k| (0.40, compliance(k as f64 * 1e-6)));
        let cases = [(0.48, rigid), (0.47, compliance(1e-6))]
            .into_iter()
            .chain(filling)
            .chain([(0.45, compliance(1e-5)), (0.46, rigid)]);
        for (nu, supports) in cases {
            let recycled = solve(&slab, nu, supports);
            let fresh = solve(&slab_body(), nu, supports);
            assert!(
                recycled
                    .iter()
                    .zip(&fresh)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "nu {nu}"
            );
        }
    }

    /// The unit probe load on a Tet10 slab of two layers (the forward
    /// model's) carries the punch's force and its moments: total 1 along
    /// the axis, centred on the contact, the rigid punch's second moment
    /// $a^2/8$ across the width and the even spread's $t^2/12$ through the
    /// thickness (quadratic shape functions reproduce $x^2$ and $z^2$, so
    /// the nodal loads keep the moments of the load they spread).
    #[test]
    fn slab_probe_load_has_the_patch_moments() {
        let body = slab_body();
        let locator = body.locator();
        let contact = [0.03, 0.0];
        let load = body.unit_probe_load(&locator, contact, WIDTH, 1).unwrap();
        let nodes = body.mesh.nodes();
        let moment = |f: &dyn Fn(&[f64; 3]) -> f64| -> f64 {
            nodes
                .iter()
                .enumerate()
                .map(|(n, x)| load[3 * n + 1] * f(x))
                .sum()
        };
        let off_axis: f64 = (0..nodes.len())
            .map(|n| load[3 * n].abs() + load[3 * n + 2].abs())
            .sum();
        let total = moment(&|_| 1.0);
        assert!(
            (total - 1.0).abs() < 1e-12 && off_axis < 1e-12,
            "{total} {off_axis}"
        );
        assert!(moment(&|x| x[0] - contact[0]).abs() < 1e-12);
        assert!(moment(&|x| x[2]).abs() < 1e-12);
        let across = moment(&|x| (x[0] - contact[0]).powi(2));
        let through = moment(&|x| x[2].powi(2));
        assert!(
            (across / (WIDTH * WIDTH / 8.0) - 1.0).abs() < 1e-9,
            "{across}"
        );
        assert!(
            (through / (THICKNESS * THICKNESS / 12.0) - 1.0).abs() < 1e-9,
            "{through}"
        );
    }

    /// The unit moment load carries no net force and a unit moment about
    /// z at the contact, on the front face and on a side face, in the
    /// plane and in the slab.
    #[test]
    fn probe_moment_load_is_a_unit_couple() {
        let slab = slab_body();
        let plane = plane_body();
        fn couple<const D: usize>(body: &Body<D>, contact: [f64; 2]) -> [f64; 3] {
            let load = body
                .unit_probe_load(&body.locator(), contact, WIDTH, 2)
                .unwrap();
            let mut out = [0.0; 3];
            for (n, x) in body.mesh.nodes().iter().enumerate() {
                let [fx, fy] = [load[D * n], load[D * n + 1]];
                out[0] += fx;
                out[1] += fy;
                out[2] += (x[0] - contact[0]) * fy - (x[1] - contact[1]) * fx;
            }
            out
        }
        for contact in [[0.03, 0.0], [0.075, 0.04], [0.0, 0.02]] {
            for [fx, fy, moment] in [couple(&slab, contact), couple(&plane, contact)] {
                assert!(
                    fx.abs() < 1e-12 && fy.abs() < 1e-12,
                    "{contact:?}: {fx} {fy}"
                );
                assert!((moment - 1.0).abs() < 1e-9, "{contact:?}: {moment}");
            }
        }
    }

    /// Largest marker difference between `a` and `b`.
    fn gap(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(a, b)| (a[0] - b[0]).abs().max((a[1] - b[1]).abs()))
            .fold(0.0, f64::max)
    }

    /// The marker displacements under an oblique probe `force` on the
    /// front face: linear, to second order, to third order, and the
    /// neo-Hookean equilibrium solved by Newton's method.
    fn four_answers(body: &Body<2>, force: [f64; 2]) -> [Vec<[f64; 2]>; 4] {
        let moduli = vec![MODULUS; body.centroids.len()];
        let factorized = body
            .factorized(&moduli, POISSON, SupportSpec::default())
            .unwrap();
        let locator = body.locator();
        let contact = [0.0375, 0.0];
        let [gx, gy, _] = body
            .probe_responses(&locator, &factorized, contact, WIDTH)
            .unwrap();
        let series = body
            .probe_series(&locator, &factorized, contact, WIDTH)
            .unwrap();
        let [fx, fy] = force;
        let linear: Vec<[f64; 2]> = (0..gx.len())
            .map(|m| [0, 1].map(|i| fx * gx[m][i] + fy * gy[m][i]))
            .collect();
        // The second order alone: the series without its cubic terms.
        let quadratic = ProbeSeries {
            cubic: series.cubic.clone().map(|c| vec![[0.0; 2]; c.len()]),
            ..series.clone()
        };
        let plus = |terms: &ProbeSeries| -> Vec<[f64; 2]> {
            let [value, _, _] = terms.at(force);
            linear
                .iter()
                .zip(value)
                .map(|(a, b)| [a[0] + b[0], a[1] + b[1]])
                .collect()
        };
        let (second, third) = (plus(&quadratic), plus(&series));
        // The full Newton solve on the same mesh, loads and constraints.
        let mut loads = vec![0.0; body.mesh.dof_count()];
        for axis in 0..2 {
            let unit = body
                .unit_probe_load(&locator, contact, WIDTH, axis)
                .unwrap();
            for (l, u) in loads.iter_mut().zip(unit) {
                *l += force[axis] * u;
            }
        }
        let materials = Materials(
            moduli
                .iter()
                .enumerate()
                .map(|(e, &m)| Material::for_region(e, m, POISSON).unwrap())
                .collect(),
        );
        let problem = HyperelasticProblem::new(body.rigid.clone()).unwrap();
        let solved = problem
            .solve_newton(&materials, &loads, None, &NonlinearOptions::default())
            .unwrap();
        let exact = body.markers(&solved.displacement, 1.0);
        [linear, second, third, exact]
    }

    #[test]
    fn each_term_of_the_series_gains_one_order_in_the_load() {
        let body = plane_body();
        // Oblique so that the mixed coefficients matter; 0.2 N on the 3 mm
        // patch strains the tissue under it by tens of percent.
        let mut errors = Vec::new();
        for load in [0.2, 0.1, 0.05] {
            let [linear, second, third, exact] = four_answers(&body, [0.4 * load, load]);
            let error = [
                gap(&linear, &exact),
                gap(&second, &exact),
                gap(&third, &exact),
            ];
            eprintln!("{load} N: linear, second and third order off by {error:?} m");
            errors.push(error);
        }
        for pair in errors.windows(2) {
            // Halving the load divides the error of the series truncated
            // after order n by 2^(n + 1).
            for (order, expected) in [(0, 4.0), (1, 8.0), (2, 16.0)] {
                let ratio = pair[0][order] / pair[1][order];
                assert!(
                    (ratio / expected - 1.0).abs() < 0.12,
                    "order {}: ratio {ratio}",
                    order + 1
                );
            }
        }
        // At the largest load each term removes most of the error left.
        let [linear, second, third] = errors[0];
        assert!(second < 0.1 * linear && third < 0.2 * second, "{errors:?}");
    }
}
