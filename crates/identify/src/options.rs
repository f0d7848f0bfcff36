//! What the caller chooses: the model (element, plane assumption, mesh
//! refinement, regions), the start and bounds of the search, the noise and
//! the treatment of frames and markers.

use needle_fem::element::ElementKind;
use serde::{Deserialize, Serialize};

use crate::error::IdentifyError;

/// The kinematics of the model: a plane idealisation of the phantom's top
/// face, or the 3-D slab.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum PlaneModel {
    /// Plane strain ($\varepsilon_{zz} = 0$), the paper's model and the default.
    #[default]
    Strain,
    /// Plane stress ($\sigma_{zz} = 0$), a thin plate.
    Stress,
    /// The 3-D slab $\[0,w\]\times\[0,d\]\times\[-t/2,t/2\]$ of tetrahedra
    /// (Tet10 for the default `Tri6` element, Tet4 for `Tri3`) with
    /// `slab_layers` element layers through the thickness, markers read on
    /// the top face $z = t/2$ and the probe force spread uniformly over the
    /// thickness of the face it presses. For data from a thin but 3-D
    /// phantom, where the plane models misread $\nu$
    /// (`docs/identification.md`).
    Slab,
}

/// How the probe's force enters the model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum ProbeLoad {
    /// A point force at the boundary point nearest to the tip (the paper's
    /// model; a line load through the thickness in the slab). Its
    /// displacement is singular at the load, so markers near it must be
    /// left out (`exclusion_radius`).
    Point,
    /// A rigid, frictionless flat punch of contact width $a$ centred on
    /// that point: the force spread along the face with the punch pressure
    /// $p(s) = F / (\pi\sqrt{(a/2)^2 - s^2})$, $|s| < a/2$ (through the
    /// whole thickness in the slab). The width is fitted with the material
    /// unless `fit_width` is false.
    FlatPunch {
        /// The width (m), or where its fit starts; `None`: one marker
        /// spacing.
        width: Option<f64>,
        /// Fit the width with E and nu (default), or hold it.
        fit_width: bool,
    },
}

impl Default for ProbeLoad {
    fn default() -> Self {
        ProbeLoad::FlatPunch {
            width: None,
            fit_width: true,
        }
    }
}

/// How elements are grouped into material regions, each with its own
/// Young's modulus (one Poisson's ratio for all).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub enum Regions {
    /// One material everywhere.
    #[default]
    Homogeneous,
    /// Layers across the insertion direction: region `k` holds the elements
    /// whose centroid lies between `boundaries[k-1]` and `boundaries[k]` in
    /// y (strictly increasing, inside `(0, depth)`); `boundaries.len() + 1`
    /// regions, region 0 at the front face. The boundaries are added as mesh
    /// lines so that no element straddles two layers.
    LayersY {
        /// Layer interfaces in y (m).
        boundaries: Vec<f64>,
    },
}

impl Regions {
    /// Number of regions.
    pub fn count(&self) -> usize {
        match self {
            Regions::Homogeneous => 1,
            Regions::LayersY { boundaries } => boundaries.len() + 1,
        }
    }

    /// Region of a point with this y coordinate.
    pub fn region_of(&self, y: f64) -> usize {
        match self {
            Regions::Homogeneous => 0,
            Regions::LayersY { boundaries } => boundaries.partition_point(|&b| b <= y),
        }
    }
}

/// Options of [`identify_material`](crate::identify_material) and
/// [`identify_from_data`](crate::identify_from_data).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IdentifyOptions {
    /// Element of the model mesh: `Tri6` (default; does not lock at
    /// $\nu \to 0.5$) or `Tri3` (the paper's linear triangles). With
    /// [`PlaneModel::Slab`] the tetrahedron of the same order (`Tet10` or
    /// `Tet4`, which may also be named directly).
    pub element: ElementKind,
    /// Plane strain (default), plane stress, or the 3-D slab.
    pub plane: PlaneModel,
    /// Element layers through the thickness of the slab model (default 2;
    /// only with [`PlaneModel::Slab`]).
    pub slab_layers: usize,
    /// Mesh lines per marker spacing (1: the element corners are the
    /// markers, as in the paper's Fig. 8). Default 2: on the paper's
    /// campaign the T6 model's bias in E drops from 0.19% to 0.04%
    /// (`docs/identification.md`).
    pub refinement: usize,
    /// Material regions (per-region moduli).
    pub regions: Regions,
    /// Starting Young's modulus (Pa). Only sets the reference scale: the
    /// modulus enters the fit in closed form (see the crate doc).
    pub start_youngs_modulus: f64,
    /// Starting Poisson's ratio, added to the scan of the ratio.
    pub start_poisson_ratio: f64,
    /// Search interval of Poisson's ratio (default `[0, 0.499]`).
    pub poisson_bounds: (f64, f64),
    /// Search interval of the moduli in Pa (default `[1 Pa, 1 GPa]`).
    pub modulus_bounds: (f64, f64),
    /// Points of the scan of Poisson's ratio before the polish.
    pub scan_points: usize,
    /// Marker noise (m, per coordinate) overriding the bundle's statement
    /// and the `sx,sy` columns.
    pub marker_sigma: Option<f64>,
    /// A frame counts as "in contact" when the probe force magnitude is at
    /// least this (N). Default: 5 times the stated force noise, or 2% of
    /// the trial's largest force when no noise is stated.
    pub contact_force: Option<f64>,
    /// Half-width (s) of the window of `tool.csv` samples to which a
    /// straight line is fitted to read the force and tip at each camera
    /// frame ([`fitted_sample_at`](crate::fitted_sample_at)), which
    /// averages out the force sensor's noise and quantisation. `None`
    /// (default): linear interpolation between the two samples around the
    /// frame, the raw record.
    pub force_window: Option<f64>,
    /// The probe's load: a flat punch of fitted width (default) or the
    /// paper's point force.
    pub probe: ProbeLoad,
    /// Markers closer than this to the load point are left out of the
    /// residuals (m). Default: none with the flat punch, which models the
    /// contact patch; one marker spacing with the point force, whose
    /// displacement is singular at the load.
    pub exclusion_radius: Option<f64>,
    /// Fit one modulus per trial (Poisson's ratio held at the global value)
    /// and a linear drift of the modulus with the day.
    pub per_trial: bool,
    /// Stopping rules of the Levenberg-Marquardt polish.
    pub lsq: needle_lsq::Options,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        Self {
            element: ElementKind::Tri6,
            plane: PlaneModel::Strain,
            slab_layers: 2,
            refinement: 2,
            regions: Regions::Homogeneous,
            start_youngs_modulus: 30e3,
            start_poisson_ratio: 0.3,
            poisson_bounds: (0.0, 0.499),
            modulus_bounds: (1.0, 1e9),
            scan_points: 24,
            marker_sigma: None,
            contact_force: None,
            force_window: None,
            probe: ProbeLoad::default(),
            exclusion_radius: None,
            per_trial: true,
            lsq: needle_lsq::Options::default(),
        }
    }
}

