//! Runs a scenario's campaign in the truth world and writes the bundle
//! (through needle-data, atomically) and the ground truth.

use std::path::{Path, PathBuf};
use std::time::Instant;

use needle_data::{
    BundleBuilder, CompressionPoint, Face, MarkerRest, Noise, Phantom, TrialKind, WriteOptions,
};
use rayon::prelude::*;

use crate::camera::TrueCamera;
use crate::effect::material_nonlinearity::uniaxial_nominal_stress;
use crate::error::SynthError;
use crate::frames::{Staging, write_calibration};
use crate::marker_mesh::{
    follows_paths, insertion_alone, marker_scenario, material_paths, settle_on,
};
use crate::needle::{NeedleRun, insert};
use crate::probe::{Factorisation, ProbeRun, press};
use crate::probe_mesh::probe_scenario;
use crate::record::{Recorded, Recorder, Source};
use crate::scenario::{ProbeTrial, Scenario};
use crate::sensor::{Instruments, stated_force_sigma};
use crate::strain::peak_strain;
use crate::truth::{Discretisation, GroundTruth};
use crate::world::World;

/// What a generation did.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Trials written.
    pub trials: usize,
    /// Rows of all `markers.csv` files.
    pub marker_rows: usize,
    /// Rows of all `tool.csv` files.
    pub tool_rows: usize,
    /// Rendered camera frames of all trials.
    pub frames: usize,
    /// Degrees of freedom of the truth.
    pub dofs: usize,
    /// Right-hand sides back-substituted for the needle insertions (kept
    /// columns and full solves, and those of the marker mesh when the needle
    /// is settled there), or Newton solves on a nonlinear phantom.
    pub needle_solves: usize,
    /// Wall time of the whole generation (s).
    pub seconds: f64,
    /// The ground truth that was written.
    pub truth: GroundTruth,
}

/// A stage of the generation, for progress display.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Meshing the phantom.
    Mesh,
    /// Probing trials, `done` of `total`.
    Probes {
        /// Finished.
        done: usize,
        /// All.
        total: usize,
    },
    /// Needle insertions, `done` days of `total` (the insertions run in
    /// parallel, so this is reported once, when they are all done; the
    /// probe trials and their frames are recorded meanwhile).
    Needles {
        /// Finished days.
        done: usize,
        /// All days.
        total: usize,
    },
    /// Recording the needle trials, writing the bundle and the truth.
    Write,
}

