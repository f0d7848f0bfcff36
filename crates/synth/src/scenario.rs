//! The scenario: phantom, material, discretisation, sensors, experiments and
//! hidden effects of one synthetic campaign, read from a RON file.
//!
//! Every struct rejects unknown fields, so a misspelt field is an error that
//! names it; [`Scenario::validate`] then checks every value and names the
//! offending field by its dotted path.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::camera::CameraFrames;
use crate::effect::Effects;
use crate::error::SynthError;

/// One synthetic campaign: what the truth world simulates and measures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Campaign name, written as the bundle name.
    pub name: String,
    /// Seed of every random draw (measurement noise); same seed, same bundle.
    pub seed: u64,
    /// The slab and its material.
    pub phantom: PhantomSpec,
    /// How finely the truth is discretised.
    pub resolution: Resolution,
    /// The needle shaft force distribution without effects.
    pub shaft: Shaft,
    /// Force sensor and camera.
    pub sensors: Sensors,
    /// Unconfined compression test of a separate sample, if done.
    #[serde(default)]
    pub compression: Option<CompressionTest>,
    /// Boundary probing trials on the front face.
    pub probes: Vec<ProbeTrial>,
    /// Needle insertion trials.
    pub needles: Needles,
    /// The physical effects present in the truth.
    pub effects: Effects,
    /// Rendered camera frames and calibration images, if asked for.
    #[serde(default)]
    pub frames: Option<CameraFrames>,
}

/// The phantom slab and its (baseline) material.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhantomSpec {
    /// Extent along x (m).
    pub width: f64,
    /// Extent along y, the insertion direction (m).
    pub depth: f64,
    /// Extent along z (m).
    pub thickness: f64,
    /// Young's modulus on day 0 (Pa).
    pub youngs_modulus: f64,
    /// Poisson's ratio.
    pub poisson_ratio: f64,
    /// Marker grid on the top face, `(columns along x, rows along y)`,
    /// spanning the whole face; ids row-major from `y = 0`.
    pub markers: (usize, usize),
}

impl PhantomSpec {
    /// The least Young's modulus accepted (Pa): the softest gels that
    /// hold their shape are tens of pascals (brain tissue about a
    /// kilopascal, the paper's PVC 25 kPa); below a pascal a phantom is
    /// no solid, and its field overflows under a needle's load.
    pub const MIN_YOUNGS_MODULUS: f64 = 1.0;
}

/// Discretisation of the truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Resolution {
    /// Element edge length in x and y is the marker spacing divided by this.
    pub refinement: usize,
    /// Element layers through the thickness (3-D truth only; even, so that
    /// the mid-plane carrying the needle is a node plane).
    pub layers: usize,
    /// Tip depth between two solved states of a needle insertion (m),
    /// halved over the first `needle::ENTRY_DEPTH`; camera frames and
    /// sensor samples in between are interpolated by cubics in depth
    /// (`interpolate`).
    pub depth_step: f64,
    /// Length of one shaft integration segment (m); two Gauss points each.
    pub shaft_step: f64,
    /// Indentation between two solved states of a probe with the nonlinear
    /// material (m); the linear truth is exactly proportional to it.
    pub indentation_step: f64,
    /// Grading of the 3-D slab's mesh; absent, [`SlabGrading::DEFAULT`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slab_grading: Option<SlabGrading>,
    /// Levels of halving of the plane-strain truth's elements towards its
    /// singular lines (the probe edges, the sides, the front and back
    /// faces; `grid::grade`), at most [`Resolution::MAX_PLANE_GRADING`];
    /// absent, 7 for the linear material and 3 for the neo-Hookean one,
    /// whose Newton solve crushes finer corner elements (`grid`). A mesh
    /// convergence study sets it; a campaign need not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane_grading: Option<usize>,
    /// Grading of a second, finer slab mesh on which the needle trials
    /// are settled (3-D linear truth only; ignored by the plane-strain and
    /// neo-Hookean truths): the needle is placed on the slab of
    /// `slab_grading` first, and every state's consistency iteration goes
    /// on from the loads found there on this mesh, where the markers and
    /// the base force are read (`marker_mesh`). Absent, the placement
    /// mesh's are kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub marker_grading: Option<SlabGrading>,
    /// Grading of the slab each probe is pressed on alone (3-D linear
    /// truth only; ignored by the plane-strain and neo-Hookean truths):
    /// its own slab, with no needle lines, graded towards its edges by
    /// `probe_edges` (`probe_mesh`). Absent, the probes are pressed on
    /// the slab of `slab_grading`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_grading: Option<SlabGrading>,
}

