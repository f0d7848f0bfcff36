//! A small truth world for the diagnosis tests, independent of the crate's
//! forward model and effect files: its own T6 mesh, solves and loads, the
//! hidden effects written here from their physics, and bundles written with
//! needle-data's `BundleBuilder` with seeded Gaussian noise.
//!
//! Needles load the material points that their spatial line passes
//! through, from the dragged-in front face to the tip, solved to
//! convergence (see `Truth::needle_state`), by point loads and Newton's
//! method rather than the model's line loads and fixed rounds.
//!
//! A neo-Hookean truth (`Hidden::neo_hookean`) solves every probe hold and
//! every needle placement to equilibrium with needle-fem's Newton solver,
//! not to any order in the load (the model's `material_nonlinearity` is
//! second order).
//!
//! The truth mesh has the refinement the tests give the model (2, to keep
//! them fast; the slab of `Hidden::slab` the model's default slab
//! refinement, 1, with two layers), so these tests check the statistics and
//! the ranking, not discretisation. A finer truth
//! (refinement 4) was tried: its difference from the model's mesh is itself
//! detectable at 8 um marker noise (marker chi2/dof 1.06-1.27 after the
//! right effect is added), and per-trial effects (stiffening, velocity
//! friction) then absorb it as significant false positives.

use std::path::{Path, PathBuf};

use needle_data::{
    BundleBuilder, Face as DataFace, MarkerRest, MarkerTrack, Noise, Phantom, ToolSample, Trial,
    TrialKind, WriteOptions,
};
use needle_fem::load::{add_line_load, add_point_force};
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, HyperelasticProblem, LineDensity,
    LinearProblem, Locator, MarkerGrid, Material, Materials, Mesh, NonlinearOptions, RectangleMesh,
    SlabMesh, Support,
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
    /// The truth is a Tet10 slab through the thickness (markers on the top
    /// face, needle in the mid-plane, probe force spread over the
    /// thickness) instead of plane strain.
    pub slab: bool,
    /// Growth of the shaft density with insertion speed (N s/m²).
    pub velocity_slope: f64,
    /// Foundation stiffness of the platform per unit area (N/m³).
    pub platform: f64,
    /// Radial tracking error at the outermost marker (m), cubic in radius.
    pub lens: f64,
    /// Relative stiffness change beyond y = `LAYER_BOUNDARY`.
    pub layer_contrast: f64,
    /// Stiffness factor of a disc of radius `INCLUSION_RADIUS` around
    /// `INCLUSION_CENTRE` (an effect outside the catalog); 0 means none.
    pub inclusion: f64,
    /// The material is compressible neo-Hookean with the same small-strain
    /// E and nu, solved to equilibrium by Newton's method.
    pub neo_hookean: bool,
}

/// Depth of the layer boundary of `Hidden::layer_contrast` (m).
const LAYER_BOUNDARY: f64 = 0.04;
/// Where the stiff inclusion of `Hidden::inclusion` sits (m).
pub const INCLUSION_CENTRE: [f64; 2] = [0.052, 0.03];
const INCLUSION_RADIUS: f64 = 0.009;

/// A load on the truth.
#[derive(Debug, Clone, Copy)]
enum Push {
    /// Probe force (N) along +y at `x` on the front face.
    Probe { x: f64, force: f64 },
    /// Needle inserted along +y at `x` to `depth` at `velocity`.
    Needle { x: f64, depth: f64, velocity: f64 },
}

const TIP_WIDTH: f64 = 0.005;
/// Width of the blunt probe's contact patch (m).
pub const PROBE_WIDTH: f64 = 0.003;
/// Elements per marker spacing of the truth mesh (see the module doc).
const TRUTH_REFINEMENT: usize = 2;
const YOUNGS: f64 = 25.0e3;
const POISSON: f64 = 0.45;
const SHAFT_DENSITY: f64 = 10.0;

