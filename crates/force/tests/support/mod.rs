//! Synthetic insertions for the tests: a finer 3-D slab "truth" (Tet10,
//! more elements per marker spacing and more layers than the model) loaded on
//! its mid-plane, at the material points the needle holds, by a known axial
//! shaft density per length of needle (uniform with a tip peak
//! 100% higher, as in the paper's Fig. 10), markers read on its top face,
//! seeded Gaussian marker noise.

#![allow(dead_code)]

use needle_data::{Face, Phantom};
use needle_fem::Face as Face3;
use needle_fem::assemble::multiply;
use needle_fem::material::Material;
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Formulation, LinearProblem, Locator, Materials,
    RectangleMesh, SlabMesh,
};
use needle_force::{Frame, Insertion, MarkerLayout, MaterialField};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The paper's phantom material.
pub fn paper_material() -> MaterialField {
    MaterialField::Homogeneous(Material::new(25.3e3, 0.48).unwrap())
}

/// A phantom `width x depth x thickness` fixed at the back face.
pub fn phantom(width: f64, depth: f64, thickness: f64) -> Phantom {
    Phantom {
        width,
        depth,
        thickness,
        fixed: vec![Face::Back],
    }
}

/// `n x n` markers covering the top face edge to edge, row-major ids.
pub fn layout(phantom: &Phantom, n: usize) -> MarkerLayout {
    let mut ids = Vec::new();
    let mut rest = Vec::new();
    for j in 0..n {
        for i in 0..n {
            ids.push((j * n + i) as u32);
            rest.push([
                phantom.width * i as f64 / (n - 1) as f64,
                phantom.depth * j as f64 / (n - 1) as f64,
            ]);
        }
    }
    MarkerLayout { ids, rest }
}

/// The truth density (N/m) along a shaft of material length `length`:
/// `q0` everywhere plus a triangular peak of height `q0` centred 2 mm behind
/// the tip, 3 mm half-width.
pub fn truth_density(q0: f64, length: f64) -> impl Fn(f64) -> f64 {
    move |s: f64| {
        if !(0.0..=length).contains(&s) {
            return 0.0;
        }
        let centre = length - 2e-3;
        q0 * (1.0 + (1.0 - (s - centre).abs() / 3e-3).max(0.0))
    }
}

/// Solve-and-re-place rounds of a truth frame.
const PLACEMENT_ROUNDS: usize = 8;

/// Substitutions $X \leftarrow p - u(X)$ per material point and round.
const SUBSTITUTIONS: usize = 6;

/// The truth world: a fine Tet10 slab of the phantom, solved by
/// `needle-fem` directly (not through this crate's response code).
pub struct Truth {
    pub phantom: Phantom,
    pub layout: MarkerLayout,
    pub needle_x: f64,
    problem: LinearProblem<3>,
    interpolation: faer::sparse::SparseColMat<usize, f64>,
}

impl Truth {
    /// Tet10 slab with `refinement` elements per marker spacing and `layers`
    /// element layers (even), mirrored in its mid-plane, back face clamped.
    pub fn new(
        phantom: Phantom,
        markers: usize,
        refinement: usize,
        layers: usize,
        material: &MaterialField,
    ) -> Self {
        let layout = layout(&phantom, markers);
        let grid = layout.grid().unwrap();
        let needle_x = 0.5 * phantom.width;
        let plan = RectangleMesh::with_markers(
            phantom.width,
            phantom.depth,
            &grid.marker_grid(),
            refinement,
        )
        .unwrap();
        // Mirrored in the mid-plane, as the estimator's slab (its upper
        // half) is: at these tests' 1 um of noise the difference between
        // Kuhn's subdivision and its mirror image would be the misfit.
        let mesh = SlabMesh::new(plan, phantom.thickness, layers)
            .unwrap()
            .build_symmetric(ElementKind::Tet10)
            .unwrap();
        let top = 0.5 * phantom.thickness;
        let points: Vec<[f64; 3]> = layout.rest.iter().map(|p| [p[0], p[1], top]).collect();
        let interpolation = Locator::new(&mesh)
            .interpolation_matrix(&points, &[0, 1])
            .unwrap();
        let dirichlet = Dirichlet::fixed_face(&mesh, Face3::Back);
        let MaterialField::Homogeneous(m) = material else {
            panic!("the test truth is homogeneous")
        };
        let mut problem = LinearProblem::new(
            Assembler::new(mesh, Formulation::Solid).unwrap(),
            Vec::new(),
            dirichlet,
        )
        .unwrap();
        problem.factorize(&Materials::homogeneous(*m)).unwrap();
        Self {
            phantom,
            layout,
            needle_x,
            problem,
            interpolation,
        }
    }

