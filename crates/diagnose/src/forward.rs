//! The forward model: from a parameter vector to the predicted marker
//! displacements at every frame and the needle base force at every sample.
//!
//! The slab's top face is a plane-strain T6 mesh with a node on every
//! marker (when the markers form a grid), fixed faces from the manifest.
//! Each element has its own material region so that effects can set any
//! modulus field $E_e = E \prod_k f_k(\text{centroid}_e, \text{trial})$.
//! Trials that share a material field and supports share one Cholesky
//! factorisation, kept in a small cache keyed by the exact values, so a
//! finite-difference Jacobian column that changes only a load parameter
//! costs triangular solves and no factorisation. All frames of those trials
//! are solved as one block of right-hand sides.
//!
//! - Probe frame: the measured force $F$ at the tip, $u = F_x g_x + F_y g_y$
//!   with $g$ the responses to unit forces (kept to propagate the force
//!   noise into the marker variance).
//! - Needle frame: a line load of density $q(s)\,\hat d$ from the entry
//!   point to the tip, $q(s) = q_0 + \sum_k \Delta q_k(s)$ (effects).
//! - Needle force sample: $F = \hat d \int_0^L q(s)\,ds$.
//! - Markers: $p = x_\text{rest} + H u$, mapped through every effect's
//!   measurement map, minus $x_\text{rest}$.

use std::sync::{Arc, Mutex};

use needle_fem::load::{add_line_load, add_point_force};
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, LineDensity, LinearProblem, Locator,
    MarkerGrid, Material, Materials, Mesh, RectangleMesh, Support,
};

use crate::effect::{Geometry, ShaftPoint, SupportSpec, TrialContext};
use crate::error::DiagnoseError;
use crate::model::Model;
use crate::observe::{Load, Observations, Shaft};

/// Factorisations kept (one per distinct material field and support).
const CACHE_SIZE: usize = 48;

/// Identity of a factorisation: the exact bits of every element modulus,
/// Poisson's ratio and the supports.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Key(Vec<u64>);

/// What the forward model predicts, in residual order.
pub(crate) struct Prediction {
    pub values: Vec<f64>,
    /// Per marker residual: the variance that the probe force noise adds
    /// (zero for needle frames).
    pub force_variance: Vec<f64>,
}

pub(crate) struct Forward {
    pub geometry: Geometry,
    formulation: Formulation,
    mesh: Mesh<2>,
    element_y: Vec<[f64; 2]>,
    centroids: Vec<[f64; 2]>,
    marker_weights: Vec<Vec<(usize, f64)>>,
    fixed_faces: Vec<Face>,
    rigid: LinearProblem<2>,
    cache: Mutex<Vec<(Key, Arc<LinearProblem<2>>)>>,
}

fn fem_face(face: needle_data::Face) -> Face {
    match face {
        needle_data::Face::Front => Face::Front,
        needle_data::Face::Back => Face::Back,
        needle_data::Face::Left => Face::Left,
        needle_data::Face::Right => Face::Right,
    }
}

/// Distinct values, sorted, merged within `tolerance`.
fn distinct(values: impl Iterator<Item = f64>, tolerance: f64) -> Vec<f64> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v.dedup_by(|a, b| (*a - *b).abs() <= tolerance);
    v
}

