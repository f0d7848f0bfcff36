//! The regularised shaft force estimator: the axial force density along the
//! needle, $q(s)$, from the marker displacements of one frame,
//!
//! $$\hat q = \arg\min_q\ |W(Gq - u)|^2 + \lambda\,|Lq|^2,$$
//!
//! with the force support restricted to the needle line (the unknowns are
//! station values of $q$ between the entry and the tip), $G$ the model's
//! response ([`crate::respond`]), $W$ the inverse marker noise, $L$ a
//! difference operator along the shaft, and $\lambda$ from the discrepancy
//! principle or GCV ([`crate::regularise`]). With the slab model this is the
//! paper's equation (6) solved as the linear least-squares problem it is.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::ForceError;
use crate::observe::{Frame, GridIndex, Insertion};
use crate::place::{Needle, Placement};
use crate::regularise::{LambdaChoice, Regularisation};
use crate::respond::{MaterialField, ModelOptions, ShaftResponse};
use crate::shaft::{ShaftBasis, ShaftPath, Smoothness, interpolate_displacement};
use crate::tip::{TipPrior, TipZone, fit_with_tip_prior};

/// Options of the regularised estimator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EstimatorOptions {
    /// The elastic model.
    pub model: ModelOptions,
    /// How $\lambda$ is chosen.
    pub regularisation: Regularisation,
    /// The smoothness prior.
    pub smoothness: Smoothness,
    /// How the smoothness prior treats the tip.
    pub tip: TipPrior,
    /// Largest spacing of the density stations along the shaft (m).
    pub shaft_spacing: f64,
}

impl EstimatorOptions {
    /// The 3-D slab estimator (equation (6)) with `regularisation`:
    /// first-difference prior, stations at most 1.5 mm apart; the tip
    /// prior chosen by the evidence ([`TipPrior::Evidence`]) with
    /// [`Regularisation::MarginalLikelihood`], uniform with the other rules.
    pub fn slab(regularisation: Regularisation) -> Self {
        Self {
            model: ModelOptions::slab(),
            regularisation,
            smoothness: Smoothness::FirstDifference,
            tip: match regularisation {
                Regularisation::MarginalLikelihood { .. } => TipPrior::Evidence,
                _ => TipPrior::Uniform,
            },
            shaft_spacing: 1.5e-3,
        }
    }

    /// The same estimator with the plane-strain model.
    pub fn plane(regularisation: Regularisation) -> Self {
        Self {
            model: ModelOptions::plane(),
            ..Self::slab(regularisation)
        }
    }
}

/// The estimated axial force density along the shaft at one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShaftDistribution {
    /// Frame time (s).
    pub t: f64,
    /// Material point of the entry: where the deformed front face crosses
    /// the needle, in the rest frame (m, on $y = 0$).
    pub entry: [f64; 2],
    /// How far that deformed entry lies inside the phantom along the
    /// needle, $\delta$ (m).
    pub entry_offset: f64,
    /// Material point of the tip, in the rest frame (m).
    pub material_tip: [f64; 2],
    /// How far the last re-placement moved the entry or the material tip
    /// (m): small against the station spacing when the placement has
    /// settled.
    pub placement_change: f64,
    /// Inserted length along the needle, deformed entry to tip (m).
    pub length: f64,
    /// Station arc lengths along the needle from the deformed entry (m).
    pub stations: Vec<f64>,
    /// Axial force density at the stations (N/m).
    pub density: Vec<f64>,
    /// One standard deviation of the density from the marker noise (N/m).
    pub density_sigma: Vec<f64>,
    /// $\int_0^L q\,ds$ (N).
    pub integrated: f64,
    /// One standard deviation of `integrated` from the marker noise (N).
    pub integrated_sigma: f64,
    /// Axial base force measured by the sensor, $f \cdot$ axis (N).
    pub base_force: f64,
    /// The regularisation weight.
    pub lambda: f64,
    /// How it was chosen; [`LambdaChoice::DiscrepancyAtModelFloor`] and
    /// [`LambdaChoice::GcvAfterUnreachableDiscrepancy`] flag a model that
    /// does not fit the data to the stated noise,
    /// [`LambdaChoice::PooledNotExplained`] a tip-following profile that
    /// does not explain this frame.
    pub choice: LambdaChoice,
    /// The tip zone of the smoothness prior the fit used
    /// ([`TipZone::UNIFORM`] when the evidence chose none).
    pub tip_zone: TipZone,
    /// Root-mean-square marker residual (m).
    pub residual_rms: f64,
    /// Marker coordinates used.
    pub data_count: usize,
}