    /// One noise-free frame with the spatial tip at depth `tip`: the truth
    /// density (per length of needle, peak behind the tip) as axial point
    /// forces at the material points whose deformed images lie on the
    /// needle, from the deformed entry to the tip (needle-synth's physics),
    /// placed by [`PLACEMENT_ROUNDS`] rounds of solve and re-place; the
    /// markers read on the top face; the base force the load's integral.
    pub fn frame(&self, q0: f64, tip: f64, t: f64) -> Frame {
        self.frame_with(
            &|d: f64| q0 * (1.0 + (1.0 - (d - 2e-3).abs() / 3e-3).max(0.0)),
            tip,
            t,
        )
    }

    /// As [`Truth::frame`] with the density `profile(d)` (N/m) at distance
    /// `d` behind the tip.
    pub fn frame_with(&self, profile: &dyn Fn(f64) -> f64, tip: f64, t: f64) -> Frame {
        let mesh = self.problem.mesh();
        let locator = Locator::new(mesh);
        let x0 = self.needle_x;
        let mut u = vec![0.0; mesh.dof_count()];
        let mut total = 0.0;
        for _ in 0..PLACEMENT_ROUNDS {
            let field = |p: [f64; 2]| {
                let q = [
                    p[0].clamp(0.0, self.phantom.width),
                    p[1].clamp(0.0, self.phantom.depth),
                    0.0,
                ];
                let v = locator.interpolate(&u, q).unwrap();
                [v[0], v[1]]
            };
            // The entry: the front-face point whose image is on the needle
            // (symmetric phantom: x stays on the line), in by u_y there.
            let entry = field([x0, 0.0])[1];
            let length = tip - entry;
            let density = |s: f64| profile(length - s);
            let pieces = (length / 0.25e-3).ceil() as usize;
            let h = length / pieces as f64;
            let mut loads = vec![0.0; mesh.dof_count()];
            total = 0.0;
            for k in 0..pieces {
                for (xi, w) in [
                    (0.5 - 0.5 / 3f64.sqrt(), 0.5),
                    (0.5 + 0.5 / 3f64.sqrt(), 0.5),
                ] {
                    let s = (k as f64 + xi) * h;
                    let p = [x0, entry + s];
                    // X + u(X) = p by substitution from X = p - u(p).
                    let mut x = p;
                    for _ in 0..SUBSTITUTIONS {
                        let v = field(x);
                        x = [p[0] - v[0], (p[1] - v[1]).max(0.0)];
                    }
                    let force = w * h * density(s);
                    total += force;
                    let weights = locator.weights([x[0], x[1], 0.0]).unwrap();
                    for (n, wn) in weights {
                        loads[3 * n + 1] += wn * force;
                    }
                }
            }
            u = self.problem.solve(&loads).unwrap().displacement;
        }
        let markers = multiply(&self.interpolation, &u);
        Frame {
            t,
            tip: [x0, tip],
            theta: 0.0,
            base_force: [0.0, total],
            displacement: (0..self.layout.len())
                .map(|k| Some([markers[2 * k], markers[2 * k + 1]]))
                .collect(),
            sigma: None,
        }
    }

    /// A noise-free insertion with frames at the given spatial tip depths.
    pub fn insertion(&self, q0: f64, depths: &[f64], velocity: f64) -> Insertion {
        let frames = depths
            .iter()
            .map(|&d| self.frame(q0, d, d / velocity))
            .collect();
        Insertion {
            trial: format!("synthetic-v{velocity}"),
            velocity,
            phantom: self.phantom.clone(),
            marker_sigma: None,
            layout: self.layout.clone(),
            frames,
        }
    }
}

/// A copy of `insertion` with Gaussian noise of `sigma` (m) on every marker
/// coordinate, seeded, and the stated noise set to `sigma`.
pub fn with_noise(insertion: &Insertion, sigma: f64, seed: u64) -> Insertion {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, sigma).unwrap();
    let mut noisy = insertion.clone();
    noisy.marker_sigma = Some(sigma);
    for frame in &mut noisy.frames {
        for d in frame.displacement.iter_mut().flatten() {
            d[0] += normal.sample(&mut rng);
            d[1] += normal.sample(&mut rng);
        }
    }
    noisy
}