impl Forward {
    pub fn new(
        phantom: &needle_data::Phantom,
        rest: &[[f64; 2]],
        refinement: usize,
    ) -> Result<Self, DiagnoseError> {
        let (width, depth) = (phantom.width, phantom.depth);
        let tolerance = 1e-9 * width.max(depth);
        let xs = distinct(rest.iter().map(|p| p[0]), tolerance);
        let ys = distinct(rest.iter().map(|p| p[1]), tolerance);
        let inside = |v: &[f64], extent: f64| v.iter().all(|&x| x > 0.0 && x < extent);
        let plan = if xs.len() * ys.len() == rest.len() && inside(&xs, width) && inside(&ys, depth)
        {
            RectangleMesh::with_markers(width, depth, &MarkerGrid { x: xs, y: ys }, refinement)?
        } else {
            // Markers off a grid: a uniform mesh of about the marker spacing.
            let per_side = ((rest.len() as f64).sqrt().ceil() as usize + 1).max(4);
            RectangleMesh::uniform(width, depth, per_side * refinement, per_side * refinement)?
        };
        let shared = plan.build(ElementKind::Tri6)?;
        let element_count = shared.element_count();
        let mesh = Mesh::new(
            shared.kind(),
            shared.nodes().to_vec(),
            shared.connectivity().to_vec(),
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
        let centroids = (0..element_count).map(|e| mesh.centroid(e)).collect();
        let locator = Locator::new(&mesh);
        let marker_weights = rest
            .iter()
            .enumerate()
            .map(|(index, &p)| {
                locator
                    .weights(p)
                    .ok_or_else(|| needle_fem::FemError::PointOutsideMesh {
                        index,
                        coordinates: p.to_vec(),
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let formulation = Formulation::PlaneStrain {
            thickness: phantom.thickness,
        };
        let fixed_faces: Vec<Face> = phantom.fixed.iter().map(|&f| fem_face(f)).collect();
        let rigid = LinearProblem::new(
            Assembler::new(mesh.clone(), formulation)?,
            vec![],
            Self::fixed_dirichlet(&mesh, &fixed_faces),
        )?;
        let centre = [
            rest.iter().map(|p| p[0]).sum::<f64>() / rest.len().max(1) as f64,
            rest.iter().map(|p| p[1]).sum::<f64>() / rest.len().max(1) as f64,
        ];
        let radius = rest
            .iter()
            .map(|p| ((p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2)).sqrt())
            .fold(0.0, f64::max);
        Ok(Self {
            geometry: Geometry {
                width,
                depth,
                thickness: phantom.thickness,
                image_centre: centre,
                image_radius: if radius > 0.0 { radius } else { 0.5 * width },
            },
            formulation,
            mesh,
            element_y,
            centroids,
            marker_weights,
            fixed_faces,
            rigid,
            cache: Mutex::new(Vec::new()),
        })
    }

    fn fixed_dirichlet(mesh: &Mesh<2>, faces: &[Face]) -> Dirichlet {
        let mut dirichlet = Dirichlet::new();
        for &face in faces {
            for (dof, value) in Dirichlet::fixed_face(mesh, face).iter() {
                // Values are zero and dofs valid: setting cannot fail.
                let _ = dirichlet.set(dof, value);
            }
        }
        dirichlet
    }

    /// The factorised problem for a material field and supports.
    fn factorized(
        &self,
        moduli: &[f64],
        poisson_ratio: f64,
        supports: SupportSpec,
    ) -> Result<Arc<LinearProblem<2>>, DiagnoseError> {
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
            return Ok(Arc::clone(p));
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
            let mut springs = Vec::new();
            let dirichlet = if supports.fixed_face_compliance > 0.0 {
                let k = 1.0 / supports.fixed_face_compliance;
                for &face in &self.fixed_faces {
                    springs.push(Support::Boundary {
                        facets: self.mesh.facets_on_face(face),
                        stiffness: [k, k],
                    });
                }
                Dirichlet::new()
            } else {
                Self::fixed_dirichlet(&self.mesh, &self.fixed_faces)
            };
            if supports.foundation > 0.0 {
                springs.push(Support::Foundation {
                    stiffness: [supports.foundation; 2],
                });
            }
            LinearProblem::new(
                Assembler::new(self.mesh.clone(), self.formulation)?,
                springs,
                dirichlet,
            )?
        };
        problem.factorize(&materials)?;
        let problem = Arc::new(problem);
        let mut cache = self.cache.lock().expect("cache lock");
        if cache.len() >= CACHE_SIZE {
            cache.remove(0);
        }
        cache.push((key, Arc::clone(&problem)));
        Ok(problem)
    }

    /// Element moduli of a trial.
    fn moduli(&self, model: &Model, p: &[f64], trial: &TrialContext) -> Vec<f64> {
        let e0 = model.baseline(p).youngs_modulus;
        (0..self.centroids.len())
            .map(|e| {
                model.effects_with(p).fold(e0, |acc, (effect, own)| {
                    acc * effect.stiffness_factor(own, trial, self.centroids[e], self.element_y[e])
                })
            })
            .collect()
    }

    /// Shaft density $q(s)$ (N/m) of a trial.
    fn density(&self, model: &Model, p: &[f64], trial: &TrialContext, point: ShaftPoint) -> f64 {
        model
            .effects_with(p)
            .fold(model.baseline(p).shaft_density, |acc, (effect, own)| {
                acc + effect.shaft_density(own, trial, point)
            })
    }

    fn breakpoints(&self, model: &Model, p: &[f64], length: f64) -> Vec<f64> {
        let mut out: Vec<f64> = model
            .effects_with(p)
            .flat_map(|(effect, own)| effect.shaft_breakpoints(own, length))
            .filter(|&s| s > 0.0 && s < length)
            .collect();
        out.sort_by(f64::total_cmp);
        out
    }

    /// $\int_0^L q(s)\,ds$ by 5-point Gauss-Legendre on pieces split at the
    /// density's breakpoints.
    fn shaft_force(&self, model: &Model, p: &[f64], trial: &TrialContext, length: f64) -> f64 {
        const NODES: [f64; 5] = [
            0.0,
            -0.538_469_310_105_683_1,
            0.538_469_310_105_683_1,
            -0.906_179_845_938_664,
            0.906_179_845_938_664,
        ];
        const WEIGHTS: [f64; 5] = [
            0.568_888_888_888_888_9,
            0.478_628_670_499_366_5,
            0.478_628_670_499_366_5,
            0.236_926_885_056_189_1,
            0.236_926_885_056_189_1,
        ];
        let mut cuts = vec![0.0];
        cuts.extend(self.breakpoints(model, p, length));
        cuts.push(length);
        let mut total = 0.0;
        for w in cuts.windows(2) {
            let (a, b) = (w[0], w[1]);
            for (x, g) in NODES.iter().zip(WEIGHTS) {
                let s = 0.5 * (a + b) + 0.5 * (b - a) * x;
                total +=
                    0.5 * (b - a) * g * self.density(model, p, trial, ShaftPoint { s, length });
            }
        }
        total
    }

    /// Predicts every observation at parameters `p`.
    pub fn predict(
        &self,
        model: &Model,
        p: &[f64],
        obs: &Observations,
    ) -> Result<Prediction, DiagnoseError> {
        let baseline = model.baseline(p);
        let mut supports = SupportSpec::default();
        for (effect, own) in model.effects_with(p) {
            effect.supports(own, &mut supports);
        }
        let marker_count = obs.marker_count();
        let mut values = vec![0.0; marker_count + obs.force_count()];
        let mut force_variance = vec![0.0; marker_count];
        let mut frame_offset = Vec::with_capacity(obs.frames.len());
        let mut offset = 0;
        for frame in &obs.frames {
            frame_offset.push(offset);
            offset += 2 * frame.markers.len();
        }
        let locator = Locator::new(&self.mesh);
        let dofs = self.mesh.dof_count();
        // Group trials by material field.
        let moduli: Vec<Vec<f64>> = obs
            .trials
            .iter()
            .map(|t| self.moduli(model, p, t))
            .collect();
        let mut done = vec![false; obs.trials.len()];
        for first in 0..obs.trials.len() {
            if done[first] {
                continue;
            }
            let group: Vec<usize> = (first..obs.trials.len())
                .filter(|&t| !done[t] && moduli[t] == moduli[first])
                .collect();
            for &t in &group {
                done[t] = true;
            }
            let frames: Vec<usize> = (0..obs.frames.len())
                .filter(|&f| group.contains(&obs.frames[f].trial))
                .collect();
            if frames.is_empty() {
                continue;
            }
            let problem = self.factorized(&moduli[first], baseline.poisson_ratio, supports)?;
            let mut loads: Vec<Vec<f64>> = Vec::new();
            let mut columns: Vec<(usize, usize)> = Vec::new(); // (first column, count)
            for &f in &frames {
                let frame = &obs.frames[f];
                let start = loads.len();
                match frame.load {
                    Load::Free => {}
                    Load::Probe { tip, .. } => {
                        let point = [
                            tip[0].clamp(0.0, self.geometry.width),
                            tip[1].clamp(0.0, self.geometry.depth),
                        ];
                        for axis in 0..2 {
                            let mut load = vec![0.0; dofs];
                            let mut unit = [0.0; 2];
                            unit[axis] = 1.0;
                            add_point_force(&locator, &mut load, point, unit)?;
                            loads.push(load);
                        }
                    }
                    Load::Needle(shaft) => {
                        loads.push(self.needle_load(
                            model,
                            p,
                            &obs.trials[frame.trial],
                            &shaft,
                            &locator,
                        )?);
                    }
                }
                columns.push((start, loads.len() - start));
            }
            let refs: Vec<&[f64]> = loads.iter().map(|l| l.as_slice()).collect();
            let solutions = if refs.is_empty() {
                Vec::new()
            } else {
                problem.solve_many(&refs)?
            };
            for (k, &f) in frames.iter().enumerate() {
                let frame = &obs.frames[f];
                let (start, count) = columns[k];
                let at = |column: usize, marker: usize| -> [f64; 2] {
                    let u = &solutions[column].displacement;
                    let mut v = [0.0; 2];
                    for &(n, w) in &self.marker_weights[marker] {
                        v[0] += w * u[2 * n];
                        v[1] += w * u[2 * n + 1];
                    }
                    v
                };
                for (j, &(m, _)) in frame.markers.iter().enumerate() {
                    let (u, variance) = match (frame.load, count) {
                        (
                            Load::Probe {
                                force, force_sigma, ..
                            },
                            2,
                        ) => {
                            let gx = at(start, m);
                            let gy = at(start + 1, m);
                            let u = [
                                force[0] * gx[0] + force[1] * gy[0],
                                force[0] * gx[1] + force[1] * gy[1],
                            ];
                            let s2 = force_sigma * force_sigma;
                            (
                                u,
                                [
                                    s2 * (gx[0].powi(2) + gy[0].powi(2)),
                                    s2 * (gx[1].powi(2) + gy[1].powi(2)),
                                ],
                            )
                        }
                        (Load::Needle(_), 1) => (at(start, m), [0.0; 2]),
                        _ => ([0.0; 2], [0.0; 2]),
                    };
                    let rest = obs.rest[m];
                    let mut position = [rest[0] + u[0], rest[1] + u[1]];
                    for (effect, own) in model.effects_with(p) {
                        position = effect.measured_position(own, &self.geometry, position);
                    }
                    let slot = frame_offset[f] + 2 * j;
                    values[slot] = position[0] - rest[0];
                    values[slot + 1] = position[1] - rest[1];
                    force_variance[slot] = variance[0];
                    force_variance[slot + 1] = variance[1];
                }
            }
        }
        for (k, sample) in obs.forces.iter().enumerate() {
            if let Some(shaft) = sample.shaft {
                let total = self.shaft_force(model, p, &obs.trials[sample.trial], shaft.length);
                values[marker_count + 2 * k] = total * shaft.direction[0];
                values[marker_count + 2 * k + 1] = total * shaft.direction[1];
            }
        }
        Ok(Prediction {
            values,
            force_variance,
        })
    }

    fn needle_load(
        &self,
        model: &Model,
        p: &[f64],
        trial: &TrialContext,
        shaft: &Shaft,
        locator: &Locator<'_, 2>,
    ) -> Result<Vec<f64>, DiagnoseError> {
        let length = shaft.length;
        let direction = shaft.direction;
        let density = move |s: f64| -> [f64; 2] {
            let q = self.density(model, p, trial, ShaftPoint { s, length });
            [q * direction[0], q * direction[1]]
        };
        let tip = [
            shaft.entry[0] + length * direction[0],
            shaft.entry[1] + length * direction[1],
        ];
        let mut load = vec![0.0; self.mesh.dof_count()];
        add_line_load(
            locator,
            &mut load,
            shaft.entry,
            tip,
            &LineDensity::Function {
                density: &density,
                breakpoints: self.breakpoints(model, p, length),
            },
        )?;
        Ok(load)
    }
}

#[cfg(test)]
mod tests {
    use needle_data::{BundleBuilder, MarkerRest, Phantom, ToolSample, Trial, TrialKind};

    use super::*;
    use crate::effect::catalog;
    use crate::model::Baseline;
    use crate::spec::ModelSpec;

    /// A small campaign: one probe frame and one needle frame on a 5 x 5
    /// marker grid (positions are irrelevant: only predictions are compared).
    fn observations() -> Observations {
        let mut builder = BundleBuilder::new(
            "tiny",
            Phantom {
                width: 0.075,
                depth: 0.075,
                thickness: 0.0075,
                fixed: vec![needle_data::Face::Back],
            },
        );
        let grid = MarkerGrid::uniform(5, 5, (0.01, 0.01), (0.065, 0.065));
        builder.markers_rest(
            grid.points()
                .iter()
                .enumerate()
                .map(|(id, p)| MarkerRest {
                    id: id as u32,
                    x: p[0],
                    y: p[1],
                })
                .collect(),
        );
        let frame: Vec<(u32, [f64; 2])> = grid
            .points()
            .iter()
            .enumerate()
            .map(|(id, p)| (id as u32, *p))
            .collect();
        for (id, kind, day, tip_y) in [
            ("probe", TrialKind::Probe, 2.0, 0.0),
            ("needle", TrialKind::Needle, 3.0, 0.04),
        ] {
            let trial = builder.trial(Trial {
                id: id.into(),
                kind,
                velocity: 0.005,
                day,
            });
            trial.tool.push(ToolSample {
                t: 0.0,
                tip_x: 0.03,
                tip_y,
                theta: 0.1,
                fx: 0.05,
                fy: 0.2,
                mz: 0.0,
            });
            trial
                .markers_mut()
                .push_frame(0, 0.0, frame.clone())
                .unwrap();
        }
        Observations::from_campaign(&builder.finish(), 1, 0.005).unwrap()
    }

    /// The observations of [`observations`] on the paper's phantom, its
    /// forward model and a baseline start.
    fn paper_forward() -> (Observations, Forward, Baseline) {
        let obs = observations();
        let phantom = Phantom {
            width: 0.075,
            depth: 0.075,
            thickness: 0.0075,
            fixed: vec![needle_data::Face::Back],
        };
        let forward = Forward::new(&phantom, &obs.rest, 1).unwrap();
        let start = Baseline {
            youngs_modulus: 25.0e3,
            poisson_ratio: 0.45,
            shaft_density: 10.0,
        };
        (obs, forward, start)
    }

    #[test]
    fn every_effect_is_silent_at_its_null_and_acts_off_it() {
        let (obs, forward, start) = paper_forward();
        let baseline = Model::new(&ModelSpec::baseline(), &forward.geometry, start).unwrap();
        let p0: Vec<f64> = baseline.parameters.iter().map(|p| p.initial).collect();
        let reference = forward.predict(&baseline, &p0, &obs).unwrap().values;
        assert!(reference.iter().any(|v| v.abs() > 1e-5));
        for effect in catalog() {
            let model = Model::new(
                &ModelSpec::from_ids(&[effect.id()]).unwrap(),
                &forward.geometry,
                start,
            )
            .unwrap();
            let mut p = p0.clone();
            p.extend(model.parameters[p0.len()..].iter().map(|q| q.null));
            let at_null = forward.predict(&model, &p, &obs).unwrap().values;
            for (a, b) in at_null.iter().zip(&reference) {
                assert!(
                    (a - b).abs() <= 1e-12 + 1e-9 * b.abs(),
                    "{}: {a} vs {b}",
                    effect.id()
                );
            }
            for (k, q) in model.parameters.iter().enumerate().skip(p0.len()) {
                if q.tested {
                    p[k] = q.null + 0.5 * q.scale;
                }
            }
            let moved = forward.predict(&model, &p, &obs).unwrap().values;
            let change = moved
                .iter()
                .zip(&reference)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(
                change > 1e-7,
                "{} changes nothing off its null ({change})",
                effect.id()
            );
        }
    }

    #[test]
    fn needle_force_integrates_the_density() {
        let (obs, forward, start) = paper_forward();
        let model = Model::new(
            &ModelSpec::from_ids(&["tip_cutting_force"]).unwrap(),
            &forward.geometry,
            start,
        )
        .unwrap();
        // q0 = 10 N/m, peak 20 N/m over 5 mm: F = 10 L + 20 * 0.005 / 2.
        let p = [25.0e3, 0.45, 10.0, 20.0, 0.005];
        let values = forward.predict(&model, &p, &obs).unwrap().values;
        let m = obs.marker_count();
        let length = 0.04 / 0.1f64.cos();
        let total = 10.0 * length + 0.05;
        assert!((values[m] - total * -(0.1f64.sin())).abs() < 1e-12);
        assert!((values[m + 1] - total * 0.1f64.cos()).abs() < 1e-12);
    }
}