impl Resolution {
    /// The most levels of `plane_grading` accepted: elements of $h/1024$
    /// at the singular lines, finer than any study has needed (the finest
    /// reference, refinement 12 with 8 levels, `docs/truth-world.md`).
    pub const MAX_PLANE_GRADING: usize = 10;

    /// The most depth intervals of an insertion (`depth_step`), shaft
    /// segments over its final depth (`shaft_step`) and indentation
    /// states of a probe (`indentation_step`) accepted: 50 times the
    /// fixtures' most (100 shaft segments). Each state is a solve of the
    /// phantom and each segment two Newton solves in every consistency
    /// iteration, and an insertion keeps every state's loaded points:
    /// at this bound about 0.8 GB, where steps of a picometre asked for
    /// more memory than there is and the process was killed.
    pub const MAX_STEPS: usize = 5_000;
}

/// Levels of halving of the 3-D slab's elements towards lines where its
/// displacement is singular or steep (`grid::grade`): level $L$ adds grid
/// lines at $c \pm h/2^k$, $k = 1..L$, around each such coordinate $c$.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlabGrading {
    /// In the plane, towards the front and back faces (in y) and the
    /// sides (in x): the clamped back face's corners and the free front
    /// face where the needle's line load ends.
    pub faces: usize,
    /// In x, towards every needle line.
    pub needle_lines: usize,
    /// Through the thickness, towards the mid-plane (the needle's load).
    pub mid_plane: usize,
    /// Through the thickness, towards the top face (the markers).
    pub top_face: usize,
    /// In x, towards both edges of every probe (a rigid flat punch, whose
    /// strain grows like $r^{-1/2}$ towards its edges), and in y towards
    /// the front face it presses on, by as many levels; absent, 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub probe_edges: usize,
    /// The mesh refined locally, an octree (or a quadtree extruded
    /// through the node planes) on the cells of the graded tensor grid
    /// (`local_mesh`); absent, the tensor grid alone, cut into six
    /// tetrahedra per cell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub local: Option<LocalRefinement>,
}

fn is_zero(levels: &usize) -> bool {
    *levels == 0
}

fn is_false(flag: &bool) -> bool {
    !flag
}

impl SlabGrading {
    /// The grading of a scenario that states none: two levels towards the
    /// faces and sides, uniform layers (the paper default states a finer
    /// one; measured in `docs/truth-world.md`, The 3-D slab).
    pub const DEFAULT: Self = Self {
        faces: 2,
        needle_lines: 0,
        mid_plane: 0,
        top_face: 0,
        probe_edges: 0,
        local: None,
    };

    /// The most levels of any kind: elements down to $h/1024$ (a probe
    /// edge's reference in the convergence test takes 9).
    pub const MAX_LEVELS: usize = 10;
}

/// Local refinement of the 3-D slab's mesh (`local_mesh`): each cell of
/// the tensor grid is halved, as an octree, until it is no larger than
/// $\max(h_f, g\,d_f)$ for every feature $f$, at distance $d_f$ with
/// $h_f$ the marker spacing over the refinement, halved `levels` times.
/// The features are where the slab's displacement is singular or steep.
/// In `resolution.marker_grading` the needle's features are where the
/// placement found its loads in the material, and each insertion is
/// settled on a slab of its own (`marker_mesh`); elsewhere they are on
/// the needle's line. With `plan_only` the cells are halved in the plan
/// alone, a quadtree extruded through the node planes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LocalRefinement {
    /// The grid under the octree: cells the marker spacing over this
    /// refinement (absent: `resolution.refinement`). The octree halves
    /// cells along all three axes, so a grid whose cells are twice as
    /// wide as the layers are thick stays so down to its finest cells.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refinement: Option<usize>,
    /// Levels along every needle's path, from the front face to its final
    /// tip depth (the line load's field is $\sim \ln r$ towards it).
    pub needle_paths: usize,
    /// Levels at every needle's entry, where the line load meets the free
    /// front face and sets the force, and at its final tip.
    pub needle_ends: usize,
    /// Levels along the edges of the clamped back face with the free top
    /// face and sides, where the displacement is singular.
    pub back_face: usize,
    /// Levels at the edges of every probe on the front face.
    pub probe_edges: usize,
    /// Levels everywhere: the largest cell, far from every feature, is
    /// the grid's cell halved this many times (0: the grid's cell).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub far_field: usize,
    /// Cells halved in the plan alone, along x and y, with distances
    /// measured in the plan: one quadtree for every layer, extruded
    /// through the grid's node planes. For features singular uniformly
    /// through the thickness (a probe's edges), at a fraction of the
    /// octree's cells; not for a needle, whose line load is singular in
    /// its cross-section.
    #[serde(default, skip_serializing_if = "is_false")]
    pub plan_only: bool,
    /// The grading $g$: the largest cell over its distance to a feature;
    /// smaller is finer. 0.25 to 4.
    pub grading: f64,
}