/// Generates the campaign of `scenario`: the bundle at `bundle_out` (which
/// must not exist) and the ground truth at `truth_out` (which must not
/// exist and must lie outside the bundle folder).
pub fn generate(
    scenario: &Scenario,
    bundle_out: &Path,
    truth_out: &Path,
    progress: impl Fn(Stage) + Sync,
) -> Result<Summary, SynthError> {
    let started = Instant::now();
    scenario.validate(&scenario.name)?;
    check_truth_path(bundle_out, truth_out)?;
    // `symlink_metadata`: a link to nothing is in the way too, and the
    // writer would refuse it only after the whole run.
    if std::fs::symlink_metadata(bundle_out).is_ok() {
        return Err(SynthError::Bundle(
            needle_data::BundleError::AlreadyExists {
                path: bundle_out.to_path_buf(),
            },
        ));
    }
    progress(Stage::Mesh);
    // Frames and calibration images are rendered here first; the bundle
    // writer copies them.
    let staging = match &scenario.frames {
        Some(_) => Some(Staging::beside(bundle_out)?),
        None => None,
    };
    let camera = TrueCamera::new(scenario);
    // The calibration images need no mechanics: they are rendered on the
    // second core while the phantom is meshed, assembled and factorised.
    let (ready, along_paths) = marker_meshes(scenario);
    let (worlds, calibration) = rayon::join(
        || -> Result<_, SynthError> {
            let world = World::new(scenario)?;
            let marker_world = ready.as_ref().map(World::new).transpose()?;
            Ok((world, marker_world))
        },
        || match (&scenario.frames, &staging) {
            (Some(frames), Some(staging)) => {
                let dir = staging.path().join(needle_data::layout::CALIBRATION);
                write_calibration(scenario, frames, &camera, &dir).map(|truth| Some((truth, dir)))
            }
            _ => Ok(None),
        },
    );
    let ((world, marker_world), calibration) = (worlds?, calibration?);
    let probes = run_probes(&world, &progress)?;
    let probe_days: Vec<f64> = probes.iter().map(|r| r.probe.day).collect();
    let needle_days: Vec<f64> = needle_plans(scenario).iter().map(|p| p.day).collect();
    let p = &scenario.phantom;
    let s = &scenario.sensors;
    let mut builder = BundleBuilder::new(
        scenario.name.clone(),
        Phantom {
            width: p.width,
            depth: p.depth,
            thickness: p.thickness,
            fixed: vec![Face::Back],
        },
    );
    let stated = (s.marker_sigma, stated_force_sigma(s));
    builder.noise(Noise {
        marker_sigma: stated.0,
        force_sigma: stated.1,
    });
    builder.markers_rest(
        world
            .markers
            .iter()
            .enumerate()
            .map(|(id, m)| MarkerRest {
                id: id as u32,
                x: m[0],
                y: m[1],
            })
            .collect(),
    );
    let mut compression_modulus = None;
    if let Some(test) = &scenario.compression {
        let modulus = p.youngs_modulus
            * scenario
                .effects
                .material_stiffening
                .map_or(1.0, |m| m.factor(test.day));
        compression_modulus = Some(modulus);
        let mut instruments = Instruments::new(*s, scenario.seed, u64::MAX);
        let area = test.side * test.side;
        let curve = (0..test.samples)
            .map(|k| {
                let strain = test.max_strain * k as f64 / (test.samples - 1) as f64;
                // Stress as the paper plots it: force over the current area
                // of an incompressible sample (area A0 / stretch).
                let stretch = 1.0 - strain;
                let nominal = if scenario.effects.material_nonlinearity.is_some() {
                    uniaxial_nominal_stress(modulus, p.poisson_ratio, stretch)
                } else {
                    modulus * strain
                };
                let force = instruments.force(nominal * area);
                let stress = if scenario.effects.material_nonlinearity.is_some() {
                    force / area * stretch
                } else {
                    force / area
                };
                CompressionPoint { strain, stress }
            })
            .collect();
        builder.compression(curve);
    }
    let recorder = Recorder {
        world: &world,
        camera: &camera,
        staging: staging.as_ref(),
    };
    let order = campaign_order(&probe_days, &needle_days);
    let jobs = |kind: TrialKind| -> Vec<(usize, usize, usize)> {
        order
            .iter()
            .enumerate()
            .filter(|(_, o)| o.0 == kind)
            .enumerate()
            .map(|(rank, (stream, o))| (stream, o.1, rank))
            .collect()
    };
    // The probe trials (their frames above all) are recorded on the second
    // core while the needles are solved.
    let (needles, probe_trials) = rayon::join(
        || {
            run_needles(
                &world,
                marker_world.as_ref(),
                along_paths.as_ref(),
                &progress,
            )
        },
        || {
            jobs(TrialKind::Probe)
                .par_iter()
                .map(|&(stream, i, rank)| {
                    recorder.record(stream, rank, Source::Probe(&probes[i], i))
                })
                .collect::<Result<Vec<_>, _>>()
        },
    );
    let Needles {
        runs: needles,
        solves: needle_solves,
        marker_mesh_nodes,
        needle_mesh_nodes,
    } = needles?;
    let probe_trials = probe_trials?;
    progress(Stage::Write);
    let needle_trials = jobs(TrialKind::Needle)
        .par_iter()
        .map(|&(stream, i, rank)| recorder.record(stream, rank, Source::Needle(&needles[i], i)))
        .collect::<Result<Vec<_>, _>>()?;
    let mut camera_truth = None;
    if let Some((truth, dir)) = calibration {
        camera_truth = Some(truth);
        builder.calibration_dir(dir);
    }
    let mut truths = Vec::new();
    let (mut marker_rows, mut tool_rows, mut frame_count) = (0, 0, 0);
    let mut recorded: Vec<Recorded> = probe_trials.into_iter().chain(needle_trials).collect();
    recorded.sort_by_key(|r| r.stream);
    for Recorded {
        trial,
        truth,
        frames,
        ..
    } in recorded
    {
        marker_rows += trial.markers.as_ref().map_or(0, |m| m.row_count());
        tool_rows += trial.tool.len();
        frame_count += frames;
        let slot = builder.trial(trial.trial.clone());
        *slot = trial;
        truths.push(truth);
    }
    let truth = GroundTruth {
        bundle: scenario.name.clone(),
        effects: scenario.effects.present(),
        scenario: scenario.clone(),
        discretisation: Discretisation {
            dimension: world.body.dim,
            nodes: world.body.nodes.len(),
            elements: world.body.element_count(),
            element_size: world.body.element_size,
            upper_half: world.body.upper_half,
            marker_mesh_nodes,
            needle_mesh_nodes,
            probe_mesh_nodes: probes.iter().filter_map(|r| r.mesh_nodes).collect(),
        },
        stated_noise: stated,
        trials: truths,
        compression_modulus,
        camera: camera_truth,
    };
    let text = ron::ser::to_string_pretty(&truth, ron::ser::PrettyConfig::default())
        .expect("the ground truth always serialises");
    // The truth first, then the bundle, whose writer publishes it whole by a
    // rename: a run that fails leaves both or neither, never a bundle
    // without its truth (a run killed while the bundle is validated leaves
    // the truth alone, which names what is missing).
    write_new(truth_out, &text)?;
    if let Err(error) = builder.write(bundle_out, WriteOptions::default()) {
        // The file was created by this run (`create_new`), so it is ours to take back.
        let _ = std::fs::remove_file(truth_out);
        return Err(error.into());
    }
    Ok(Summary {
        trials: order.len(),
        marker_rows,
        tool_rows,
        frames: frame_count,
        dofs: world.body.dof_count(),
        needle_solves,
        seconds: started.elapsed().as_secs_f64(),
        truth,
    })
}

