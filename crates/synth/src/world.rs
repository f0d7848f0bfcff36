//! The truth world of one scenario: the meshed phantom, its supports and
//! springs, its material on any day, and the solver of its response.
//!
//! The linear stiffness is linear in the moduli: $K(cE) = c\,K(E)$ for a
//! uniform factor $c$, so $u = K(cE)^{-1} f = c^{-1} K(E)^{-1} f$. Every day
//! whose moduli are a uniform multiple of the day-0 moduli (stiffening over
//! days) therefore shares one factorisation, made on first use, and scales
//! its solutions by $1/c$. Springs (compliant support, platform) do not
//! scale with $E$; with them each day is factorised on its own.

use std::sync::{Arc, Mutex};

use needle_fem::material::Materials;

use crate::body::{Body, Location};
use crate::effect::material_nonlinearity::NeoHookean;
use crate::error::SynthError;
use crate::probe_mesh::pressed_apart;
use crate::scenario::{ProbeTrial, Scenario};
use crate::slab_mesh::{MaterialPaths, Span};
use crate::system::{Factorised, Stiffness};

/// The phantom of a scenario, meshed, with everything that does not depend
/// on the trial.
pub(crate) struct World<'s> {
    /// The scenario.
    pub scenario: &'s Scenario,
    /// The mesh.
    pub body: Body,
    /// Components held fixed by the supports (the back face unless the
    /// support is compliant).
    pub fixed: Vec<bool>,
    /// Spring triplets of the compliant support and the platform.
    pub springs: Vec<(usize, usize, f64)>,
    /// Marker rest positions on the marker face.
    pub markers: Vec<[f64; 2]>,
    /// Where each marker lies in the mesh.
    pub marker_locations: Vec<Location>,
    /// The day-0 linear system with the supports held, once made.
    reference: Mutex<Option<Arc<LinearSystem>>>,
}

/// The lines in x at which a probe's contact can end, graded like a
/// singular line in plane strain (`grid`): a flat punch's two edges
/// (its nodes under the face are held, and only they); for a rounded
/// probe, lines a quarter of its radius apart over twice its width,
/// $|x - x_p| \le 2a$. Under a frictionless probe the face slides
/// sideways as the probe goes in (under the first probe of
/// `material-nonlinearity.ron`, 0.54 mm at 1 mm deep, and the marker under
/// its centre 1.76 mm at 4 mm), so where the
/// contact ends moves, in the phantom's rest coordinates, across the
/// footprint and beyond it. Graded at the punch's edges alone, or over
/// its rounded edges' bands $a - r \le |x - x_p| \le a$ alone, the
/// contact ended in coarser elements and refinement 6 and 12 differed by
/// 14 and 10 um at 1 mm deep; graded over the footprint, by 0.10 um
/// (`docs/truth-world.md`, session 46).
fn edge_lines(probe: &ProbeTrial) -> Vec<f64> {
    let a = probe.width / 2.0;
    let mut lines = vec![probe.x - a, probe.x + a];
    if let Some(r) = probe.edge_radius {
        let spacing = r / 4.0;
        let count = (4.0 * a / spacing).round() as usize;
        lines.extend((0..=count).map(|j| probe.x - 2.0 * a + spacing * j as f64));
    }
    lines
}

impl<'s> World<'s> {
    /// Meshes the phantom with grid lines on the needle lines, the probe
    /// centres and edges and the layer boundaries (graded towards the
    /// probe edges in plane strain), and sets up its supports. Rounded
    /// probes pressed on meshes of their own (`probe_mesh::pressed_apart`)
    /// add no lines. A slab is solved as its upper half unless the
    /// platform's foundation under its bottom face breaks the symmetry.
    pub fn new(scenario: &'s Scenario) -> Result<Self, SynthError> {
        Self::covering(scenario, Self::span(scenario))
    }