/// The truth's answer to one push.
struct Response {
    /// In-plane displacement of every asked point of the top face.
    markers: Vec<[f64; 2]>,
    /// How far a needle dragged its entry point into the slab (m).
    entry: f64,
}

/// In-plane displacements of `points` on the top face in the solution `u`.
fn top_face<const D: usize>(
    locator: &Locator<'_, D>,
    u: &[f64],
    points: &[[f64; 2]],
) -> Vec<[f64; 2]> {
    points
        .iter()
        .map(|p| {
            let d = locator.interpolate(u, lift(*p, 0.5 * THICKNESS)).unwrap();
            [d[0], d[1]]
        })
        .collect()
}

/// The truth's equilibrium on one day: linear, or neo-Hookean.
struct Equilibrium<const D: usize> {
    linear: LinearProblem<D>,
    hyperelastic: Option<(HyperelasticProblem<D>, Materials)>,
}

impl<const D: usize> Equilibrium<D> {
    /// Nodal displacements under nodal `load`; the neo-Hookean solve starts
    /// from `start` when given (a nearby state), else from the linear
    /// solution. It iterates with the factorised linear stiffness
    /// (modified Newton, cheap near the answer) and falls back to Newton's
    /// method if that does not converge; both stop at a relative residual
    /// of 1e-10.
    fn solve(&self, load: &[f64], start: Option<&[f64]>) -> Vec<f64> {
        let linear = || self.linear.solve(load).unwrap().displacement;
        match &self.hyperelastic {
            None => linear(),
            Some((problem, materials)) => {
                let guess = start.map_or_else(linear, <[f64]>::to_vec);
                let options = NonlinearOptions::default();
                match problem.solve_modified_newton(materials, &[load], Some(&[&guess]), &options) {
                    Ok(mut solved) => solved.remove(0).displacement,
                    Err(_) => {
                        problem
                            .solve_newton(materials, load, Some(&guess), &options)
                            .unwrap()
                            .displacement
                    }
                }
            }
        }
    }
}

struct Truth {
    plane: Mesh<2>,
    slab: Mesh<3>,
    hidden: Hidden,
}

/// The same mesh with every element in its own region.
fn own_regions<const D: usize>(mesh: Mesh<D>) -> Mesh<D> {
    let count = mesh.element_count();
    Mesh::new(
        mesh.kind(),
        mesh.nodes().to_vec(),
        mesh.connectivity().to_vec(),
        (0..count).collect(),
    )
    .unwrap()
}

/// A point of the plane at height `z` (ignored in 2-D).
fn lift<const D: usize>(xy: [f64; 2], z: f64) -> [f64; D] {
    std::array::from_fn(|i| if i < 2 { xy[i] } else { z })
}

impl Truth {
    fn new(markers: &MarkerGrid, hidden: Hidden) -> Self {
        let plane = own_regions(
            RectangleMesh::with_markers(WIDTH, DEPTH, markers, TRUTH_REFINEMENT)
                .unwrap()
                .build(ElementKind::Tri6)
                .unwrap(),
        );
        let slab = own_regions(
            SlabMesh::new(
                RectangleMesh::with_markers(WIDTH, DEPTH, markers, 1).unwrap(),
                THICKNESS,
                2,
            )
            .unwrap()
            .build(ElementKind::Tet10)
            .unwrap(),
        );
        Self {
            plane,
            slab,
            hidden,
        }
    }