/// The noise-free response of one trial: its solved states.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialResponse {
    /// Trial id, as in the bundle.
    pub id: String,
    /// Probe or needle.
    pub kind: TrialKind,
    /// State coordinate: probe indentation or needle tip depth (m).
    pub states: Vec<f64>,
    /// Marker displacements (x, y) at each state (m), markers row-major.
    pub markers: Vec<Vec<[f64; 2]>>,
    /// True force at the tool base at each state (N).
    pub force: Vec<f64>,
    /// Largest principal strain at the last state.
    pub peak_strain: f64,
}

/// The noise-free responses of every trial of `scenario`, in campaign
/// order (no file is written): what the bundle's measurements sample.
pub fn respond(scenario: &Scenario) -> Result<Vec<TrialResponse>, SynthError> {
    scenario.validate(&scenario.name)?;
    let world = World::new(scenario)?;
    let (ready, along_paths) = marker_meshes(scenario);
    let marker_world = ready.as_ref().map(World::new).transpose()?;
    let probes = run_probes(&world, &|_| {})?;
    let needles = run_needles(&world, marker_world.as_ref(), along_paths.as_ref(), &|_| {})?.runs;
    let probe_days: Vec<f64> = probes.iter().map(|r| r.probe.day).collect();
    let needle_days: Vec<f64> = needles.iter().map(|r| r.plan.day).collect();
    Ok(campaign_order(&probe_days, &needle_days)
        .into_iter()
        .map(|(kind, i)| match kind {
            TrialKind::Probe => {
                let r = &probes[i];
                TrialResponse {
                    id: probe_id(i),
                    kind,
                    states: r.indentations.clone(),
                    markers: in_plane(&r.markers),
                    force: r.force.clone(),
                    peak_strain: r.peak_strain,
                }
            }
            _ => {
                let r = &needles[i];
                TrialResponse {
                    id: needle_id(i, &r.plan),
                    kind,
                    states: r.depths.clone(),
                    markers: in_plane(&r.markers),
                    force: r.force.clone(),
                    peak_strain: peak_strain(&world.body, &r.last_displacement),
                }
            }
        })
        .collect())
}

/// The in-plane (x, y) part of marker displacement tables.
fn in_plane(table: &[Vec<[f64; 3]>]) -> Vec<Vec<[f64; 2]>> {
    table
        .iter()
        .map(|state| state.iter().map(|d| [d[0], d[1]]).collect())
        .collect()
}