impl ShaftDistribution {
    /// True when the fit did not reach the stated noise level (the estimate
    /// then carries model error that its `sigma`s do not include).
    pub fn is_flagged(&self) -> bool {
        matches!(
            self.choice,
            LambdaChoice::GcvAfterUnreachableDiscrepancy
                | LambdaChoice::DiscrepancyAtModelFloor
                | LambdaChoice::PooledNotExplained
        )
    }

    /// The density at arc length `s` (linear between stations, zero outside).
    pub fn density_at(&self, s: f64) -> f64 {
        ShaftBasis {
            stations: self.stations.clone(),
        }
        .evaluate(&self.density, s)
    }
}

/// The estimator for one needle insertion: one model factorisation and one
/// set of unit responses serve every frame of the trial.
#[derive(Debug, Clone)]
pub struct ShaftEstimator {
    options: EstimatorOptions,
    grid: GridIndex,
    response: ShaftResponse,
    /// The needle line the frames were fitted to, before the model snapped
    /// it to a mesh line: frames are checked against this line, so that the
    /// snap (at most a quarter element) does not reject frames the line fits.
    line_entry_x: f64,
}

impl ShaftEstimator {
    /// Builds the model for the needle line of `insertion` (the median entry
    /// x of its frames).
    pub fn new(
        insertion: &Insertion,
        material: &MaterialField,
        options: EstimatorOptions,
    ) -> Result<Self, ForceError> {
        crate::error::positive("shaft spacing", options.shaft_spacing)?;
        let grid = insertion.layout.grid()?;
        let paths: Vec<ShaftPath> = insertion
            .frames
            .iter()
            .map(|f| ShaftPath::from_frame(f, &insertion.layout, &grid))
            .collect::<Result<_, _>>()?;
        if paths.is_empty() {
            return Err(ForceError::NoFramesInContact {
                trial: insertion.trial.clone(),
            });
        }
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let entry_x = median(paths.iter().map(|p| p.entry[0]).collect());
        let angle = median(paths.iter().map(|p| p.axis[0].atan2(p.axis[1])).collect());
        // A straight insertion stays exactly on +y (the model then puts the
        // needle on a mesh line).
        let axis = if angle.abs() <= 1e-9 {
            [0.0, 1.0]
        } else {
            [angle.sin(), angle.cos()]
        };
        let response = ShaftResponse::new(
            &insertion.phantom,
            &insertion.layout,
            &grid,
            material,
            options.model,
            [entry_x, 0.0],
            axis,
        )?;
        Ok(Self {
            options,
            grid,
            response,
            line_entry_x: entry_x,
        })
    }

    /// The model's response.
    pub fn response(&self) -> &ShaftResponse {
        &self.response
    }

    /// The distribution at one frame of `insertion`.
    ///
    /// Errors: a needle that is not straight along +y, or whose entry is more
    /// than a quarter marker spacing from the model's needle line; fewer
    /// tracked marker coordinates than unknowns.
    pub fn estimate(
        &self,
        insertion: &Insertion,
        frame: &Frame,
    ) -> Result<ShaftDistribution, ForceError> {
        let placed = self.estimate_placed(insertion, frame)?;
        Ok(placed
            .solved
            .into_distribution(frame, &placed.placement, placed.change))
    }

    /// The estimate at one frame with where its load was placed: what the
    /// tip-following estimator (`crate::follow`) builds on.
    pub(crate) fn estimate_placed(
        &self,
        insertion: &Insertion,
        frame: &Frame,
    ) -> Result<Placed, ForceError> {
        let path = ShaftPath::from_frame(frame, &insertion.layout, &self.grid)?;
        let axis = self.response.axis();
        let turn = path.axis[0] * axis[1] - path.axis[1] * axis[0];
        if (path.entry[0] - self.line_entry_x).abs() > 0.25 * self.grid.spacing()
            || turn.abs() > 1e-3
        {
            return Err(ForceError::Mismatch(format!(
                "frame at t = {} s: the needle enters at x = {} m with axis {:?}, off the model's needle line (x = {} m, axis {:?})",
                frame.t, path.entry[0], path.axis, self.line_entry_x, axis
            )));
        }
        if path.length > insertion.phantom.depth {
            return Err(ForceError::BadShaft {
                length: path.length,
                reason: "the tip is beyond the back face",
            });
        }
        // The load acts on the material line whose deformed image is the
        // needle (`crate::place`). First placed in the measured top-face
        // displacement, then, a fixed number of rounds, in the model's own
        // mid-plane displacement of the previous fit.
        let needle = Needle::through(frame.tip, axis);
        let extent = [insertion.phantom.width, insertion.phantom.depth];
        let spacing = self.options.shaft_spacing;
        let measured = |x: [f64; 2]| {
            Ok(
                interpolate_displacement(frame, &insertion.layout, &self.grid, x)
                    .unwrap_or([0.0; 2]),
            )
        };
        let mut placement = Placement::in_field(&needle, spacing, &measured, extent)?;
        let mut solved = self.solve_at(insertion, frame, &placement)?;
        let mut change = f64::NAN;
        for _ in 0..PLACEMENT_ROUNDS {
            let q = DVector::from_column_slice(&solved.density);
            let field = self.response.band_field(&(&solved.loads * q));
            let next = Placement::in_field(&needle, spacing, &|x| field.at(x), extent)?;
            change = next.moved_from(&placement);
            placement = next;
            solved = self.solve_at(insertion, frame, &placement)?;
        }
        Ok(Placed {
            solved,
            placement,
            needle,
            change,
        })
    }