impl LocalRefinement {
    /// The range of [`LocalRefinement::grading`] accepted: from cells a
    /// quarter of their distance to cells four times it.
    pub const GRADING: (f64, f64) = (0.25, 4.0);
}

/// Shaft force density without effects.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shaft {
    /// Axial force per unit shaft length at the reference velocity (N/m).
    pub density: f64,
    /// Insertion velocity at which `density` holds (m/s).
    pub reference_velocity: f64,
}

/// The force sensor and the camera.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sensors {
    /// Force sensor sample rate (Hz).
    pub force_rate: f64,
    /// Force quantisation step (N), 0.0125 for the paper's ATI Nano-17.
    pub force_resolution: f64,
    /// Gaussian force noise before quantisation, one sigma (N).
    pub force_sigma: f64,
    /// Camera frame rate (Hz).
    pub camera_rate: f64,
    /// Gaussian tracking noise per coordinate, one sigma (m).
    pub marker_sigma: f64,
}

impl Sensors {
    /// The highest force sensor or camera rate accepted (Hz): a
    /// megahertz, a hundred times a fast force sensor's (the Nano-17's
    /// 7 kHz) or a high-speed camera's (the paper's 100 Hz and 30 Hz).
    pub const MAX_RATE: f64 = 1e6;
}

/// An unconfined compression test of a block cut from the same material.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompressionTest {
    /// Side of the square cross-section (m).
    pub side: f64,
    /// Height along the loading axis (m).
    pub height: f64,
    /// Largest compressive engineering strain.
    pub max_strain: f64,
    /// Number of curve points from 0 to `max_strain`.
    pub samples: usize,
    /// Day of the test since casting.
    pub day: f64,
}

/// A blunt probe pressed on the front face `y = 0`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProbeTrial {
    /// Centre of the probe on the front face (m).
    pub x: f64,
    /// Final indentation along +y (m).
    pub indentation: f64,
    /// Indentation speed (m/s).
    pub velocity: f64,
    /// Width of the flat probe face along x (m); it spans the thickness.
    pub width: f64,
    /// Day of the trial.
    pub day: f64,
    /// Radius of the probe's rounded edges (m), above zero and at most half
    /// its width. Absent, the edges are sharp and the nodes under the face
    /// are held (a flat punch, `probe`); present, the probe touches the
    /// phantom in frictionless contact, face, edges and sides (`contact`),
    /// which the truth solves for the neo-Hookean material
    /// (`material_nonlinearity`) only, in depth steps best no larger than
    /// half the radius (`resolution.indentation_step`). Its edges also
    /// push the face sideways where it slides, which the sensor reads as
    /// `fx`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_radius: Option<f64>,
}

/// The needle insertions: every velocity once per day in `days`, each
/// along its own line `x = first_line + k * line_spacing`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Needles {
    /// Insertion velocities (m/s); none for a campaign without
    /// insertions.
    pub velocities: Vec<f64>,
    /// One repeat of all velocities per entry (days since casting).
    pub days: Vec<f64>,
    /// Final tip depth (m).
    pub depth: f64,
    /// x of the first insertion line (m).
    pub first_line: f64,
    /// Distance between consecutive insertion lines (m).
    pub line_spacing: f64,
    /// Radius of the needle (m), 0 for a line. In the 3-D slab a needle
    /// of radius $a$ drags the tissue on its surface: the displacement
    /// that places its load is read there, not on its axis (`needle.rs`).
    /// A line load's field is singular at the line, so a drag read on the
    /// axis, and the markers near it, change with every refinement
    /// towards it, where a radius gives a limit. The plane-strain truth
    /// ignores it.
    #[serde(default)]
    pub radius: f64,
}

