//! The truth world of one scenario: the meshed phantom, its supports and
//! springs, its material on any day, and the solver of its response.

use needle_fem::material::Materials;

use crate::body::{Body, Location};
use crate::effect::material_nonlinearity::NeoHookean;
use crate::error::SynthError;
use crate::scenario::Scenario;
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
}

impl<'s> World<'s> {
    /// Meshes the phantom with grid lines on the needle lines, the probe
    /// edges and the layer boundaries, and sets up its supports.
    pub fn new(scenario: &'s Scenario) -> Result<Self, SynthError> {
        let p = &scenario.phantom;
        let mut x_lines: Vec<f64> = scenario.needles.plan().iter().map(|n| n.line).collect();
        for probe in &scenario.probes {
            x_lines.extend([
                probe.x - probe.width / 2.0,
                probe.x,
                probe.x + probe.width / 2.0,
            ]);
        }
        let layers = scenario.effects.layered_stiffness.clone();
        let y_lines = layers
            .as_ref()
            .map(|l| l.boundaries.clone())
            .unwrap_or_default();
        let body = Body::build(scenario, &x_lines, &y_lines, |y| {
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

    /// The response of the phantom on `day`, with `extra_held` components
    /// held besides the supports (a probe face).
    pub fn response(&self, day: f64, extra_held: &[usize]) -> Result<Response, SynthError> {
        let nu = self.scenario.phantom.poisson_ratio;
        let pairs: Vec<(f64, f64)> = self.moduli(day).into_iter().map(|e| (e, nu)).collect();
        let mut held = self.fixed.clone();
        for &d in extra_held {
            held[d] = true;
        }
        if self.scenario.effects.material_nonlinearity.is_some() {
            return Ok(Response::NeoHookean(NeoHookean::new(
                &self.body,
                &pairs,
                &self.springs,
                held,
            )?));
        }
        let materials = Materials::from_parameters(&pairs)?;
        let stiffness = Stiffness::new(&self.body.stiffness(&materials)?, &self.springs)?;
        let factorised = Factorised::new(&stiffness, &held, &format!("the phantom on day {day}"))?;
        Ok(Response::Linear {
            stiffness,
            factorised,
        })
    }

    /// Displacement of every marker in the plane (x, y).
    pub fn marker_displacements(&self, u: &[f64]) -> Vec<[f64; 2]> {
        self.marker_locations
            .iter()
            .map(|at| {
                let v = self.body.value(at, u);
                [v[0], v[1]]
            })
            .collect()
    }
}

/// How the phantom answers loads on one day.
pub(crate) enum Response {
    /// Linear elasticity: one factorisation, every load a back-substitution.
    Linear {
        /// Total stiffness.
        stiffness: Stiffness,
        /// Its free block, factorised.
        factorised: Factorised,
    },
    /// Neo-Hookean material solved by Newton iteration.
    NeoHookean(NeoHookean),
}

impl Response {
    /// Displacements for several load vectors; `start` are initial guesses
    /// for the nonlinear solve (ignored by the linear one). Held
    /// components take the values of `prescribed` (zero when empty).
    pub fn solve(
        &self,
        body: &Body,
        loads: &[Vec<f64>],
        start: &[Vec<f64>],
        prescribed: &[f64],
    ) -> Result<Vec<Vec<f64>>, SynthError> {
        match self {
            Response::Linear {
                stiffness,
                factorised,
            } => {
                if prescribed.iter().all(|&v| v == 0.0) {
                    Ok(factorised.solve(loads))
                } else {
                    let base = factorised.solve_prescribed(stiffness, prescribed);
                    let extra = factorised.solve(loads);
                    Ok(extra
                        .into_iter()
                        .map(|u| u.iter().zip(&base).map(|(a, b)| a + b).collect())
                        .collect())
                }
            }
            Response::NeoHookean(solver) => loads
                .iter()
                .zip(start)
                .map(|(f, u0)| solver.solve(body, f, u0, prescribed))
                .collect(),
        }
    }

    /// Reaction forces $r = f_{int}(u)$ (full vector): what the supports
    /// and prescribed components exert, where no external load acts.
    pub fn internal_forces(&self, body: &Body, u: &[f64]) -> Vec<f64> {
        match self {
            Response::Linear { stiffness, .. } => stiffness.multiply(u),
            Response::NeoHookean(solver) => solver.internal_forces(body, u),
        }
    }
}