    fn problem<const D: usize>(&self, mesh: &Mesh<D>, day: f64) -> Equilibrium<D> {
        let formulation = if D == 2 {
            Formulation::PlaneStrain {
                thickness: THICKNESS,
            }
        } else {
            Formulation::Solid
        };
        let assembler = Assembler::new(mesh.clone(), formulation).unwrap();
        let (mut supports, dirichlet) = if self.hidden.back_springs > 0.0 {
            let k = self.hidden.back_springs;
            (
                vec![Support::Boundary {
                    facets: mesh.facets_on_face(Face::Back),
                    stiffness: [k; D],
                }],
                Dirichlet::new(),
            )
        } else {
            (vec![], Dirichlet::fixed_face(mesh, Face::Back))
        };
        if self.hidden.platform > 0.0 {
            let stiffness = [self.hidden.platform; D];
            supports.push(if D == 2 {
                Support::Foundation { stiffness }
            } else {
                Support::Boundary {
                    facets: mesh.facets_on_face(Face::Bottom),
                    stiffness,
                }
            });
        }
        let mut problem = LinearProblem::new(assembler, supports, dirichlet).unwrap();
        let e = YOUNGS * (1.0 + self.hidden.stiffening * day);
        let materials = (0..mesh.element_count())
            .map(|k| {
                let c = mesh.centroid(k);
                let mut factor = 1.0;
                if c[1] > LAYER_BOUNDARY {
                    factor *= 1.0 + self.hidden.layer_contrast;
                }
                let inside = (c[0] - INCLUSION_CENTRE[0]).hypot(c[1] - INCLUSION_CENTRE[1])
                    < INCLUSION_RADIUS;
                if inside && self.hidden.inclusion > 0.0 {
                    factor *= self.hidden.inclusion;
                }
                Material::for_region(k, e * factor, POISSON).unwrap()
            })
            .collect();
        let materials = Materials(materials);
        problem.factorize(&materials).unwrap();
        let hyperelastic = self.hidden.neo_hookean.then(|| {
            (
                HyperelasticProblem::new(problem.clone()).unwrap(),
                materials,
            )
        });
        Equilibrium {
            linear: problem,
            hyperelastic,
        }
    }

    /// In-plane displacement of every point of `points` (on the top face)
    /// under `pushes` on day `day`, and how far each push's entry point
    /// was dragged into the slab (0 for probes).
    fn respond(&self, day: f64, pushes: &[Push], points: &[[f64; 2]]) -> Vec<Response> {
        if self.hidden.slab {
            self.respond_on(&self.slab, day, pushes, points)
        } else {
            self.respond_on(&self.plane, day, pushes, points)
        }
    }

    fn respond_on<const D: usize>(
        &self,
        mesh: &Mesh<D>,
        day: f64,
        pushes: &[Push],
        points: &[[f64; 2]],
    ) -> Vec<Response> {
        let problem = self.problem(mesh, day);
        let locator = Locator::new(mesh);
        let half = 0.5 * THICKNESS;
        pushes
            .iter()
            .map(|push| {
                let mut load = vec![0.0; mesh.dof_count()];
                match *push {
                    // A blunt probe: a rigid flat punch of PROBE_WIDTH on
                    // the front face, its pressure 1/sqrt(1 - (2s/a)^2)
                    // integrated by 16-point Gauss-Chebyshev (through the
                    // thickness in 3-D).
                    Push::Probe { x, force } => {
                        const POINTS: usize = 16;
                        let share = force / POINTS as f64;
                        for i in 0..POINTS {
                            let angle =
                                (2 * i + 1) as f64 * std::f64::consts::PI / (2 * POINTS) as f64;
                            let at = x + 0.5 * PROBE_WIDTH * angle.cos();
                            if D == 2 {
                                add_point_force(
                                    &locator,
                                    &mut load,
                                    lift([at, 0.0], 0.0),
                                    lift([0.0, share], 0.0),
                                )
                                .unwrap();
                            } else {
                                let per_length = lift::<D>([0.0, share / THICKNESS], 0.0);
                                let density = move |_: f64| per_length;
                                add_line_load(
                                    &locator,
                                    &mut load,
                                    lift([at, 0.0], -half),
                                    lift([at, 0.0], half),
                                    &LineDensity::Function {
                                        density: &density,
                                        breakpoints: vec![],
                                    },
                                )
                                .unwrap();
                            }
                        }
                    }
                    Push::Needle { x, depth, velocity } => {
                        return self.needle_state(&problem, &locator, x, depth, velocity, points);
                    }
                }
                let u = problem.solve(&load, None);
                Response {
                    markers: top_face(&locator, &u, points),
                    entry: 0.0,
                }
            })
            .collect()
    }