/// One needle trial as the campaign runs it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NeedlePlan {
    /// x of the insertion line (m).
    pub line: f64,
    /// Insertion velocity (m/s).
    pub velocity: f64,
    /// Day of the trial.
    pub day: f64,
}

impl Needles {
    /// The needle trials in campaign order: day by day, velocities in the
    /// listed order, each on the next unused line.
    pub fn plan(&self) -> Vec<NeedlePlan> {
        let mut plans = Vec::new();
        for &day in &self.days {
            for &velocity in &self.velocities {
                let line = self.first_line + plans.len() as f64 * self.line_spacing;
                plans.push(NeedlePlan {
                    line,
                    velocity,
                    day,
                });
            }
        }
        plans
    }
}

/// Reads and validates a scenario file.
pub fn load_scenario(path: impl AsRef<Path>) -> Result<Scenario, SynthError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|source| SynthError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    // Spreadsheets and Windows editors start UTF-8 files with a byte-order
    // mark, which RON reads as a stray character before the struct.
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let scenario: Scenario = ron::from_str(text).map_err(|e| SynthError::Parse {
        path: path.to_path_buf(),
        line: e.span.start.line,
        column: e.span.start.col,
        message: e.code.to_string(),
    })?;
    scenario
        .validate(&path.display().to_string())
        .map_err(|error| match error {
            SynthError::InvalidField {
                source_name,
                field,
                reason,
                ..
            } => SynthError::InvalidField {
                line: line_of_field(text, &field),
                source_name,
                field,
                reason,
            },
            other => other,
        })?;
    Ok(scenario)
}

/// The line of `field` (`probes[1].day`) in the scenario `text`: of the
/// field itself, else of the nearest field holding it (a list's element,
/// `needles.days[1]`, is at its list's line or after; a field a scenario
/// leaves to its default is not in the file at all).
fn line_of_field(text: &str, field: &str) -> Option<u64> {
    let lines = needle_data::ron_field_lines(text);
    let mut path = field;
    loop {
        if let Some(&line) = lines.get(path) {
            return Some(line);
        }
        path = &path[..path.rfind(['.', '['])?];
    }
}

/// Checks scenario values and names the field that fails. Values are
/// quoted with `{:?}`, which writes 1e300 so and not in 301 digits.
pub struct FieldChecker<'a> {
    source: &'a str,
}

impl FieldChecker<'_> {
    /// Fails with the field's name and `reason` unless `ok`.
    pub fn check(
        &self,
        ok: bool,
        field: &str,
        reason: impl FnOnce() -> String,
    ) -> Result<(), SynthError> {
        if ok {
            Ok(())
        } else {
            Err(SynthError::InvalidField {
                source_name: self.source.to_string(),
                line: None,
                field: field.to_string(),
                reason: reason(),
            })
        }
    }

    /// The value must be positive and finite.
    pub fn positive(&self, value: f64, field: &str) -> Result<(), SynthError> {
        self.check(value.is_finite() && value > 0.0, field, || {
            format!("must be positive and finite, got {value:?}")
        })
    }

    /// The value must be non-negative and finite.
    pub fn non_negative(&self, value: f64, field: &str) -> Result<(), SynthError> {
        self.check(value.is_finite() && value >= 0.0, field, || {
            format!("must be non-negative and finite, got {value:?}")
        })
    }

    /// The value must lie in the open interval.
    pub fn within(&self, value: f64, lo: f64, hi: f64, field: &str) -> Result<(), SynthError> {
        self.check(value.is_finite() && value > lo && value < hi, field, || {
            format!("must lie strictly between {lo} and {hi}, got {value:?}")
        })
    }
}

impl Scenario {
    /// The latest day of a trial or the compression test accepted: ten
    /// years after casting, beyond any campaign on one phantom.
    pub const MAX_DAY: f64 = 3650.0;

