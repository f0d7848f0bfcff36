//! The "fine 2-D plane-strain truth" for the tests: probing data computed
//! with needle-fem on a mesh several times finer than the model's, solved
//! here independently of the crate's model (the fixed dofs are eliminated
//! and the reduced system is factorised from scratch), with seeded Gaussian
//! marker noise.

#![allow(dead_code)]

use faer::Side;
use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use needle_data::{
    BundleBuilder, MarkerRest, Noise, Phantom, ToolSample, Trial, TrialKind, WriteOptions,
};
use needle_fem::assemble::Assembler;
use needle_fem::element::ElementKind;
use needle_fem::load::add_point_force;
use needle_fem::locate::Locator;
use needle_fem::material::{Formulation, Materials};
use needle_fem::mesh::{Face, MarkerGrid, RectangleMesh};
use needle_identify::{
    IdentifyOptions, MarkerDisplacement, ProbeData, ProbeFrame, ProbeLoad, ProbeSetup, ProbeTrial,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The default options with the paper's point-force probe, the model that
/// matches this truth (whose probe is a point force).
pub fn point_force() -> IdentifyOptions {
    IdentifyOptions {
        probe: ProbeLoad::Point,
        ..IdentifyOptions::default()
    }
}

/// A probing campaign on the default phantom geometry.
#[derive(Debug, Clone)]
pub struct Scenario {
    pub width: f64,
    pub depth: f64,
    pub thickness: f64,
    /// Markers per side (a full grid from edge to edge).
    pub markers_per_side: usize,
    /// Probe sites: x positions on the front face.
    pub sites: Vec<f64>,
    /// Peak probe force along +y (N); frames ramp up to it.
    pub peak_force: f64,
    /// Lateral force as a fraction of the axial one.
    pub lateral_fraction: f64,
    pub frames_per_trial: usize,
    /// Truth mesh lines per marker spacing.
    pub truth_refinement: usize,
    pub truth_element: ElementKind,
    /// (E, nu) per region of the truth; layers split at `layers` in y.
    pub youngs_modulus: f64,
    pub poisson_ratio: f64,
    pub layers: Vec<(f64, f64)>,
    /// Modulus of trial k is `youngs_modulus * (1 + drift_per_day * day_k)`.
    pub days: Vec<f64>,
    pub drift_per_day: f64,
    pub fixed: Vec<Face>,
}

impl Scenario {
    /// The test-sized but representative default: 21 x 21 markers on
    /// 75 x 75 mm, E = 25.3 kPa, nu = 0.48, 4 probe sites on the front face,
    /// back face fixed, a truth T6 mesh 3x finer than the marker grid.
    pub fn paper() -> Self {
        Self {
            width: 0.075,
            depth: 0.075,
            thickness: 0.0075,
            markers_per_side: 21,
            sites: vec![0.0175, 0.0310, 0.0440, 0.0580],
            peak_force: 0.25,
            lateral_fraction: 0.1,
            frames_per_trial: 4,
            truth_refinement: 3,
            truth_element: ElementKind::Tri6,
            youngs_modulus: 25.3e3,
            poisson_ratio: 0.48,
            layers: Vec::new(),
            days: vec![0.0, 0.0, 0.0, 0.0],
            drift_per_day: 0.0,
            fixed: vec![Face::Back],
        }
    }

    pub fn grid(&self) -> MarkerGrid {
        MarkerGrid::uniform(
            self.markers_per_side,
            self.markers_per_side,
            (0.0, 0.0),
            (self.width, self.depth),
        )
    }

    /// Noise-free marker displacements per unit force along x and y at each
    /// site, `[site][axis]` of interleaved marker displacements.
    pub fn unit_responses(&self) -> Vec<[Vec<f64>; 2]> {
        let grid = self.grid();
        let plan =
            RectangleMesh::with_markers(self.width, self.depth, &grid, self.truth_refinement)
                .unwrap();
        let mut plan = plan;
        for &(y, _) in &self.layers {
            if plan.y_lines.iter().all(|&l| (l - y).abs() > 1e-12) {
                plan.y_lines.push(y);
            }
        }
        plan.y_lines.sort_by(f64::total_cmp);
        let mut mesh = plan.build(self.truth_element).unwrap();
        let layers = self.layers.clone();
        mesh.assign_regions(|c| layers.iter().filter(|&&(y, _)| c[1] >= y).count());
        let mut parameters = vec![(self.youngs_modulus, self.poisson_ratio)];
        parameters.extend(self.layers.iter().map(|&(_, e)| (e, self.poisson_ratio)));
        let materials = Materials::from_parameters(&parameters).unwrap();
        let formulation = Formulation::PlaneStrain {
            thickness: self.thickness,
        };
        let assembler = Assembler::new(mesh.clone(), formulation).unwrap();
        let k = assembler.stiffness(&materials).unwrap();
        let dofs = mesh.dof_count();
        let mut fixed = vec![false; dofs];
        for &face in &self.fixed {
            for n in mesh.nodes_on_face(face) {
                fixed[2 * n] = true;
                fixed[2 * n + 1] = true;
            }
        }
        let mut free_index = vec![usize::MAX; dofs];
        let mut free = 0;
        for i in 0..dofs {
            if !fixed[i] {
                free_index[i] = free;
                free += 1;
            }
        }
        let symbolic = k.symbolic();
        let mut triplets = Vec::new();
        for j in 0..dofs {
            for p in symbolic.col_ptr()[j]..symbolic.col_ptr()[j + 1] {
                let i = symbolic.row_idx()[p];
                if !fixed[i] && !fixed[j] {
                    triplets.push(Triplet::new(free_index[i], free_index[j], k.val()[p]));
                }
            }
        }
        let reduced =
            SparseColMat::<usize, f64>::try_new_from_triplets(free, free, &triplets).unwrap();
        let llt = reduced.sp_cholesky(Side::Lower).unwrap();
        let locator = Locator::new(&mesh);
        let marker_weights: Vec<_> = grid
            .points()
            .iter()
            .map(|&p| locator.weights(p).unwrap())
            .collect();
        self.sites
            .iter()
            .map(|&x| {
                let mut out: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
                for (c, slot) in out.iter_mut().enumerate() {
                    let mut force = [0.0; 2];
                    force[c] = 1.0;
                    let mut load = vec![0.0; dofs];
                    add_point_force(&locator, &mut load, [x, 0.0], force).unwrap();
                    let mut rhs = faer::Mat::<f64>::from_fn(free, 1, |_, _| 0.0);
                    for i in 0..dofs {
                        if !fixed[i] {
                            rhs[(free_index[i], 0)] = load[i];
                        }
                    }
                    llt.solve_in_place(rhs.as_mut());
                    let u = |i: usize| {
                        if fixed[i] {
                            0.0
                        } else {
                            rhs[(free_index[i], 0)]
                        }
                    };
                    *slot = marker_weights
                        .iter()
                        .flat_map(|w| {
                            let ux: f64 = w.iter().map(|&(n, a)| a * u(2 * n)).sum();
                            let uy: f64 = w.iter().map(|&(n, a)| a * u(2 * n + 1)).sum();
                            [ux, uy]
                        })
                        .collect();
                }
                out
            })
            .collect()
    }

    /// The force of frame `k` (1-based ramp) of a trial.
    pub fn force(&self, k: usize) -> [f64; 2] {
        let fy = self.peak_force * k as f64 / self.frames_per_trial as f64;
        [self.lateral_fraction * fy, fy]
    }

    /// Probing data with marker noise `sigma` (m) drawn from `seed`.
    pub fn probe_data(&self, sigma: f64, seed: u64) -> ProbeData {
        let responses = self.unit_responses();
        let markers = self.grid().points();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        let mut frames = Vec::new();
        let mut trials = Vec::new();
        for (t, (&x, response)) in self.sites.iter().zip(&responses).enumerate() {
            let day = self.days[t];
            let compliance = 1.0 / (1.0 + self.drift_per_day * day);
            trials.push(ProbeTrial {
                id: format!("probe-{:02}", t + 1),
                day,
            });
            for k in 1..=self.frames_per_trial {
                let f = self.force(k);
                let displacements = (0..markers.len())
                    .map(|m| {
                        let mut d = [0.0; 2];
                        for c in 0..2 {
                            let clean = compliance
                                * (f[0] * response[0][2 * m + c] + f[1] * response[1][2 * m + c]);
                            d[c] = clean
                                + if sigma > 0.0 {
                                    noise.sample(&mut rng)
                                } else {
                                    0.0
                                };
                        }
                        MarkerDisplacement {
                            marker: m,
                            displacement: d,
                            sigma: None,
                        }
                    })
                    .collect();
                frames.push(ProbeFrame {
                    trial: t,
                    t: k as f64,
                    tip: [x, 0.001 * k as f64],
                    force: f,
                    displacements,
                });
            }
        }
        ProbeData {
            setup: ProbeSetup {
                width: self.width,
                depth: self.depth,
                thickness: self.thickness,
                fixed: self.fixed.clone(),
                markers,
            },
            trials,
            frames,
            marker_sigma: (sigma > 0.0).then_some(sigma),
        }
    }

    /// Writes `data` as a measurement bundle: per trial a tool.csv sampled at
    /// twice the camera rate (the frames fall between samples, so the force
    /// at a frame is interpolated) and a markers.csv with a rest frame.
    pub fn write_bundle(&self, data: &ProbeData, path: &std::path::Path) {
        let phantom = Phantom {
            width: self.width,
            depth: self.depth,
            thickness: self.thickness,
            fixed: self
                .fixed
                .iter()
                .map(|f| match f {
                    Face::Front => needle_data::Face::Front,
                    Face::Back => needle_data::Face::Back,
                    Face::Left => needle_data::Face::Left,
                    _ => needle_data::Face::Right,
                })
                .collect(),
        };
        let mut builder = BundleBuilder::new("identify-test", phantom);
        if let Some(sigma) = data.marker_sigma {
            builder.noise(Noise {
                marker_sigma: sigma,
                force_sigma: 1e-3,
            });
        }
        let rest: Vec<MarkerRest> = data
            .setup
            .markers
            .iter()
            .enumerate()
            .map(|(i, p)| MarkerRest {
                id: i as u32,
                x: p[0],
                y: p[1],
            })
            .collect();
        builder.markers_rest(rest.clone());
        for (t, trial) in data.trials.iter().enumerate() {
            let frames: Vec<&ProbeFrame> = data.frames.iter().filter(|f| f.trial == t).collect();
            let entry = builder.trial(Trial {
                id: trial.id.clone(),
                kind: TrialKind::Probe,
                velocity: 0.001,
                day: trial.day,
            });
            // Samples at t = 0, 0.5, 1, ... linear in time between frames, so
            // interpolation at the frame times recovers the frame forces.
            let last = frames.len() as f64;
            let mut s = 0.0;
            while s <= last + 1e-9 {
                let (force, tip) = if s < 1.0 {
                    let f = frames[0];
                    ([f.force[0] * s, f.force[1] * s], [f.tip[0], f.tip[1] * s])
                } else {
                    let a = frames[(s.floor() as usize - 1).min(frames.len() - 1)];
                    let b = frames[(s.ceil() as usize - 1).min(frames.len() - 1)];
                    let w = s - s.floor();
                    (
                        [
                            a.force[0] + w * (b.force[0] - a.force[0]),
                            a.force[1] + w * (b.force[1] - a.force[1]),
                        ],
                        [
                            a.tip[0] + w * (b.tip[0] - a.tip[0]),
                            a.tip[1] + w * (b.tip[1] - a.tip[1]),
                        ],
                    )
                };
                entry.tool.push(ToolSample {
                    t: s,
                    tip_x: tip[0],
                    tip_y: tip[1],
                    theta: 0.0,
                    fx: force[0],
                    fy: force[1],
                    mz: 0.0,
                });
                s += 0.5;
            }
            let track = entry.markers_mut();
            track
                .push_frame(0, 0.0, rest.iter().map(|m| (m.id, [m.x, m.y])))
                .unwrap();
            for (k, frame) in frames.iter().enumerate() {
                track
                    .push_frame(
                        k as u64 + 1,
                        frame.t,
                        frame.displacements.iter().map(|d| {
                            let r = data.setup.markers[d.marker];
                            (
                                d.marker as u32,
                                [r[0] + d.displacement[0], r[1] + d.displacement[1]],
                            )
                        }),
                    )
                    .unwrap();
            }
        }
        builder.write(path, WriteOptions::default()).unwrap();
    }
}
