//! The speed-comparison problem shared with the scikit-fem peer
//! (`bench/peers/fem_skfem_peer.py`): times each phase of a plane-strain T6
//! solve with needle-fem and prints one table row per mesh size.
//!
//! The problem: a 75 mm x 75 mm square, 7.5 mm thick, plane strain,
//! $E = 25.3$ kPa, $\nu = 0.48$; back face $y = 75$ mm fixed
//! ($u_x = u_y = 0$); a uniform 1 kPa traction in $-y$ on the front face
//! $y = 0$. The mesh is `RectangleMesh::uniform(.., n, n)` (each grid cell
//! cut into two triangles along a diagonal that alternates in a checkerboard,
//! `/` when `i + j` is even), promoted to 6-node triangles: $2(2n+1)^2$ dofs.
//!
//! Run (release build; the default sizes are n = 35, 111, 353, i.e. about
//! 10k, 100k and 1M dofs; other cell counts may be given as arguments):
//!
//! ```text
//! cargo run --release -p needle-fem --example peer_problem
//! cargo run --release -p needle-fem --example peer_problem -- 35 111
//! ```
//!
//! Each size is solved 5 times (3 times from 300 cells up) and the table
//! shows medians, in seconds:
//!
//! - `mesh`: `RectangleMesh::build(Tri6)` (not in the total, as on the
//!   peer's side);
//! - `assemble`: the load vector (`add_traction`), the sparsity pattern
//!   (`Assembler::new`) and the values of $K$ (`Assembler::stiffness_into`);
//! - `symbolic`: `LinearProblem::new`: rigid-mode check, extraction of the
//!   pattern of $K_{ff}$ (the condensation), nested-dissection ordering
//!   and symbolic Cholesky analysis (AMD before session 32);
//! - `numeric`: the numeric Cholesky factorisation of $K_{ff}$ alone;
//! - `factorize`: `LinearProblem::factorize`, which re-assembles the values
//!   of $K$ and then factorises ($\approx$ values + numeric);
//! - `solve`: `LinearProblem::solve` (lift of the prescribed values, the two
//!   triangular solves, the reactions);
//! - `total`: wall time of the whole pipeline as a user calls it,
//!   `add_traction`, `Assembler::new`, `LinearProblem::new`, `factorize`,
//!   `solve` (so `total` $\approx$ `assemble` + `symbolic` + `numeric` +
//!   `solve`).
//!
//! `values` and `numeric` are measured by separate calls after the pipeline
//! (the API fuses them in `factorize`). `mean_uy` is the arithmetic mean of
//! $u_y$ over all nodes on the front face (corner and mid-side nodes), the
//! check that both sides solve the same problem; `peak_MB` is the process's
//! peak resident memory so far (`VmHWM`).

use std::time::Instant;

use faer::Side;
use faer::sparse::linalg::cholesky::factorize_symbolic_cholesky;
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, FemError, Formulation, LinearProblem, Material,
    Materials, RectangleMesh,
};

const SIDE: f64 = 0.075;
const THICKNESS: f64 = 0.0075;
const YOUNGS_MODULUS: f64 = 25.3e3;
const POISSON_RATIO: f64 = 0.48;
const TRACTION: f64 = 1.0e3;

/// Timings (s) and results of one run of one size.
struct Run {
    dofs: usize,
    nnz: usize,
    factor_nnz: usize,
    mesh: f64,
    loads: f64,
    pattern: f64,
    values: f64,
    symbolic: f64,
    analysis: f64,
    numeric: f64,
    factorize: f64,
    solve: f64,
    total: f64,
    mean_uy: f64,
}

fn seconds(start: Instant) -> f64 {
    start.elapsed().as_secs_f64()
}