    /// The range of the stiffening factor $1 + r\,d$
    /// (`effects.material_stiffening`) accepted on every day a trial or
    /// the compression test is done: the paper measured 6 % over several
    /// days, and a modulus fallen to a tenth or grown tenfold is no longer
    /// the phantom that linear law extrapolates (nor, below zero, a
    /// solid at all).
    pub const STIFFENING_FACTOR: (f64, f64) = (0.1, 10.0);

    /// The most rows of one table a trial writes (its force samples, or
    /// its camera frames times the markers) or points of the compression
    /// curve accepted: 15 times the fixtures' most, the markers of an
    /// insertion of 50 s at 1 mm/s (1501 frames of 441 markers), and
    /// some 0.5 GB of a table, where a rate or velocity far out asked for
    /// more memory than there is and the process was killed.
    pub const MAX_ROWS: usize = 10_000_000;

    /// Every day a trial or the compression test is done, with its field.
    fn days(&self) -> Vec<(String, f64)> {
        let compression = self
            .compression
            .iter()
            .map(|t| ("compression.day".to_string(), t.day));
        let probes = self
            .probes
            .iter()
            .enumerate()
            .map(|(i, probe)| (format!("probes[{i}].day"), probe.day));
        let needles = self
            .needles
            .days
            .iter()
            .enumerate()
            .map(|(i, &day)| (format!("needles.days[{i}]"), day));
        compression.chain(probes).chain(needles).collect()
    }

    /// Checks that a trial of `duration` (s) writes at most
    /// [`Scenario::MAX_ROWS`] force samples and marker rows; `field` is
    /// the velocity that sets its duration.
    fn check_rows(
        &self,
        c: &FieldChecker<'_>,
        duration: f64,
        field: &str,
    ) -> Result<(), SynthError> {
        let s = &self.sensors;
        let samples = (duration * s.force_rate).floor() + 1.0;
        c.check(samples <= Self::MAX_ROWS as f64, field, || {
            format!(
                "a trial of {duration} s gives {samples} force samples at \
                 sensors.force_rate {} Hz, above the {} accepted",
                s.force_rate,
                Self::MAX_ROWS
            )
        })?;
        let markers = self.phantom.markers.0 as f64 * self.phantom.markers.1 as f64;
        let rows = ((duration * s.camera_rate).floor() + 1.0) * markers;
        c.check(rows <= Self::MAX_ROWS as f64, field, || {
            format!(
                "a trial of {duration} s gives {rows} marker rows at sensors.camera_rate {} \
                 Hz with {markers} markers, above the {} accepted",
                s.camera_rate,
                Self::MAX_ROWS
            )
        })
    }

