//! A small truth world for the diagnosis tests, independent of the crate's
//! forward model and effect files: its own T6 mesh, solves and loads, the
//! hidden effects written here from their physics, and bundles written with
//! needle-data's `BundleBuilder` with seeded Gaussian noise.
//!
//! The truth mesh has the model's default refinement (3). A finer truth
//! (refinement 4) was tried: its difference from the model's mesh is itself
//! detectable at 8 um marker noise (marker chi2/dof 1.06-1.27 after the
//! right effect is added), and per-trial effects (stiffening, velocity
//! friction) then absorb it as significant false positives.

use std::path::{Path, PathBuf};

use needle_data::{
    BundleBuilder, Face as DataFace, MarkerRest, Noise, Phantom, ToolSample, Trial, TrialKind,
    WriteOptions,
};
use needle_fem::load::{add_line_load, add_point_force};
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, LineDensity, LinearProblem, Locator,
    MarkerGrid, Material, Materials, Mesh, RectangleMesh, Support,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

pub const WIDTH: f64 = 0.075;
pub const DEPTH: f64 = 0.075;
pub const THICKNESS: f64 = 0.0075;
pub const MARKER_SIGMA: f64 = 8.0e-6;
pub const FORCE_SIGMA: f64 = 5.0e-3;

/// The hidden physics of a truth world.
#[derive(Debug, Clone, Copy, Default)]
pub struct Hidden {
    /// Tip peak amplitude (N/m), triangular over `TIP_WIDTH` behind the tip.
    pub tip_peak: f64,
    /// Relative growth of E per day.
    pub stiffening: f64,
    /// Spring stiffness per unit area of the back face (N/m³); 0 = rigid.
    pub back_springs: f64,
}

const TIP_WIDTH: f64 = 0.005;
/// Elements per marker spacing of the truth mesh (see the module doc).
const TRUTH_REFINEMENT: usize = 3;
const YOUNGS: f64 = 25.0e3;
const POISSON: f64 = 0.45;
const SHAFT_DENSITY: f64 = 10.0;

struct Truth {
    mesh: Mesh<2>,
    formulation: Formulation,
    hidden: Hidden,
}

impl Truth {
    fn new(markers: &MarkerGrid, hidden: Hidden) -> Self {
        let mesh = RectangleMesh::with_markers(WIDTH, DEPTH, markers, TRUTH_REFINEMENT)
            .unwrap()
            .build(ElementKind::Tri6)
            .unwrap();
        Self {
            mesh,
            formulation: Formulation::PlaneStrain {
                thickness: THICKNESS,
            },
            hidden,
        }
    }

    fn problem(&self, day: f64) -> LinearProblem<2> {
        let assembler = Assembler::new(self.mesh.clone(), self.formulation).unwrap();
        let (supports, dirichlet) = if self.hidden.back_springs > 0.0 {
            let k = self.hidden.back_springs;
            (
                vec![Support::Boundary {
                    facets: self.mesh.facets_on_face(Face::Back),
                    stiffness: [k, k],
                }],
                Dirichlet::new(),
            )
        } else {
            (vec![], Dirichlet::fixed_face(&self.mesh, Face::Back))
        };
        let mut problem = LinearProblem::new(assembler, supports, dirichlet).unwrap();
        let e = YOUNGS * (1.0 + self.hidden.stiffening * day);
        problem
            .factorize(&Materials::homogeneous(Material::new(e, POISSON).unwrap()))
            .unwrap();
        problem
    }

    /// Shaft density at arclength `s` of a needle inserted by `length`.
    fn density(&self, s: f64, length: f64) -> f64 {
        let behind = length - s;
        let peak = if behind < TIP_WIDTH {
            self.hidden.tip_peak * (TIP_WIDTH - behind) / TIP_WIDTH
        } else {
            0.0
        };
        SHAFT_DENSITY + peak
    }

    fn needle_force(&self, length: f64) -> f64 {
        let peak_length = length.min(TIP_WIDTH);
        // Area of the part of the triangle inside the slab.
        let peak =
            self.hidden.tip_peak * (peak_length - 0.5 * peak_length * peak_length / TIP_WIDTH);
        SHAFT_DENSITY * length + peak
    }
}

fn marker_grid() -> MarkerGrid {
    MarkerGrid::uniform(7, 7, (0.0075, 0.0075), (0.0675, 0.0675))
}