    /// A needle along +y at `x` with its tip at `depth`, its load on the
    /// material points whose deformed positions lie on it, found by
    /// iterating: place the point loads, solve, move every point to the
    /// material point of its spatial position (Newton's method on
    /// $X + u(X) = p$), until no point moves by more than 1e-11 m. The
    /// shaft starts at the deformed front face, whose material point
    /// $(x_e, 0)$ satisfies $x_e + u_x = x$.
    fn needle_state<const D: usize>(
        &self,
        problem: &Equilibrium<D>,
        locator: &Locator<'_, D>,
        x: f64,
        depth: f64,
        velocity: f64,
        points: &[[f64; 2]],
    ) -> Response {
        let dofs = locator.mesh().dof_count();
        let at = |u: &[f64], p: [f64; 2]| -> [f64; 2] {
            let inside = [p[0].clamp(0.0, WIDTH), p[1].clamp(0.0, DEPTH)];
            let d = locator.interpolate(u, lift(inside, 0.0)).unwrap();
            [d[0], d[1]]
        };
        // Two Gauss points on each of `segments` spatial segments.
        let segments = (depth / 2.5e-4).ceil().max(1.0) as usize;
        let mut u = vec![0.0; dofs];
        let mut placed: Vec<[f64; 2]> = Vec::new();
        for _ in 0..200 {
            let mut xe = x;
            for _ in 0..20 {
                let h = 1e-8;
                let miss = |xe: f64| xe + at(&u, [xe, 0.0])[0] - x;
                let step = miss(xe) * 2.0 * h / (miss(xe + h) - miss(xe - h));
                xe -= step;
                if step.abs() < 1e-14 {
                    break;
                }
            }
            let entry = at(&u, [xe, 0.0])[1];
            let length = depth - entry;
            let h = length / segments as f64;
            let g = 0.5 / 3f64.sqrt();
            let mut loads = Vec::with_capacity(2 * segments);
            for k in 0..segments {
                let middle = (k as f64 + 0.5) * h;
                for s in [middle - g * h, middle + g * h] {
                    let p = [x, entry + s];
                    let mut m = p;
                    for _ in 0..30 {
                        let d = at(&u, m);
                        let r = [m[0] + d[0] - p[0], m[1] + d[1] - p[1]];
                        let e = 1e-8;
                        let dx = at(&u, [m[0] + e, m[1]]);
                        let dy = at(&u, [m[0], m[1] + e]);
                        let jac = [
                            [1.0 + (dx[0] - d[0]) / e, (dy[0] - d[0]) / e],
                            [(dx[1] - d[1]) / e, 1.0 + (dy[1] - d[1]) / e],
                        ];
                        let det = jac[0][0] * jac[1][1] - jac[0][1] * jac[1][0];
                        let step = [
                            (jac[1][1] * r[0] - jac[0][1] * r[1]) / det,
                            (jac[0][0] * r[1] - jac[1][0] * r[0]) / det,
                        ];
                        m = [m[0] - step[0], m[1] - step[1]];
                        if step[0].abs().max(step[1].abs()) < 1e-14 {
                            break;
                        }
                    }
                    let m = [m[0].clamp(0.0, WIDTH), m[1].clamp(0.0, DEPTH)];
                    loads.push((m, 0.5 * h * self.density(s, length, velocity)));
                }
            }
            let moved = placed
                .iter()
                .zip(&loads)
                .map(|(a, (b, _))| (a[0] - b[0]).abs().max((a[1] - b[1]).abs()))
                .fold(if placed.is_empty() { 1.0 } else { 0.0 }, f64::max);
            if moved < 1e-11 {
                return Response {
                    markers: top_face(locator, &u, points),
                    entry,
                };
            }
            let first = placed.is_empty();
            placed = loads.iter().map(|l| l.0).collect();
            let mut load = vec![0.0; dofs];
            for (m, force) in loads {
                add_point_force(locator, &mut load, lift(m, 0.0), lift([0.0, force], 0.0)).unwrap();
            }
            // Each placement is near the last: Newton starts there.
            let start = (!first).then_some(u.as_slice());
            u = problem.solve(&load, start);
        }
        panic!("the truth's needle placement did not converge at depth {depth}");
    }