    /// Checks every field; `source` names the file (or the scenario) in
    /// the error.
    pub fn validate(&self, source: &str) -> Result<(), SynthError> {
        let c = FieldChecker { source };
        let day = |day: f64, field: &str| {
            c.check((0.0..=Self::MAX_DAY).contains(&day), field, || {
                format!(
                    "must be 0 to {} days (ten years) after casting, got {day:?}",
                    Self::MAX_DAY
                )
            })
        };
        let p = &self.phantom;
        c.positive(p.width, "phantom.width")?;
        c.positive(p.depth, "phantom.depth")?;
        c.positive(p.thickness, "phantom.thickness")?;
        c.check(
            p.youngs_modulus.is_finite() && p.youngs_modulus >= PhantomSpec::MIN_YOUNGS_MODULUS,
            "phantom.youngs_modulus",
            || {
                format!(
                    "must be finite and at least {} Pa, got {:?}",
                    PhantomSpec::MIN_YOUNGS_MODULUS,
                    p.youngs_modulus
                )
            },
        )?;
        c.within(p.poisson_ratio, -1.0, 0.5, "phantom.poisson_ratio")?;
        c.check(
            p.markers.0 >= 2 && p.markers.1 >= 2,
            "phantom.markers",
            || format!("needs at least 2 x 2 markers, got {:?}", p.markers),
        )?;
        let r = &self.resolution;
        c.check(
            (1..=16).contains(&r.refinement),
            "resolution.refinement",
            || format!("must be 1 to 16, got {}", r.refinement),
        )?;
        c.check(
            r.layers >= 2 && r.layers.is_multiple_of(2) && r.layers <= 16,
            "resolution.layers",
            || {
                format!(
                    "must be even, 2 to 16 (the mid-plane is a node plane), got {}",
                    r.layers
                )
            },
        )?;
        for (field, grading) in [
            ("resolution.slab_grading", &r.slab_grading),
            ("resolution.marker_grading", &r.marker_grading),
            ("resolution.probe_grading", &r.probe_grading),
        ] {
            if let Some(g) = grading {
                let levels = [
                    g.faces,
                    g.needle_lines,
                    g.mid_plane,
                    g.top_face,
                    g.probe_edges,
                ];
                c.check(
                    levels.iter().all(|&l| l <= SlabGrading::MAX_LEVELS),
                    field,
                    || {
                        format!(
                            "levels must be 0 to {}, got {levels:?}",
                            SlabGrading::MAX_LEVELS
                        )
                    },
                )?;
                if let Some(local) = &g.local {
                    let levels = [
                        local.needle_paths,
                        local.needle_ends,
                        local.back_face,
                        local.probe_edges,
                        local.far_field,
                    ];
                    c.check(
                        levels.iter().all(|&l| l <= SlabGrading::MAX_LEVELS),
                        &format!("{field}.local"),
                        || {
                            format!(
                                "levels must be 0 to {}, got {levels:?}",
                                SlabGrading::MAX_LEVELS
                            )
                        },
                    )?;
                    if let Some(refinement) = local.refinement {
                        c.check(
                            (1..=16).contains(&refinement),
                            &format!("{field}.local.refinement"),
                            || format!("must be 1 to 16, got {refinement}"),
                        )?;
                    }
                    let (lo, hi) = LocalRefinement::GRADING;
                    c.check(
                        (lo..=hi).contains(&local.grading),
                        &format!("{field}.local.grading"),
                        || format!("must be {lo} to {hi}, got {:?}", local.grading),
                    )?;
                }
            }
        }
        if let Some(levels) = r.plane_grading {
            c.check(
                levels <= Resolution::MAX_PLANE_GRADING,
                "resolution.plane_grading",
                || {
                    format!(
                        "levels must be 0 to {}, got {levels}",
                        Resolution::MAX_PLANE_GRADING
                    )
                },
            )?;
        }
        c.positive(r.depth_step, "resolution.depth_step")?;
        c.positive(r.shaft_step, "resolution.shaft_step")?;
        c.positive(r.indentation_step, "resolution.indentation_step")?;
        c.positive(self.shaft.density, "shaft.density")?;
        c.positive(self.shaft.reference_velocity, "shaft.reference_velocity")?;
        let s = &self.sensors;
        for (rate, field) in [
            (s.force_rate, "sensors.force_rate"),
            (s.camera_rate, "sensors.camera_rate"),
        ] {
            c.within(rate, 0.0, Sensors::MAX_RATE, field)?;
        }
        c.non_negative(s.force_resolution, "sensors.force_resolution")?;
        c.non_negative(s.force_sigma, "sensors.force_sigma")?;
        c.non_negative(s.marker_sigma, "sensors.marker_sigma")?;
        if let Some(t) = &self.compression {
            c.positive(t.side, "compression.side")?;
            c.positive(t.height, "compression.height")?;
            c.within(t.max_strain, 0.0, 0.6, "compression.max_strain")?;
            c.check(
                (2..=Self::MAX_ROWS).contains(&t.samples),
                "compression.samples",
                || format!("must be 2 to {} points, got {}", Self::MAX_ROWS, t.samples),
            )?;
            day(t.day, "compression.day")?;
        }
        for (i, probe) in self.probes.iter().enumerate() {
            let f = |name: &str| format!("probes[{i}].{name}");
            c.positive(probe.width, &f("width"))?;
            c.check(
                probe.x - probe.width / 2.0 > 0.0 && probe.x + probe.width / 2.0 < p.width,
                &f("x"),
                || {
                    format!(
                        "probe face [{}, {}] leaves the front face [0, {}]",
                        probe.x - probe.width / 2.0,
                        probe.x + probe.width / 2.0,
                        p.width
                    )
                },
            )?;
            c.within(probe.indentation, 0.0, 0.25 * p.depth, &f("indentation"))?;
            if let Some(radius) = probe.edge_radius {
                c.check(
                    radius.is_finite() && radius > 0.0 && radius <= probe.width / 2.0,
                    &f("edge_radius"),
                    || {
                        format!(
                            "must lie in (0, half the width {}], got {radius:?}",
                            probe.width / 2.0
                        )
                    },
                )?;
                c.check(
                    self.effects.material_nonlinearity.is_some(),
                    &f("edge_radius"),
                    || {
                        "a probe with rounded edges is solved in contact, which the truth \
                         does for the neo-Hookean material (material_nonlinearity) only"
                            .into()
                    },
                )?;
            }
            c.positive(probe.velocity, &f("velocity"))?;
            self.check_rows(&c, probe.indentation / probe.velocity, &f("velocity"))?;
            day(probe.day, &f("day"))?;
            let states = (probe.indentation / r.indentation_step).ceil();
            c.check(
                states <= Resolution::MAX_STEPS as f64,
                "resolution.indentation_step",
                || {
                    format!(
                        "gives {states} states to the indentation {} m of {}, above the {} \
                         accepted",
                        probe.indentation,
                        f("indentation"),
                        Resolution::MAX_STEPS
                    )
                },
            )?;
        }
        // No velocities (or no days) is a campaign without insertions.
        let n = &self.needles;
        c.within(n.depth, 0.0, p.depth, "needles.depth")?;
        for (i, &v) in n.velocities.iter().enumerate() {
            let field = format!("needles.velocities[{i}]");
            c.positive(v, &field)?;
            self.check_rows(&c, n.depth / v, &field)?;
        }
        for (i, &d) in n.days.iter().enumerate() {
            day(d, &format!("needles.days[{i}]"))?;
        }
        for (step, field) in [
            (r.depth_step, "resolution.depth_step"),
            (r.shaft_step, "resolution.shaft_step"),
        ] {
            let count = (n.depth / step).ceil();
            c.check(count <= Resolution::MAX_STEPS as f64, field, || {
                format!(
                    "splits the needle depth {} m into {count} steps, above the {} accepted",
                    n.depth,
                    Resolution::MAX_STEPS
                )
            })?;
        }
        c.positive(n.line_spacing, "needles.line_spacing")?;
        // The rim must stay inside the slab, clear of its faces.
        c.check(
            n.radius.is_finite() && n.radius >= 0.0 && n.radius < 0.25 * p.thickness,
            "needles.radius",
            || {
                format!(
                    "must be non-negative and below a quarter of the thickness {}, got {:?}",
                    p.thickness, n.radius
                )
            },
        )?;
        // A line closer to the previous than the needle's diameter runs
        // through its hole, where every insertion is meant in fresh
        // material.
        c.check(
            n.line_spacing >= 2.0 * n.radius,
            "needles.line_spacing",
            || {
                format!(
                    "must be at least the needle's diameter {}, got {:?}",
                    2.0 * n.radius,
                    n.line_spacing
                )
            },
        )?;
        // The rim strictly inside the side faces: the tissue between the
        // needle and a face must not vanish.
        if let Some(last) = n.plan().last() {
            c.check(
                n.first_line - n.radius > 0.0 && last.line + n.radius < p.width,
                "needles.first_line",
                || {
                    format!(
                        "insertion lines {} .. {} of a needle of radius {} leave the phantom \
                         width {}",
                        n.first_line, last.line, n.radius, p.width
                    )
                },
            )?;
        }
        self.effects.validate(&c, self)?;
        if let Some(stiffening) = &self.effects.material_stiffening {
            let (lo, hi) = Self::STIFFENING_FACTOR;
            for (field, on) in self.days() {
                let factor = stiffening.factor(on);
                c.check((lo..=hi).contains(&factor), &field, || {
                    format!(
                        "the modulus factor 1 + rate_per_day * day = {factor} on day {on} \
                         (effects.material_stiffening.rate_per_day {}) must be {lo} to {hi}",
                        stiffening.rate_per_day
                    )
                })?;
            }
        }
        if let Some(frames) = &self.frames {
            frames.check(&c, self)?;
        }
        Ok(())
    }

    /// Writes the scenario as pretty RON.
    pub fn to_ron(&self) -> String {
        ron::ser::to_string_pretty(self, ron::ser::PrettyConfig::default().struct_names(true))
            .expect("a scenario always serialises")
    }
}