    /// [`World::new`] with the slab's mesh covering `span` of it (the
    /// upper half is the whole's solution only for a symmetric scenario:
    /// without `platform_friction`).
    pub fn covering(scenario: &'s Scenario, span: Span) -> Result<Self, SynthError> {
        Self::build(scenario, span, None)
    }

    /// [`World::new`] with a locally refined slab (`SlabGrading::local`)
    /// refined towards the needles' material `paths`, found on another
    /// mesh, instead of their lines.
    pub fn along(scenario: &'s Scenario, paths: &MaterialPaths) -> Result<Self, SynthError> {
        Self::build(scenario, Self::span(scenario), Some(paths))
    }

    fn span(scenario: &Scenario) -> Span {
        match scenario.effects.platform_friction {
            Some(_) => Span::Whole,
            None => Span::UpperHalf,
        }
    }

    fn build(
        scenario: &'s Scenario,
        span: Span,
        paths: Option<&MaterialPaths>,
    ) -> Result<Self, SynthError> {
        let p = &scenario.phantom;
        let probes: Vec<&ProbeTrial> = scenario
            .probes
            .iter()
            .filter(|probe| !pressed_apart(scenario, probe))
            .collect();
        let edges: Vec<f64> = probes.iter().flat_map(|probe| edge_lines(probe)).collect();
        let mut x_lines: Vec<f64> = scenario.needles.plan().iter().map(|n| n.line).collect();
        x_lines.extend(probes.iter().map(|probe| probe.x));
        x_lines.extend(&edges);
        let layers = scenario.effects.layered_stiffness.clone();
        let y_lines = layers
            .as_ref()
            .map(|l| l.boundaries.clone())
            .unwrap_or_default();
        let body = Body::build(scenario, span, paths, &x_lines, &edges, &y_lines, |y| {
            layers.as_ref().map_or(0, |l| l.layer_of(y))
        })?;
        let tol = 1e-9 * p.depth;
        let mut fixed = vec![false; body.dof_count()];
        let mut springs = Vec::new();
        let on_back = |x: [f64; 3]| (x[1] - p.depth).abs() < tol;
        match &scenario.effects.compliant_support {
            Some(support) => springs.extend(support.springs(&body, on_back)),
            None => {
                for n in body.nodes_where(on_back) {
                    for c in 0..body.dim {
                        fixed[n * body.dim + c] = true;
                    }
                }
            }
        }
        if body.upper_half {
            // The symmetry plane: u_z = 0 on the mid-plane.
            let on_mid_plane = |x: [f64; 3]| x[2].abs() < 1e-9 * p.thickness;
            for n in body.nodes_where(on_mid_plane) {
                fixed[n * body.dim + 2] = true;
            }
        }
        if let Some(platform) = &scenario.effects.platform_friction {
            springs.extend(platform.springs(&body));
        }
        let (nx, ny) = p.markers;
        let markers: Vec<[f64; 2]> = (0..ny)
            .flat_map(|j| {
                (0..nx).map(move |i| {
                    [
                        p.width * i as f64 / (nx - 1) as f64,
                        p.depth * j as f64 / (ny - 1) as f64,
                    ]
                })
            })
            .collect();
        let z = body.marker_z();
        let marker_locations = markers
            .iter()
            .map(|m| {
                body.locate([m[0], m[1], z])
                    .expect("markers span the phantom, which the mesh covers")
            })
            .collect();
        Ok(Self {
            scenario,
            body,
            fixed,
            springs,
            markers,
            marker_locations,
            reference: Mutex::new(None),
        })
    }

    /// Young's modulus of every region (layer) on `day` (Pa).
    pub fn moduli(&self, day: f64) -> Vec<f64> {
        let e = &self.scenario.effects;
        let factor = e.material_stiffening.map_or(1.0, |s| s.factor(day));
        match &e.layered_stiffness {
            Some(layers) => layers.moduli.iter().map(|m| m * factor).collect(),
            None => vec![self.scenario.phantom.youngs_modulus * factor],
        }
    }

