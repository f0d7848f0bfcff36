//! The measured side of equation (5): one whitened residual row per marker
//! coordinate per frame, with the frame's load point and force, so that the
//! prediction of row $i$ (marker coordinate $j$ in frame $k$, load point $l$)
//! is $f_{k,x} G_{l,x}[j] + f_{k,y} G_{l,y}[j]$.

use crate::error::IdentifyError;
use crate::model::{ProbeModel, project_to_boundary};
use crate::options::{IdentifyOptions, ProbeLoad};
use crate::probe::{MIN_MARKERS, ProbeData};
use crate::result::NoiseSource;

/// One residual row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Row {
    /// Index into [`Observations::frames`].
    pub frame: usize,
    /// Marker coordinate index `2 * marker + component`.
    pub index: usize,
    /// Measured displacement (m).
    pub value: f64,
    /// Whitening weight `1 / sigma` (1/m).
    pub weight: f64,
}

/// A frame's load.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FrameLoad {
    /// Index into [`ProbeData::trials`].
    pub trial: usize,
    /// Index into the model's load points.
    pub load: usize,
    /// Probe force (N).
    pub force: [f64; 2],
}

/// All residual rows of a fit.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Observations {
    pub rows: Vec<Row>,
    pub frames: Vec<FrameLoad>,
    pub noise: NoiseSource,
    /// Distinct markers with at least one row.
    pub markers: usize,
}

/// The load point of every frame of `data`, deduplicated: returns the
/// distinct points and each frame's index into them.
pub(crate) fn load_points(data: &ProbeData) -> Result<(Vec<[f64; 2]>, Vec<usize>), IdentifyError> {
    let setup = &data.setup;
    let tol = 1e-5 * setup.width.max(setup.depth);
    let mut points: Vec<[f64; 2]> = Vec::new();
    let mut of_frame = Vec::with_capacity(data.frames.len());
    for frame in &data.frames {
        let point =
            project_to_boundary(setup, frame.tip).map_err(|reason| IdentifyError::LoadPoint {
                trial: data.trials[frame.trial].id.clone(),
                t: frame.t,
                x: frame.tip[0],
                y: frame.tip[1],
                reason,
            })?;
        let found = points
            .iter()
            .position(|p| (p[0] - point[0]).hypot(p[1] - point[1]) <= tol);
        of_frame.push(found.unwrap_or_else(|| {
            points.push(point);
            points.len() - 1
        }));
    }
    Ok((points, of_frame))
}

impl Observations {
    /// The rows of `data` for `model` (built on the points of
    /// [`load_points`], whose per-frame indices are `frame_loads`).
    pub fn new(
        data: &ProbeData,
        model: &ProbeModel,
        frame_loads: &[usize],
        options: &IdentifyOptions,
    ) -> Result<Self, IdentifyError> {
        let radius = options.exclusion_radius.unwrap_or(match options.probe {
            ProbeLoad::Point => model.marker_spacing(),
            ProbeLoad::FlatPunch { .. } => 0.0,
        });
        let noise = if let Some(sigma) = options.marker_sigma {
            NoiseSource::Stated(sigma)
        } else if data
            .frames
            .iter()
            .flat_map(|f| &f.displacements)
            .all(|d| d.sigma.is_some())
        {
            NoiseSource::PerObservation
        } else if let Some(sigma) = data.marker_sigma {
            NoiseSource::Stated(sigma)
        } else {
            // Placeholder unit weights until the scan estimates sigma.
            NoiseSource::Estimated(1.0)
        };
        let mut rows = Vec::new();
        let mut frames = Vec::with_capacity(data.frames.len());
        let mut used = vec![false; data.setup.markers.len()];
        for (k, frame) in data.frames.iter().enumerate() {
            let load = frame_loads[k];
            let point = model.load_points()[load];
            for d in &frame.displacements {
                let rest = data.setup.markers[d.marker];
                if (rest[0] - point[0]).hypot(rest[1] - point[1]) < radius {
                    continue;
                }
                used[d.marker] = true;
                for c in 0..2 {
                    // Options override everything; an observation's own sigma
                    // beats the manifest's; an estimated noise is one for all.
                    let sigma = match (options.marker_sigma, d.sigma, noise) {
                        (Some(s), _, _) => s,
                        (None, _, NoiseSource::Estimated(s)) => s,
                        (None, Some(s), _) => s[c],
                        (None, None, NoiseSource::Stated(s)) => s,
                        (None, None, NoiseSource::PerObservation) => {
                            unreachable!("every observation has sigma")
                        }
                    };
                    rows.push(Row {
                        frame: k,
                        index: 2 * d.marker + c,
                        value: d.displacement[c],
                        weight: 1.0 / sigma,
                    });
                }
            }
            frames.push(FrameLoad {
                trial: frame.trial,
                load,
                force: frame.force,
            });
        }
        let markers = used.iter().filter(|&&u| u).count();
        if markers < MIN_MARKERS {
            return Err(IdentifyError::TooFewMarkers {
                context: format!("frames in contact, outside {radius:.3e} m of the load points"),
                needed: MIN_MARKERS,
                found: markers,
            });
        }
        Ok(Self {
            rows,
            frames,
            noise,
            markers,
        })
    }

    /// Sets every weight to `1 / sigma` (after estimating the noise).
    pub fn rescale(&mut self, sigma: f64) {
        for row in &mut self.rows {
            row.weight = 1.0 / sigma;
        }
        self.noise = NoiseSource::Estimated(sigma);
    }

    /// The unwhitened prediction of `row` from unit-load marker responses
    /// (`responses[2 l + c]`).
    pub fn predict(&self, row: &Row, responses: &[Vec<f64>]) -> f64 {
        let frame = &self.frames[row.frame];
        let l = frame.load;
        frame.force[0] * responses[2 * l][row.index]
            + frame.force[1] * responses[2 * l + 1][row.index]
    }
}
