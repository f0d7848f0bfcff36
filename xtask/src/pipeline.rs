//! `cargo xtask pipeline`: the main job on the built-in default experiment.
//!
//! Stages that exist today:
//! 1. forward model of the paper's phantom (75 x 75 x 7.5 mm, 21 x 21
//!    markers, E = 25.3 kPa, nu = 0.48, back face fixed) under a needle
//!    shaft load shaped like the paper's Fig. 10, solved with quadratic
//!    plane-strain triangles, with a deformation plot.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use needle_fem::{
    Assembler, Dirichlet, ElementKind, Face, Formulation, LineDensity, LinearProblem, Locator,
    MarkerGrid, Material, Materials, RectangleMesh,
};

use crate::output::OutputFolder;
use crate::plot;
use crate::report::Report;

/// Options of `cargo xtask pipeline`.
#[derive(Args)]
pub struct PipelineArgs {
    /// Output folder (must not exist); default: a new folder under `out/`.
    #[arg(long)]
    out: Option<PathBuf>,
    /// A smaller experiment (coarser meshes), as run in CI.
    #[arg(long)]
    quick: bool,
}

/// The paper's phantom and needle, in SI units.
struct Phantom {
    width: f64,
    depth: f64,
    thickness: f64,
    markers_per_side: usize,
    youngs_modulus: f64,
    poisson_ratio: f64,
}

const PAPER_PHANTOM: Phantom = Phantom {
    width: 0.075,
    depth: 0.075,
    thickness: 0.0075,
    markers_per_side: 21,
    youngs_modulus: 25.3e3,
    poisson_ratio: 0.48,
};

/// Shaft force density along +y (N/m): uniform behind a tip peak that
/// rises 100% above it over the last `TIP_PEAK_LENGTH` (the paper's Fig. 10).
const SHAFT_DENSITY: f64 = 12.0;
const TIP_PEAK_LENGTH: f64 = 0.003;
const NEEDLE_DEPTH: f64 = 0.045;

/// Runs the pipeline.
pub fn run(args: &PipelineArgs) -> Result<(), String> {
    let started = Instant::now();
    let folder = OutputFolder::create(args.out.as_deref(), "pipeline")?;
    let mut report = Report::default();

    forward_model(args.quick, &folder, &mut report)?;

    folder.write("report.html", &report.to_html("needle pipeline report"))?;
    let finished = folder.finish()?;
    println!(
        "pipeline finished in {:.1} s; report: {}",
        started.elapsed().as_secs_f64(),
        finished.join("report.html").display()
    );
    Ok(())
}

/// Stage 1: the paper's phantom under a needle shaft load.
fn forward_model(quick: bool, folder: &OutputFolder, report: &mut Report) -> Result<(), String> {
    let phantom = PAPER_PHANTOM;
    let refinement = if quick { 1 } else { 2 };
    let markers = MarkerGrid::uniform(
        phantom.markers_per_side,
        phantom.markers_per_side,
        (0.0, 0.0),
        (phantom.width, phantom.depth),
    );
    let fem_error = |e: needle_fem::FemError| format!("forward model: {e}");
    let mesh = RectangleMesh::with_markers(phantom.width, phantom.depth, &markers, refinement)
        .and_then(|plan| plan.build(ElementKind::Tri6))
        .map_err(fem_error)?;
    let formulation = Formulation::PlaneStrain {
        thickness: phantom.thickness,
    };
    let fixed = Dirichlet::fixed_face(&mesh, Face::Back);

    let mut loads = vec![0.0; mesh.dof_count()];
    let entry = [phantom.width / 2.0, 0.0];
    let tip = [phantom.width / 2.0, NEEDLE_DEPTH];
    let density = |s: f64| {
        let peak = if s > NEEDLE_DEPTH - TIP_PEAK_LENGTH {
            2.0
        } else {
            1.0
        };
        [0.0, SHAFT_DENSITY * peak]
    };
    let profile = LineDensity::Function {
        density: &density,
        breakpoints: vec![NEEDLE_DEPTH - TIP_PEAK_LENGTH],
    };
    let applied = {
        let locator = Locator::new(&mesh);
        needle_fem::load::add_line_load(&locator, &mut loads, entry, tip, &profile)
            .map_err(fem_error)?
    };

    let assembler = Assembler::new(mesh, formulation).map_err(fem_error)?;
    let mut problem = LinearProblem::new(assembler, vec![], fixed).map_err(fem_error)?;
    let material =
        Material::new(phantom.youngs_modulus, phantom.poisson_ratio).map_err(fem_error)?;
    problem
        .factorize(&Materials::homogeneous(material))
        .map_err(fem_error)?;
    let solution = problem.solve(&loads).map_err(fem_error)?;

    let locator = Locator::new(problem.mesh());
    let marker_points = markers.points();
    let mut displacements = Vec::with_capacity(marker_points.len());
    for &point in &marker_points {
        displacements.push(
            locator
                .interpolate(&solution.displacement, point)
                .map_err(fem_error)?,
        );
    }
    let reaction_y: f64 = solution.reactions.iter().skip(1).step_by(2).sum();
    let largest = displacements
        .iter()
        .map(|d| d[0].hypot(d[1]))
        .fold(0.0, f64::max);

    let svg = plot::marker_displacements(
        &marker_points,
        &displacements,
        (phantom.width, phantom.depth),
        (entry, tip),
        "Paper phantom under a needle shaft load (plane strain, T6)",
    )?;
    folder.write("deformation.svg", &svg)?;
    report.section(
        "Forward model: the paper phantom under a needle shaft load",
        &format!(
            "75 x 75 x 7.5 mm phantom, E = 25.3 kPa, nu = 0.48, back face fixed; quadratic \
             plane-strain triangles. Needle along x = 37.5 mm to {:.0} mm depth with a uniform \
             shaft force density of {SHAFT_DENSITY} N/m and a tip peak 100% above it.",
            NEEDLE_DEPTH * 1e3,
        ),
        &[svg],
    );
    report.table(
        "Forward model figures",
        &["quantity", "value"],
        &[
            vec!["mesh nodes".into(), problem.mesh().node_count().to_string()],
            vec![
                "applied shaft force (N)".into(),
                format!("{:.4}", applied[1]),
            ],
            vec![
                "reaction at the back face (N)".into(),
                format!("{:.4}", -reaction_y),
            ],
            vec![
                "largest marker displacement (mm)".into(),
                format!("{:.3}", largest * 1e3),
            ],
        ],
    );
    Ok(())
}