    /// The response of the phantom on `day` with the supports held.
    pub fn response(&self, day: f64) -> Result<Response, SynthError> {
        if self.scenario.effects.material_nonlinearity.is_some() {
            return Ok(Response::NeoHookean(Box::new(self.neo_hookean(
                day,
                &[],
                &[],
            )?)));
        }
        let moduli = self.moduli(day);
        if !self.springs.is_empty() {
            let system = self.linear_system(&moduli, &format!("the phantom on day {day}"))?;
            return Ok(Response::Linear {
                system: Arc::new(system),
                scale: 1.0,
            });
        }
        let base = self.moduli(0.0);
        let scale = moduli[0] / base[0];
        let uniform = moduli
            .iter()
            .zip(&base)
            .all(|(m, b)| (m - scale * b).abs() <= 1e-12 * m.abs());
        if !uniform {
            let system = self.linear_system(&moduli, &format!("the phantom on day {day}"))?;
            return Ok(Response::Linear {
                system: Arc::new(system),
                scale: 1.0,
            });
        }
        let mut reference = self.reference.lock().expect("no panic while factorising");
        let system = match &*reference {
            Some(system) => Arc::clone(system),
            None => {
                let system = Arc::new(self.linear_system(&base, "the phantom on day 0")?);
                *reference = Some(Arc::clone(&system));
                system
            }
        };
        Ok(Response::Linear { system, scale })
    }

    /// The neo-Hookean phantom on `day`, with `extra_held` components held
    /// besides the supports (a flat probe's face), and `contact_nodes` that
    /// a rounded probe may touch.
    pub fn neo_hookean(
        &self,
        day: f64,
        extra_held: &[usize],
        contact_nodes: &[usize],
    ) -> Result<NeoHookean, SynthError> {
        let nu = self.scenario.phantom.poisson_ratio;
        let pairs: Vec<(f64, f64)> = self.moduli(day).into_iter().map(|e| (e, nu)).collect();
        let mut held = self.fixed.clone();
        for &d in extra_held {
            held[d] = true;
        }
        NeoHookean::new(&self.body, &pairs, &self.springs, held, contact_nodes)
    }

    /// The linear phantom on `day` with the components `pressed` held at
    /// `value` besides the supports, factorised for this load alone: its
    /// displacement and the reactions $K u$ (nonzero only on held
    /// components).
    pub fn press_linear(
        &self,
        day: f64,
        pressed: &[usize],
        value: f64,
        what: &str,
    ) -> Result<(Vec<f64>, Vec<f64>), SynthError> {
        let stiffness = self.stiffness(&self.moduli(day))?;
        let mut held = self.fixed.clone();
        let mut prescribed = vec![0.0; held.len()];
        for &d in pressed {
            held[d] = true;
            prescribed[d] = value;
        }
        let factorised = Factorised::new(&stiffness, &held, what)?;
        let u = factorised.solve_prescribed(&stiffness, &prescribed);
        let reactions = stiffness.multiply(&u);
        Ok((u, reactions))
    }

    /// The linear stiffness with `moduli` per region, factorised with the
    /// supports held.
    fn linear_system(&self, moduli: &[f64], what: &str) -> Result<LinearSystem, SynthError> {
        let stiffness = self.stiffness(moduli)?;
        let factorised = Factorised::new(&stiffness, &self.fixed, what)?;
        Ok(LinearSystem {
            stiffness,
            factorised,
        })
    }

    /// The linear stiffness with `moduli` per region and the springs.
    fn stiffness(&self, moduli: &[f64]) -> Result<Stiffness, SynthError> {
        let nu = self.scenario.phantom.poisson_ratio;
        let pairs: Vec<(f64, f64)> = moduli.iter().map(|&e| (e, nu)).collect();
        let materials = Materials::from_parameters(&pairs)?;
        Stiffness::new(&self.body.stiffness(&materials)?, &self.springs)
    }