fn run(cells: usize) -> Result<Run, FemError> {
    let formulation = Formulation::PlaneStrain {
        thickness: THICKNESS,
    };
    let materials = Materials::homogeneous(Material::new(YOUNGS_MODULUS, POISSON_RATIO)?);

    let start = Instant::now();
    let mesh = RectangleMesh::uniform(SIDE, SIDE, cells, cells)?.build(ElementKind::Tri6)?;
    let mesh_time = seconds(start);

    // The pipeline, timed phase by phase and end to end.
    let pipeline = Instant::now();
    let start = Instant::now();
    let fixed = Dirichlet::fixed_face(&mesh, Face::Back);
    let front = mesh.facets_on_face(Face::Front);
    let mut loads = vec![0.0; mesh.dof_count()];
    needle_fem::load::add_traction(&mesh, formulation, &mut loads, &front, |_| [0.0, -TRACTION])?;
    let loads_time = seconds(start);
    let start = Instant::now();
    let assembler = Assembler::new(mesh, formulation)?;
    let pattern = seconds(start);
    let start = Instant::now();
    let mut problem = LinearProblem::new(assembler, vec![], fixed)?;
    let symbolic = seconds(start);
    let start = Instant::now();
    problem.factorize(&materials)?;
    let factorize = seconds(start);
    let start = Instant::now();
    let solution = problem.solve(&loads)?;
    let solve = seconds(start);
    let total = seconds(pipeline);

    // The two halves of `factorize`, each on its own.
    let mut stiffness = problem.assembler().pattern().zeros();
    let start = Instant::now();
    problem
        .assembler()
        .stiffness_into(&materials, &mut stiffness)?;
    let values = seconds(start);
    let start = Instant::now();
    let mut factor = problem.new_factor();
    factor.factorize(problem.reduced_stiffness().as_ref())?;
    let numeric = seconds(start);
    drop(factor);
    // faer's default symbolic analysis alone (AMD ordering and elimination
    // tree), for comparison with the ordering `LinearProblem::new` makes.
    let factor_nnz = problem.new_factor().symbolic().len_val();
    let start = Instant::now();
    let analysis = factorize_symbolic_cholesky(
        problem.reduced_stiffness().symbolic(),
        Side::Lower,
        Default::default(),
        Default::default(),
    )
    .map_err(|e| FemError::Factorization(format!("{e:?}")))?;
    let analysis_time = seconds(start);
    drop(analysis);

    let front_nodes = problem.mesh().nodes_on_face(Face::Front);
    if front_nodes.len() != 2 * cells + 1 {
        return Err(FemError::InvalidMesh(format!(
            "{} front nodes, expected {}",
            front_nodes.len(),
            2 * cells + 1
        )));
    }
    let mean_uy = front_nodes
        .iter()
        .map(|&n| solution.displacement[2 * n + 1])
        .sum::<f64>()
        / front_nodes.len() as f64;
    Ok(Run {
        dofs: problem.mesh().dof_count(),
        nnz: problem.stiffness().compute_nnz(),
        factor_nnz,
        mesh: mesh_time,
        loads: loads_time,
        pattern,
        values,
        symbolic,
        analysis: analysis_time,
        numeric,
        factorize,
        solve,
        total,
        mean_uy,
    })
}

fn median(mut samples: Vec<f64>) -> f64 {
    samples.sort_by(f64::total_cmp);
    let m = samples.len() / 2;
    if samples.len() % 2 == 1 {
        samples[m]
    } else {
        0.5 * (samples[m - 1] + samples[m])
    }
}

/// Peak resident set size of this process in MB, if `/proc` tells it.
fn peak_megabytes() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kilobytes: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kilobytes / 1024.0)
}

/// The header of the table shared with the peer script.
const HEADER: &str = "solver               cells     dofs    nnz(K)     nnz(L) rep    mesh assemble condense symbolic  numeric    solve    total        mean_uy  peak_MB";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let cells: Vec<usize> = {
        let args: Vec<usize> = std::env::args()
            .skip(1)
            .map(|a| a.parse())
            .collect::<Result<_, _>>()?;
        if args.is_empty() {
            vec![35, 111, 353]
        } else {
            args
        }
    };
    println!(
        "needle-fem, {} rayon threads; medians in s; condense is inside symbolic (LinearProblem::new)",
        rayon::current_num_threads()
    );
    println!("{HEADER}");
    let mut details = Vec::new();
    for &n in &cells {
        let repeats = if n >= 300 { 3 } else { 5 };
        let runs: Vec<Run> = (0..repeats).map(|_| run(n)).collect::<Result<_, _>>()?;
        let med = |f: fn(&Run) -> f64| median(runs.iter().map(f).collect());
        let first = &runs[0];
        // Every repeat solves the same system: the answers must agree.
        let spread = runs
            .iter()
            .map(|r| (r.mean_uy - first.mean_uy).abs())
            .fold(0.0, f64::max);
        if spread > 1e-12 * first.mean_uy.abs() {
            return Err(format!("repeats disagree on mean_uy by {spread:e}").into());
        }
        println!(
            "{:<20} {:>5} {:>8} {:>9} {:>10} {:>3} {:>7.3} {:>8.3} {:>8} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>14.8e} {:>8.0}",
            "needle-fem/faer",
            n,
            first.dofs,
            first.nnz,
            first.factor_nnz,
            repeats,
            med(|r| r.mesh),
            med(|r| r.loads + r.pattern + r.values),
            "-",
            med(|r| r.symbolic),
            med(|r| r.numeric),
            med(|r| r.solve),
            med(|r| r.total),
            first.mean_uy,
            peak_megabytes().unwrap_or(f64::NAN),
        );
        details.push(format!(
            "{:>5} {:>8} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>9.3}",
            n,
            first.dofs,
            med(|r| r.loads),
            med(|r| r.pattern),
            med(|r| r.values),
            med(|r| r.analysis),
            med(|r| r.factorize),
            med(|r| r.loads + r.pattern + r.values + r.symbolic + r.numeric + r.solve),
        ));
    }
    println!(
        "\nneedle-fem phases in detail (medians in s): loads = add_traction, pattern = Assembler::new,\n\
         values = stiffness_into, analysis = AMD + symbolic Cholesky alone, factorize = LinearProblem::factorize\n\
         (values + numeric), sum = assemble + symbolic + numeric + solve"
    );
    println!("cells     dofs    loads  pattern   values analysis factoriz       sum");
    for line in details {
        println!("{line}");
    }
    Ok(())
}
