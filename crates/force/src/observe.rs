//! What an insertion trial measured, frame by frame, in the form the
//! estimators use: marker displacements from rest, the needle tip and the
//! base force interpolated to each camera frame's time.
//!
//! Sensor samples (`tool.csv`) and camera frames (`markers.csv`) run on
//! different clocks; the tool pose and force are interpolated linearly to
//! each frame time, and frames outside the tool samples' time span are
//! dropped. Only frames with the tip inside the phantom (tip y > 0) are kept.

use needle_data::{LoadedBundle, MarkerSet, Phantom, TrialKind};

use crate::error::ForceError;

/// The markers at rest, in a fixed order (the order of `markers_rest.csv`),
/// and the rectangular grid they form when they form one.
#[derive(Debug, Clone, PartialEq)]
pub struct MarkerLayout {
    /// Marker ids.
    pub ids: Vec<u32>,
    /// Rest positions (x, y) on the top face (m), aligned with `ids`.
    pub rest: Vec<[f64; 2]>,
}

/// A rectangular marker grid: distinct x and y coordinates, and for every
/// grid point (row-major, x fastest) the index of its marker in the layout.
#[derive(Debug, Clone, PartialEq)]
pub struct GridIndex {
    /// Distinct marker x coordinates, ascending.
    pub x: Vec<f64>,
    /// Distinct marker y coordinates, ascending.
    pub y: Vec<f64>,
    /// `marker[j * x.len() + i]` is the layout index of the marker at `(x[i], y[j])`.
    pub marker: Vec<usize>,
}

impl GridIndex {
    /// The smallest spacing between grid lines in x or y (m).
    pub fn spacing(&self) -> f64 {
        let gap = |v: &[f64]| {
            v.windows(2)
                .map(|w| w[1] - w[0])
                .fold(f64::INFINITY, f64::min)
        };
        gap(&self.x).min(gap(&self.y))
    }

    /// The grid as `needle-fem`'s marker grid.
    pub fn marker_grid(&self) -> needle_fem::mesh::MarkerGrid {
        needle_fem::mesh::MarkerGrid {
            x: self.x.clone(),
            y: self.y.clone(),
        }
    }
}

impl MarkerLayout {
    /// The layout of a bundle's `markers_rest.csv`.
    pub fn from_markers(markers: &MarkerSet) -> Self {
        let rows = markers.as_slice();
        Self {
            ids: rows.iter().map(|m| m.id).collect(),
            rest: rows.iter().map(|m| [m.x, m.y]).collect(),
        }
    }

    /// Number of markers.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// True when there is no marker.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// The rectangular grid the markers form: every combination of the
    /// distinct x and y coordinates holds exactly one marker. Coordinates
    /// closer than $10^{-6}$ of the layout's extent count as equal.
    pub fn grid(&self) -> Result<GridIndex, ForceError> {
        if self.len() < 4 {
            return Err(ForceError::TooFewMarkers {
                context: "marker grid",
                found: self.len(),
                required: 4,
            });
        }
        let extent = self
            .rest
            .iter()
            .flat_map(|p| p.iter().map(|c| c.abs()))
            .fold(0.0_f64, f64::max)
            .max(f64::MIN_POSITIVE);
        let tolerance = 1e-6 * extent;
        let distinct = |axis: usize| {
            let mut values: Vec<f64> = self.rest.iter().map(|p| p[axis]).collect();
            values.sort_by(f64::total_cmp);
            let mut lines: Vec<f64> = Vec::new();
            for v in values {
                if lines.last().is_none_or(|&last| v - last > tolerance) {
                    lines.push(v);
                }
            }
            lines
        };
        let (x, y) = (distinct(0), distinct(1));
        if x.len() < 2 || y.len() < 2 {
            return Err(ForceError::NotAGrid {
                detail: format!("{} column(s) and {} row(s)", x.len(), y.len()),
            });
        }
        if x.len() * y.len() != self.len() {
            return Err(ForceError::NotAGrid {
                detail: format!(
                    "{} markers on {} columns x {} rows",
                    self.len(),
                    x.len(),
                    y.len()
                ),
            });
        }
        let locate = |lines: &[f64], v: f64| lines.iter().position(|&l| (l - v).abs() <= tolerance);
        let mut marker = vec![usize::MAX; self.len()];
        for (k, p) in self.rest.iter().enumerate() {
            let (Some(i), Some(j)) = (locate(&x, p[0]), locate(&y, p[1])) else {
                return Err(ForceError::NotAGrid {
                    detail: format!("marker {} is off the grid lines", self.ids[k]),
                });
            };
            let slot = &mut marker[j * x.len() + i];
            if *slot != usize::MAX {
                return Err(ForceError::NotAGrid {
                    detail: format!(
                        "markers {} and {} share a grid point",
                        self.ids[*slot], self.ids[k]
                    ),
                });
            }
            *slot = k;
        }
        Ok(GridIndex { x, y, marker })
    }
}