    /// Shaft density at arclength `s` of a needle inserted by `length` at
    /// `velocity`.
    fn density(&self, s: f64, length: f64, velocity: f64) -> f64 {
        let behind = length - s;
        let peak = if behind < TIP_WIDTH {
            self.hidden.tip_peak * (TIP_WIDTH - behind) / TIP_WIDTH
        } else {
            0.0
        };
        SHAFT_DENSITY + self.hidden.velocity_slope * velocity + peak
    }

    fn needle_force(&self, length: f64, velocity: f64) -> f64 {
        let peak_length = length.min(TIP_WIDTH);
        // Area of the part of the triangle inside the slab.
        let peak =
            self.hidden.tip_peak * (peak_length - 0.5 * peak_length * peak_length / TIP_WIDTH);
        (SHAFT_DENSITY + self.hidden.velocity_slope * velocity) * length + peak
    }
}

fn marker_grid() -> MarkerGrid {
    MarkerGrid::uniform(7, 7, (0.0075, 0.0075), (0.0675, 0.0675))
}

/// Writes a bundle with `hidden` effects and noise drawn from `seed` into
/// `dir/name` and returns its path.
pub fn make_bundle(dir: &Path, name: &str, hidden: Hidden, seed: u64) -> PathBuf {
    make_bundle_with(dir, name, hidden, seed, Written::default())
}

/// How a bundle states its noise, and which trials it holds.
#[derive(Debug, Clone, Copy)]
pub struct Written {
    /// The manifest states the noise (`MARKER_SIGMA`, `FORCE_SIGMA`).
    pub state_noise: bool,
    /// Markers with odd ids are tracked `ODD_MARKER_NOISE` times worse.
    pub odd_noise: bool,
    /// Every row of `markers.csv` gives its own `sx,sy`.
    pub row_sigmas: bool,
    /// The needle trials are written (without them, a probing campaign).
    pub needles: bool,
}

impl Default for Written {
    fn default() -> Self {
        Self {
            state_noise: true,
            odd_noise: false,
            row_sigmas: false,
            needles: true,
        }
    }
}

/// How much noisier the odd markers are with `Written::odd_noise`.
pub const ODD_MARKER_NOISE: f64 = 3.0;