/// Campaign order of probes and needles on the days `probe_days` and
/// `needle_days`: by day, probes before needles on the same day; each entry
/// is the kind and the index in its list.
fn campaign_order(probe_days: &[f64], needle_days: &[f64]) -> Vec<(TrialKind, usize)> {
    let mut order: Vec<(f64, usize, usize)> = probe_days
        .iter()
        .enumerate()
        .map(|(i, &day)| (day, 0, i))
        .collect();
    order.extend(needle_days.iter().enumerate().map(|(i, &day)| (day, 1, i)));
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    order
        .into_iter()
        .map(|(_, k, i)| {
            (
                if k == 0 {
                    TrialKind::Probe
                } else {
                    TrialKind::Needle
                },
                i,
            )
        })
        .collect()
}

pub(crate) fn probe_id(index: usize) -> String {
    format!("probe-{:02}", index + 1)
}

pub(crate) fn needle_id(index: usize, plan: &crate::scenario::NeedlePlan) -> String {
    format!(
        "needle-{:02}-v{}",
        index + 1,
        (plan.velocity * 1e3).round() as i64
    )
}

fn check_truth_path(bundle_out: &Path, truth_out: &Path) -> Result<(), SynthError> {
    // Compared as the paths will be when written: `..` and links, even to
    // folders that do not exist yet, would otherwise lead the truth inside.
    if resolved(truth_out).starts_with(resolved(bundle_out)) {
        return Err(SynthError::TruthPath {
            path: truth_out.to_path_buf(),
            reason: "lies inside the bundle folder".into(),
        });
    }
    if std::fs::symlink_metadata(truth_out).is_ok() {
        return Err(SynthError::TruthPath {
            path: truth_out.to_path_buf(),
            reason: "already exists; refusing to overwrite".into(),
        });
    }
    // Its folder is made now, so that a folder that cannot be made fails the
    // run before the work, not after it.
    match truth_out.parent() {
        Some(folder) if !folder.as_os_str().is_empty() => {
            std::fs::create_dir_all(folder).map_err(|source| SynthError::Io {
                path: folder.to_path_buf(),
                source,
            })
        }
        _ => Ok(()),
    }
}

/// `path` made absolute, with every link followed (also a link to a folder
/// not made yet) and `.` and `..` applied: the file it will name when
/// written. Parts that do not exist are taken as written.
fn resolved(path: &Path) -> PathBuf {
    use std::path::Component;
    // Links followed before giving up on a loop; Linux's own limit.
    const MOST_LINKS: usize = 40;
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().unwrap_or_default().join(path)
    };
    let mut links = 0;
    let mut out = PathBuf::new();
    let mut rest: Vec<std::ffi::OsString> = absolute
        .components()
        .rev()
        .map(|c| c.as_os_str().to_os_string())
        .collect();
    while let Some(part) = rest.pop() {
        match Path::new(&part).components().next() {
            Some(Component::RootDir | Component::Prefix(_)) => out.push(&part),
            Some(Component::CurDir) | None => {}
            Some(Component::ParentDir) => {
                out.pop();
            }
            Some(Component::Normal(name)) => {
                let next = out.join(name);
                match std::fs::read_link(&next) {
                    Ok(target) if links < MOST_LINKS => {
                        links += 1;
                        // A relative link is read from the folder holding it.
                        let target = if target.is_absolute() {
                            target
                        } else {
                            out.join(target)
                        };
                        rest.extend(
                            target
                                .components()
                                .rev()
                                .map(|c| c.as_os_str().to_os_string()),
                        );
                        out = PathBuf::new();
                    }
                    _ => out = next,
                }
            }
        }
    }
    out
}

fn write_new(path: &Path, text: &str) -> Result<(), SynthError> {
    use std::io::Write;
    let io = |source| SynthError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
        .map_err(io)?;
    file.write_all(text.as_bytes()).map_err(io)
}