/// One camera frame of an insertion, reduced to what the estimators use.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Frame time since the trial began (s).
    pub t: f64,
    /// Needle tip position in the mid-plane, spatial (m).
    pub tip: [f64; 2],
    /// Needle axis angle from +y, counter-clockwise (rad).
    pub theta: f64,
    /// Force the needle applies to the phantom, measured at its base (N).
    pub base_force: [f64; 2],
    /// Displacement of every layout marker from rest (m); `None` where the
    /// marker was not tracked in this frame.
    pub displacement: Vec<Option<[f64; 2]>>,
    /// Tracking standard deviation per marker and coordinate (m), when the
    /// track gives it.
    pub sigma: Option<Vec<Option<[f64; 2]>>>,
}

impl Frame {
    /// The unit vector of the needle axis, pointing into the phantom.
    pub fn axis(&self) -> [f64; 2] {
        [-self.theta.sin(), self.theta.cos()]
    }

    /// Number of markers tracked in this frame.
    pub fn tracked(&self) -> usize {
        self.displacement.iter().flatten().count()
    }
}

/// A needle insertion trial: its frames in contact, in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct Insertion {
    /// Trial id.
    pub trial: String,
    /// Commanded insertion speed (m/s).
    pub velocity: f64,
    /// The phantom.
    pub phantom: Phantom,
    /// Stated marker noise, one standard deviation per coordinate (m), if the
    /// manifest gives one.
    pub marker_sigma: Option<f64>,
    /// The markers at rest.
    pub layout: MarkerLayout,
    /// Frames with the tip inside the phantom, in time order.
    pub frames: Vec<Frame>,
}

/// Reads needle trial `trial` of a bundle into an [`Insertion`].
///
/// Errors: unknown trial, a trial that is not a needle insertion, no tracked
/// markers or tool samples, fewer than 4 markers at rest, or no frame with the
/// tip inside the phantom.
pub fn observe_insertion(bundle: &LoadedBundle, trial: &str) -> Result<Insertion, ForceError> {
    let campaign = &bundle.campaign;
    let data = campaign
        .trial(trial)
        .ok_or_else(|| ForceError::UnknownTrial {
            trial: trial.into(),
        })?;
    if data.trial.kind != TrialKind::Needle {
        return Err(ForceError::NotANeedleTrial {
            trial: trial.into(),
            kind: format!("{:?}", data.trial.kind),
        });
    }
    let track = data.markers.as_ref().ok_or_else(|| ForceError::NoMarkers {
        trial: trial.into(),
    })?;
    if data.tool.is_empty() {
        return Err(ForceError::NoToolSamples {
            trial: trial.into(),
        });
    }
    let layout = MarkerLayout::from_markers(&campaign.markers_rest);
    if layout.len() < 4 {
        return Err(ForceError::TooFewMarkers {
            context: "markers_rest.csv",
            found: layout.len(),
            required: 4,
        });
    }
    let index_of = |id: u32| campaign.markers_rest.index_of(id);
    let mut frames = Vec::new();
    for view in track.frames() {
        let Some(sample) = interpolate_tool(&data.tool, view.t) else {
            continue;
        };
        if sample.tip_y <= 0.0 {
            continue;
        }
        let mut displacement = vec![None; layout.len()];
        let mut sigma = view.sigmas.map(|_| vec![None; layout.len()]);
        for (row, (id, position)) in view.iter().enumerate() {
            let Some(k) = index_of(id) else { continue };
            let rest = layout.rest[k];
            displacement[k] = Some([position[0] - rest[0], position[1] - rest[1]]);
            if let (Some(all), Some(given)) = (sigma.as_mut(), view.sigmas) {
                all[k] = Some(given[row]);
            }
        }
        frames.push(Frame {
            t: view.t,
            tip: [sample.tip_x, sample.tip_y],
            theta: sample.theta,
            base_force: [sample.fx, sample.fy],
            displacement,
            sigma,
        });
    }
    if frames.is_empty() {
        return Err(ForceError::NoFramesInContact {
            trial: trial.into(),
        });
    }
    Ok(Insertion {
        trial: trial.into(),
        velocity: data.trial.velocity,
        phantom: campaign.phantom.clone(),
        marker_sigma: campaign.noise.map(|n| n.marker_sigma),
        layout,
        frames,
    })
}

/// The tool sample linearly interpolated at time `t`, or `None` outside the
/// samples' span.
fn interpolate_tool(
    samples: &[needle_data::ToolSample],
    t: f64,
) -> Option<needle_data::ToolSample> {
    let first = samples.first()?;
    let last = samples.last()?;
    if t < first.t || t > last.t {
        return None;
    }
    let after = samples.partition_point(|s| s.t < t).min(samples.len() - 1);
    let b = samples[after];
    if after == 0 || b.t == t {
        return Some(b);
    }
    let a = samples[after - 1];
    let w = (t - a.t) / (b.t - a.t);
    let mix = |p: f64, q: f64| p + w * (q - p);
    Some(needle_data::ToolSample {
        t,
        tip_x: mix(a.tip_x, b.tip_x),
        tip_y: mix(a.tip_y, b.tip_y),
        theta: mix(a.theta, b.theta),
        fx: mix(a.fx, b.fx),
        fy: mix(a.fy, b.fy),
        mz: mix(a.mz, b.mz),
    })
}