/// As [`make_bundle`], with the noise written as `written` says.
pub fn make_bundle_with(
    dir: &Path,
    name: &str,
    hidden: Hidden,
    seed: u64,
    written: Written,
) -> PathBuf {
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
    if written.state_noise {
        builder.noise(Noise {
            marker_sigma: MARKER_SIGMA,
            force_sigma: FORCE_SIGMA,
        });
    }
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
    // Brown's radial model about the marker field's centre, k1 set so that
    // the outermost marker is displaced by `hidden.lens`.
    let centre = [0.5 * WIDTH, 0.5 * DEPTH];
    let outermost = points
        .iter()
        .map(|p| (p[0] - centre[0]).hypot(p[1] - centre[1]))
        .fold(0.0, f64::max);
    let k1 = hidden.lens / outermost.powi(3);
    let marker_sigma = |id: usize| {
        if written.odd_noise && id % 2 == 1 {
            ODD_MARKER_NOISE * MARKER_SIGMA
        } else {
            MARKER_SIGMA
        }
    };
    let markers_of = |d: &[[f64; 2]], rng: &mut ChaCha8Rng| -> Vec<(u32, [f64; 2])> {
        points
            .iter()
            .zip(d)
            .enumerate()
            .map(|(id, (p, d))| {
                let (x, y) = (p[0] + d[0] - centre[0], p[1] + d[1] - centre[1]);
                let distortion = 1.0 + k1 * (x * x + y * y);
                (
                    id as u32,
                    [
                        centre[0]
                            + distortion * x
                            + marker_noise.sample(rng) * marker_sigma(id) / MARKER_SIGMA,
                        centre[1]
                            + distortion * y
                            + marker_noise.sample(rng) * marker_sigma(id) / MARKER_SIGMA,
                    ],
                )
            })
            .collect()
    };
    let push = |track: &mut MarkerTrack, frame: u64, t: f64, markers: Vec<(u32, [f64; 2])>| {
        if written.row_sigmas {
            let rows = markers.into_iter().map(|(id, p)| {
                let sigma = marker_sigma(id as usize);
                (id, p, [sigma, sigma])
            });
            track.push_frame_with_sigma(frame, t, rows).unwrap();
        } else {
            track.push_frame(frame, t, markers).unwrap();
        }
    };
    // Probe trials: three holds of increasing force pushing +y on the front face.
    for (k, (x, day)) in [(0.02, 0.0), (0.0375, 3.0), (0.055, 6.0)]
        .into_iter()
        .enumerate()
    {
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
                // The blunt probe sinks in by millimetres (10 mm/N here);
                // the model must still load the boundary under it.
                tip_y: 0.01 * force,
                theta: 0.0,
                fx: force_noise.sample(&mut rng),
                fy: force + force_noise.sample(&mut rng),
                mz: 0.0,
            });
        }
        let pushes: Vec<Push> = levels
            .iter()
            .map(|&force| Push::Probe { x, force })
            .collect();
        for (frame, response) in truth.respond(day, &pushes, &points).iter().enumerate() {
            let t = 0.5 + frame as f64;
            let markers = markers_of(&response.markers, &mut rng);
            push(trial.markers_mut(), frame as u64, t, markers);
        }
    }
    // Needle trials: straight insertions to 50 mm at three speeds.
    let needles = [(0.03, 0.002, 1.0), (0.0375, 0.005, 4.0), (0.045, 0.01, 5.0)];
    let needles = if written.needles { &needles[..] } else { &[] };
    for (k, &(x, velocity, day)) in needles.iter().enumerate() {
        let trial = builder.trial(Trial {
            id: format!("needle-{k:02}"),
            kind: TrialKind::Needle,
            velocity,
            day,
        });
        let samples = 26;
        let duration = 0.05 / velocity;
        let time = |i: usize| duration * i as f64 / (samples - 1) as f64;
        // Every tool sample's state: its base force needs the dragged entry.
        let pushes: Vec<Push> = (1..samples)
            .map(|i| Push::Needle {
                x,
                depth: velocity * time(i),
                velocity,
            })
            .collect();
        let responses = truth.respond(day, &pushes, &points);
        for i in 0..samples {
            let depth = velocity * time(i);
            let force = if i == 0 {
                0.0
            } else {
                truth.needle_force(depth - responses[i - 1].entry, velocity)
            };
            trial.tool.push(ToolSample {
                t: time(i),
                tip_x: x,
                tip_y: depth,
                theta: 0.0,
                fx: force_noise.sample(&mut rng),
                fy: force + force_noise.sample(&mut rng),
                mz: 0.0,
            });
        }
        for (frame, &i) in [10usize, 17, 25].iter().enumerate() {
            let markers = markers_of(&responses[i - 1].markers, &mut rng);
            push(trial.markers_mut(), frame as u64, time(i), markers);
        }
    }
    let path = dir.join(name);
    builder.write(&path, WriteOptions::default()).unwrap();
    path
}