    /// Displacement of every marker (x, y, z; z is zero in plane strain).
    pub fn marker_displacements(&self, u: &[f64]) -> Vec<[f64; 3]> {
        self.marker_locations
            .iter()
            .map(|at| self.body.value(at, u))
            .collect()
    }
}

/// A linear stiffness and its free block, factorised.
pub(crate) struct LinearSystem {
    stiffness: Stiffness,
    factorised: Factorised,
}

/// How the phantom answers loads on one day (supports held).
pub(crate) enum Response {
    /// Linear elasticity: a factorisation, possibly shared with other days,
    /// whose stiffness is this day's divided by `scale`.
    Linear {
        /// The (shared) system.
        system: Arc<LinearSystem>,
        /// This day's stiffness over the system's.
        scale: f64,
    },
    /// Neo-Hookean material solved by Newton iteration.
    NeoHookean(Box<NeoHookean>),
}

impl Response {
    /// Whether the response is linear (a factorisation: loads superpose).
    pub fn is_linear(&self) -> bool {
        matches!(self, Response::Linear { .. })
    }

    /// Displacements for several load vectors (entries on held components
    /// are ignored; they stay at zero); `start` are initial guesses for the
    /// nonlinear solve (ignored by the linear one).
    pub fn solve(
        &self,
        body: &Body,
        loads: &[Vec<f64>],
        start: &[Vec<f64>],
    ) -> Result<Vec<Vec<f64>>, SynthError> {
        let jobs: Vec<(&Response, &[f64], &[f64])> = loads
            .iter()
            .enumerate()
            .map(|(i, f)| (self, f.as_slice(), start.get(i).map_or(&[][..], |s| s)))
            .collect();
        solve_each(body, &jobs)
    }

    /// Reaction forces $r = f_{int}(u)$ (full vector): what the supports
    /// and prescribed components exert, where no external load acts.
    pub fn internal_forces(&self, body: &Body, u: &[f64]) -> Vec<f64> {
        match self {
            Response::Linear { system, scale } => system
                .stiffness
                .multiply(u)
                .into_iter()
                .map(|r| scale * r)
                .collect(),
            Response::NeoHookean(solver) => solver.internal_forces(body, u),
        }
    }
}

/// Solves each job `(response, load, start)`; the linear jobs whose
/// responses share a factorisation are solved together, as one
/// back-substitution with several right-hand sides, and each solution is
/// divided by its own response's scale.
fn solve_each(
    body: &Body,
    jobs: &[(&Response, &[f64], &[f64])],
) -> Result<Vec<Vec<f64>>, SynthError> {
    let mut solutions: Vec<Vec<f64>> = vec![Vec::new(); jobs.len()];
    let mut groups: Vec<(&Arc<LinearSystem>, Vec<usize>)> = Vec::new();
    for (i, (response, load, start)) in jobs.iter().enumerate() {
        match response {
            Response::Linear { system, .. } => {
                match groups.iter_mut().find(|g| Arc::ptr_eq(g.0, system)) {
                    Some(group) => group.1.push(i),
                    None => groups.push((system, vec![i])),
                }
            }
            Response::NeoHookean(solver) => {
                let zero = vec![0.0; load.len()];
                let start = if start.is_empty() { &zero[..] } else { start };
                solutions[i] = solver.solve(body, load, start, &[])?
            }
        }
    }
    for (system, members) in groups {
        let loads: Vec<&[f64]> = members.iter().map(|&i| jobs[i].1).collect();
        for (&i, mut u) in members.iter().zip(system.factorised.solve(&loads)) {
            if let Response::Linear { scale, .. } = jobs[i].0 {
                u.iter_mut().for_each(|v| *v /= scale);
            }
            solutions[i] = u;
        }
    }
    Ok(solutions)
}