impl IdentifyOptions {
    /// Checks every option, naming the first bad one.
    pub fn validate(&self) -> Result<(), IdentifyError> {
        let bad = |field, value, reason| {
            Err(IdentifyError::InvalidValue {
                field,
                value,
                reason,
            })
        };
        if self.plane != PlaneModel::Slab && self.element.dimension() != 2 {
            return Err(IdentifyError::Inconsistent(format!(
                "options.element: the {:?} model is 2-D, {:?} is a 3-D element (use PlaneModel::Slab)",
                self.plane, self.element
            )));
        }
        if self.refinement == 0 {
            return bad("options.refinement", 0.0, "must be at least 1");
        }
        if self.slab_layers == 0 {
            return bad("options.slab_layers", 0.0, "must be at least 1");
        }
        let (nu_lo, nu_hi) = self.poisson_bounds;
        if !(nu_lo.is_finite() && nu_hi.is_finite() && -1.0 < nu_lo && nu_lo < nu_hi && nu_hi < 0.5)
        {
            return bad(
                "options.poisson_bounds",
                nu_hi,
                "need -1 < lower < upper < 0.5",
            );
        }
        let (e_lo, e_hi) = self.modulus_bounds;
        if !(e_lo.is_finite() && e_hi.is_finite() && 0.0 < e_lo && e_lo < e_hi) {
            return bad(
                "options.modulus_bounds",
                e_lo,
                "need 0 < lower < upper, finite",
            );
        }
        if !(self.start_youngs_modulus >= e_lo && self.start_youngs_modulus <= e_hi) {
            return bad(
                "options.start_youngs_modulus",
                self.start_youngs_modulus,
                "outside options.modulus_bounds",
            );
        }
        if !(self.start_poisson_ratio >= nu_lo && self.start_poisson_ratio <= nu_hi) {
            return bad(
                "options.start_poisson_ratio",
                self.start_poisson_ratio,
                "outside options.poisson_bounds",
            );
        }
        if self.scan_points < 3 {
            return bad(
                "options.scan_points",
                self.scan_points as f64,
                "must be at least 3",
            );
        }
        for (field, value) in [
            ("options.marker_sigma", self.marker_sigma),
            ("options.contact_force", self.contact_force),
            ("options.force_window", self.force_window),
        ] {
            if let Some(v) = value
                && !(v.is_finite() && v > 0.0)
            {
                return bad(field, v, "must be positive and finite");
            }
        }
        if let ProbeLoad::FlatPunch {
            width: Some(width), ..
        } = self.probe
            && !(width.is_finite() && width > 0.0)
        {
            return bad(
                "options.probe.width",
                width,
                "must be positive and finite (ProbeLoad::Point is the point force)",
            );
        }
        if let Some(v) = self.exclusion_radius
            && !(v.is_finite() && v >= 0.0)
        {
            return bad(
                "options.exclusion_radius",
                v,
                "must be non-negative and finite",
            );
        }
        if let Regions::LayersY { boundaries } = &self.regions {
            if boundaries.is_empty() {
                return Err(IdentifyError::Inconsistent(
                    "options.regions: LayersY needs at least one boundary (use Homogeneous for one region)".into(),
                ));
            }
            for (k, &b) in boundaries.iter().enumerate() {
                if !b.is_finite() || (k > 0 && b <= boundaries[k - 1]) {
                    return bad(
                        "options.regions.boundaries",
                        b,
                        "must be finite and strictly increasing",
                    );
                }
            }
        }
        Ok(())
    }
}