fn run_probes(
    world: &World,
    progress: &(impl Fn(Stage) + Sync),
) -> Result<Vec<ProbeRun>, SynthError> {
    let scenario = world.scenario;
    let total = scenario.probes.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let press_one = |probe: &ProbeTrial| {
        let run = match probe_scenario(scenario, probe) {
            Some(own) => World::new(&own).and_then(|alone| {
                let mut run = press(&alone, probe, Factorisation::Own)?;
                run.mesh_nodes = Some(alone.body.nodes.len());
                Ok(run)
            }),
            None => press(world, probe, Factorisation::Shared),
        };
        let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        progress(Stage::Probes { done: d, total });
        run
    };
    // Slabs of their own are pressed one after the other, as the needles'
    // are: each factor is the largest thing in memory (some 10 GB for the
    // fine paper default's probes), and two beside the campaign's slab
    // took more than this machine's 23 GB. Rounded probes' plane meshes
    // of their own are far smaller (`material-nonlinearity.ron` with its
    // probes rounded peaked at 1.3 GB on one thread), and two fit.
    let own_slabs = scenario.effects.out_of_plane.is_some()
        && scenario
            .probes
            .iter()
            .any(|probe| probe_scenario(scenario, probe).is_some());
    if own_slabs {
        scenario.probes.iter().map(press_one).collect()
    } else {
        scenario.probes.par_iter().map(press_one).collect()
    }
}

/// The needle trials in the order they are solved and listed: by day.
fn needle_plans(scenario: &Scenario) -> Vec<crate::scenario::NeedlePlan> {
    let mut plans = scenario.needles.plan();
    plans.sort_by(|a, b| a.day.total_cmp(&b.day));
    plans
}

/// The scenario of the marker mesh (`marker_mesh`), if `scenario` has
/// one: to be meshed before the needles are placed, or (refined locally)
/// for each along the material path it is placed on.
fn marker_meshes(scenario: &Scenario) -> (Option<Scenario>, Option<Scenario>) {
    match marker_scenario(scenario) {
        Some(fine) if follows_paths(&fine) => (None, Some(fine)),
        fine => (fine, None),
    }
}

/// The needle trials, solved.
struct Needles {
    runs: Vec<NeedleRun>,
    /// Right-hand sides solved (see [`Summary::needle_solves`]).
    solves: usize,
    /// Nodes of the mesh they were settled on, if one for all.
    marker_mesh_nodes: Option<usize>,
    /// Nodes of the mesh each was settled on, if each on its own.
    needle_mesh_nodes: Vec<usize>,
}

/// The needle trials placed on `world`, and settled on `marker_world`
/// when the scenario has one (`marker_mesh`), or each on a marker mesh
/// of `along_paths` refined along its own material path on `world`; with
/// the linear solves made.
fn run_needles(
    world: &World,
    marker_world: Option<&World>,
    along_paths: Option<&Scenario>,
    progress: &(impl Fn(Stage) + Sync),
) -> Result<Needles, SynthError> {
    let scenario = world.scenario;
    let plans = needle_plans(scenario);
    let mut days: Vec<f64> = plans.iter().map(|p| p.day).collect();
    days.dedup();
    let responses = days
        .iter()
        .map(|&day| world.response(day))
        .collect::<Result<Vec<_>, _>>()?;
    // Days sharing a factorisation share the response (see `World`).
    let trials: Vec<_> = plans
        .iter()
        .map(|plan| {
            let d = days.partition_point(|&day| day < plan.day);
            (*plan, &responses[d])
        })
        .collect();
    let mut runs = insert(
        world,
        &trials,
        scenario.needles.depth,
        scenario.resolution.depth_step,
    )?;
    let mut solves = runs.iter().map(|r| r.solves).sum();
    let mut marker_mesh_nodes = None;
    let mut needle_mesh_nodes = Vec::new();
    if let Some(fine) = marker_world {
        solves += settle_on(fine, &mut runs)?;
        marker_mesh_nodes = Some(fine.body.nodes.len());
    }
    if let Some(fine) = along_paths {
        // One slab per insertion, refined along its own path: one slab
        // along every path grows with their number (along the fine paper
        // default's ten needle lines, 2.9 M dofs against 0.7 M for one).
        // One at a time, since each factorisation takes gigabytes; each
        // settles its states in parallel.
        for run in runs.iter_mut() {
            let alone = insertion_alone(fine, &run.plan);
            let own = World::along(&alone, &material_paths(std::slice::from_ref(run)))?;
            solves += settle_on(&own, std::slice::from_mut(run))?;
            needle_mesh_nodes.push(own.body.nodes.len());
        }
    }
    progress(Stage::Needles {
        done: days.len(),
        total: days.len(),
    });
    Ok(Needles {
        runs,
        solves,
        marker_mesh_nodes,
        needle_mesh_nodes,
    })
}