    /// The marker data of `frame` and their weights $1/\sigma$: the row
    /// `2k + c` of every tracked coordinate, its displacement and weight
    /// (the per-row tracking sigma if the track has it, else the stated
    /// noise, else 1: GCV does not depend on the scale).
    pub(crate) fn weighted_data(
        &self,
        insertion: &Insertion,
        frame: &Frame,
    ) -> Result<WeightedData, ForceError> {
        let stated = self.stated_sigma(insertion);
        let mut data = WeightedData::default();
        for (k, d) in frame.displacement.iter().enumerate() {
            let Some(d) = d else { continue };
            let row_sigma = frame.sigma.as_ref().and_then(|s| s[k]);
            for c in 0..2 {
                let sigma = row_sigma.map(|s| s[c]).or(stated).unwrap_or(1.0);
                crate::error::positive("marker sigma", sigma)?;
                data.rows.push(2 * k + c);
                data.values.push(d[c]);
                data.weights.push(1.0 / sigma);
            }
        }
        Ok(data)
    }

    /// The marker noise the rule states, else the insertion's.
    fn stated_sigma(&self, insertion: &Insertion) -> Option<f64> {
        match self.options.regularisation {
            Regularisation::Discrepancy { sigma }
            | Regularisation::MarginalLikelihood { sigma } => Some(sigma),
            _ => insertion.marker_sigma,
        }
    }

    /// The smallest spacing of the marker grid (m).
    pub fn marker_spacing(&self) -> f64 {
        self.grid.spacing()
    }

    /// The options the estimator was built with.
    pub fn options(&self) -> &EstimatorOptions {
        &self.options
    }

    /// The regularised fit for the load placed by `placement`.
    fn solve_at(
        &self,
        insertion: &Insertion,
        frame: &Frame,
        placement: &Placement,
    ) -> Result<Solved, ForceError> {
        let basis = placement.basis.clone();
        let loads = self
            .response
            .point_loads(&placement.load_points(), &basis)?;
        let g = self.response.marker_response(&loads);
        let stated = self.stated_sigma(insertion);
        let WeightedData {
            rows,
            values: data,
            weights,
        } = self.weighted_data(insertion, frame)?;
        if rows.len() < basis.len() + 2 {
            return Err(ForceError::TooFewMarkers {
                context: "shaft force distribution (tracked marker coordinates)",
                found: rows.len(),
                required: basis.len() + 2,
            });
        }
        let a = DMatrix::from_fn(rows.len(), basis.len(), |r, j| weights[r] * g[(rows[r], j)]);
        let b = DVector::from_fn(rows.len(), |r, _| weights[r] * data[r]);
        let regularisation = match self.options.regularisation {
            // The data are whitened already: unit noise.
            Regularisation::Discrepancy { .. } => Regularisation::Discrepancy { sigma: 1.0 },
            Regularisation::MarginalLikelihood { .. } => {
                Regularisation::MarginalLikelihood { sigma: 1.0 }
            }
            other => other,
        };
        let (fit, tip_zone) = fit_with_tip_prior(
            &a,
            &b,
            &basis,
            self.options.smoothness,
            regularisation,
            self.options.tip,
        )?;
        // Covariance of q for whitened data: C A^T A C, scaled by the
        // residual variance when the noise is not known.
        let noise_known = stated.is_some() || frame.sigma.is_some();
        let variance_scale = if noise_known {
            1.0
        } else {
            fit.residual_squared / (fit.data_count as f64 - fit.effective_parameters).max(1.0)
        };
        let covariance =
            &fit.inverse_normal * (a.transpose() * &a) * &fit.inverse_normal * variance_scale;
        let w = DVector::from_vec(basis.weights());
        let integrated = w.dot(&fit.solution);
        let integrated_sigma = (w.transpose() * &covariance * &w)[(0, 0)].max(0.0).sqrt();
        let residual: f64 = (0..rows.len())
            .map(|r| {
                let predicted: f64 = (0..basis.len())
                    .map(|j| g[(rows[r], j)] * fit.solution[j])
                    .sum();
                (predicted - data[r]).powi(2)
            })
            .sum();
        Ok(Solved {
            loads,
            whitened_misfit: fit.residual_squared,
            density: fit.solution.iter().copied().collect(),
            density_sigma: (0..basis.len())
                .map(|j| covariance[(j, j)].max(0.0).sqrt())
                .collect(),
            basis,
            integrated,
            integrated_sigma,
            lambda: fit.lambda,
            choice: fit.choice,
            tip_zone,
            residual_rms: (residual / rows.len() as f64).sqrt(),
            data_count: rows.len(),
        })
    }
}