/// Writes a bundle with `hidden` effects and noise drawn from `seed` into
/// `dir/name` and returns its path.
pub fn make_bundle(dir: &Path, name: &str, hidden: Hidden, seed: u64) -> PathBuf {
    let grid = marker_grid();
    let points = grid.points();
    let truth = Truth::new(&grid, hidden);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let marker_noise = Normal::new(0.0, MARKER_SIGMA).unwrap();
    let force_noise = Normal::new(0.0, FORCE_SIGMA).unwrap();
    let mut builder = BundleBuilder::new(
        name,
        Phantom {
            width: WIDTH,
            depth: DEPTH,
            thickness: THICKNESS,
            fixed: vec![DataFace::Back],
        },
    );
    builder.noise(Noise {
        marker_sigma: MARKER_SIGMA,
        force_sigma: FORCE_SIGMA,
    });
    builder.markers_rest(
        points
            .iter()
            .enumerate()
            .map(|(id, p)| MarkerRest {
                id: id as u32,
                x: p[0],
                y: p[1],
            })
            .collect(),
    );
    let locator = Locator::new(&truth.mesh);
    let dofs = truth.mesh.dof_count();
    let markers_of = |u: &[f64], rng: &mut ChaCha8Rng| -> Vec<(u32, [f64; 2])> {
        points
            .iter()
            .enumerate()
            .map(|(id, p)| {
                let d = locator.interpolate(u, *p).unwrap();
                (
                    id as u32,
                    [
                        p[0] + d[0] + marker_noise.sample(rng),
                        p[1] + d[1] + marker_noise.sample(rng),
                    ],
                )
            })
            .collect()
    };
    // Probe trials: three holds of increasing force pushing +y on the front face.
    for (k, (x, day)) in [(0.02, 0.0), (0.0375, 3.0), (0.055, 6.0)]
        .into_iter()
        .enumerate()
    {
        let problem = truth.problem(day);
        let trial = builder.trial(Trial {
            id: format!("probe-{k:02}"),
            kind: TrialKind::Probe,
            velocity: 0.001,
            day,
        });
        let levels = [0.1, 0.2, 0.3];
        for i in 0..60 {
            let t = i as f64 * 0.05;
            let force = levels[(i / 20).min(2)];
            trial.tool.push(ToolSample {
                t,
                tip_x: x,
                tip_y: 0.0,
                theta: 0.0,
                fx: force_noise.sample(&mut rng),
                fy: force + force_noise.sample(&mut rng),
                mz: 0.0,
            });
        }
        for (frame, level) in levels.iter().enumerate() {
            let mut load = vec![0.0; dofs];
            add_point_force(&locator, &mut load, [x, 0.0], [0.0, *level]).unwrap();
            let u = problem.solve(&load).unwrap().displacement;
            let t = 0.5 + frame as f64;
            trial
                .markers_mut()
                .push_frame(frame as u64, t, markers_of(&u, &mut rng))
                .unwrap();
        }
    }
    // Needle trials: straight insertions to 50 mm at three speeds.
    for (k, (x, velocity, day)) in [(0.03, 0.002, 1.0), (0.0375, 0.005, 4.0), (0.045, 0.01, 5.0)]
        .into_iter()
        .enumerate()
    {
        let problem = truth.problem(day);
        let trial = builder.trial(Trial {
            id: format!("needle-{k:02}"),
            kind: TrialKind::Needle,
            velocity,
            day,
        });
        let samples = 26;
        let duration = 0.05 / velocity;
        for i in 0..samples {
            let t = duration * i as f64 / (samples - 1) as f64;
            let depth = velocity * t;
            let force = truth.needle_force(depth);
            trial.tool.push(ToolSample {
                t,
                tip_x: x,
                tip_y: depth,
                theta: 0.0,
                fx: force_noise.sample(&mut rng),
                fy: force + force_noise.sample(&mut rng),
                mz: 0.0,
            });
        }
        for (frame, i) in [10usize, 17, 25].into_iter().enumerate() {
            let t = duration * i as f64 / (samples - 1) as f64;
            let depth = velocity * t;
            let density = |s: f64| [0.0, truth.density(s, depth)];
            let mut load = vec![0.0; dofs];
            add_line_load(
                &locator,
                &mut load,
                [x, 0.0],
                [x, depth],
                &LineDensity::Function {
                    density: &density,
                    breakpoints: vec![(depth - TIP_WIDTH).max(0.0)],
                },
            )
            .unwrap();
            let u = problem.solve(&load).unwrap().displacement;
            trial
                .markers_mut()
                .push_frame(frame as u64, t, markers_of(&u, &mut rng))
                .unwrap();
        }
    }
    let path = dir.join(name);
    builder.write(&path, WriteOptions::default()).unwrap();
    path
}