/// Re-placements of the load in the model's own displacement, after the
/// first fit placed in the measured one. A fixed count rather than a
/// tolerance, so that every frame costs the same and the estimate is a
/// smooth function of the data; the last move is reported
/// ([`ShaftDistribution::placement_change`]).
const PLACEMENT_ROUNDS: usize = 4;

/// The marker data of one frame: rows `2k + c` of the tracked coordinates,
/// their displacements (m) and weights $1/\sigma$.
#[derive(Debug, Clone, Default)]
pub(crate) struct WeightedData {
    pub rows: Vec<usize>,
    pub values: Vec<f64>,
    pub weights: Vec<f64>,
}

/// A frame's estimate with where its load acts.
pub(crate) struct Placed {
    pub solved: Solved,
    pub placement: Placement,
    pub needle: Needle,
    /// The last re-placement's move (m).
    pub change: f64,
}

/// One regularised fit, before it is tied to its frame.
pub(crate) struct Solved {
    /// The load matrix $P$ of the placement (loaded dofs x stations).
    pub loads: DMatrix<f64>,
    basis: ShaftBasis,
    pub density: Vec<f64>,
    /// $|W(Gq - u)|^2$: the whitened misfit of the fit.
    pub whitened_misfit: f64,
    density_sigma: Vec<f64>,
    integrated: f64,
    integrated_sigma: f64,
    lambda: f64,
    choice: LambdaChoice,
    tip_zone: TipZone,
    residual_rms: f64,
    data_count: usize,
}

impl Solved {
    pub(crate) fn into_distribution(
        self,
        frame: &Frame,
        placement: &Placement,
        placement_change: f64,
    ) -> ShaftDistribution {
        let axis = frame.axis();
        ShaftDistribution {
            t: frame.t,
            entry: placement.material[0],
            entry_offset: placement.entry_offset,
            material_tip: placement.tip(),
            placement_change,
            length: self.basis.length(),
            stations: self.basis.stations,
            density: self.density,
            density_sigma: self.density_sigma,
            integrated: self.integrated,
            integrated_sigma: self.integrated_sigma,
            base_force: frame.base_force[0] * axis[0] + frame.base_force[1] * axis[1],
            lambda: self.lambda,
            choice: self.choice,
            tip_zone: self.tip_zone,
            residual_rms: self.residual_rms,
            data_count: self.data_count,
        }
    }
}

/// The shaft force distribution at frame `frame_index` of an insertion
/// (builds the model; use [`ShaftEstimator`] to reuse it over frames).
pub fn shaft_force_distribution(
    insertion: &Insertion,
    frame_index: usize,
    material: &MaterialField,
    options: EstimatorOptions,
) -> Result<ShaftDistribution, ForceError> {
    let frame = insertion.frames.get(frame_index).ok_or_else(|| {
        ForceError::Mismatch(format!(
            "frame {frame_index} requested, the insertion has {}",
            insertion.frames.len()
        ))
    })?;
    ShaftEstimator::new(insertion, material, options)?.estimate(insertion, frame)
}

/// The distributions at every frame of an insertion, one model for all.
pub fn shaft_force_distributions(
    insertion: &Insertion,
    material: &MaterialField,
    options: EstimatorOptions,
) -> Result<Vec<ShaftDistribution>, ForceError> {
    let estimator = ShaftEstimator::new(insertion, material, options)?;
    insertion
        .frames
        .iter()
        .map(|f| estimator.estimate(insertion, f))
        .collect()
}
