//! A model instance: the baseline parameters followed by each effect's, and
//! the split of a parameter vector into them.

use needle_lsq::Parameter;

use crate::effect::{Chain, Effect, EffectParameter, Geometry, TrialContext};
use crate::error::DiagnoseError;
use crate::spec::ModelSpec;

/// Number of baseline parameters: E, nu, shaft density, probe width.
pub(crate) const BASELINE_PARAMETERS: usize = 4;
/// Index of Young's modulus in a parameter vector.
pub(crate) const YOUNGS_MODULUS: usize = 0;
/// Index of Poisson's ratio in a parameter vector.
pub(crate) const POISSON_RATIO: usize = 1;
/// Index of the uniform shaft density in a parameter vector.
pub(crate) const SHAFT_DENSITY: usize = 2;
/// Index of the probe contact width in a parameter vector.
pub(crate) const PROBE_WIDTH: usize = 3;

/// The baseline parameters of a parameter vector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Baseline {
    pub youngs_modulus: f64,
    pub poisson_ratio: f64,
    pub shaft_density: f64,
    pub probe_width: f64,
}

/// The baseline plus effects, with the layout of its parameter vector.
pub(crate) struct Model {
    pub spec: ModelSpec,
    pub effects: Vec<Box<dyn Effect>>,
    pub parameters: Vec<EffectParameter>,
    /// `offsets[k]..offsets[k + 1]` are the parameters of effect `k`.
    offsets: Vec<usize>,
}

impl Model {
    pub fn new(
        spec: &ModelSpec,
        geometry: &Geometry,
        start: Baseline,
    ) -> Result<Self, DiagnoseError> {
        let effects = spec.effects()?;
        let mut parameters = vec![
            EffectParameter {
                name: "youngs_modulus".into(),
                null: start.youngs_modulus,
                initial: start.youngs_modulus,
                scale: start.youngs_modulus,
                lower: Some(1.0e-3 * start.youngs_modulus),
                upper: Some(1.0e3 * start.youngs_modulus),
                tested: false,
                meaning: "Young's modulus of the phantom (Pa)",
            },
            EffectParameter {
                name: "poisson_ratio".into(),
                null: start.poisson_ratio,
                initial: start.poisson_ratio,
                scale: 0.05,
                lower: Some(0.05),
                upper: Some(0.499),
                tested: false,
                meaning: "Poisson's ratio of the phantom",
            },
            EffectParameter {
                name: "shaft_density".into(),
                null: start.shaft_density,
                initial: start.shaft_density,
                scale: start.shaft_density.abs().max(1.0),
                lower: None,
                upper: None,
                tested: false,
                meaning: "uniform shaft force density along the inserted needle (N/m)",
            },
            EffectParameter {
                name: "probe_width".into(),
                null: start.probe_width,
                initial: start.probe_width,
                scale: 1.0e-3,
                lower: Some(1.0e-4),
                upper: Some(0.25 * geometry.width.min(geometry.depth)),
                tested: false,
                meaning: "width of the blunt probe's contact patch, pressed as a rigid flat \
                          punch (m)",
            },
        ];
        let mut offsets = vec![BASELINE_PARAMETERS];
        for effect in &effects {
            let own = effect.parameters(geometry);
            for p in &own {
                if parameters.iter().any(|q| q.name == p.name) {
                    return Err(DiagnoseError::DuplicateEffect(format!(
                        "{} (parameter `{}` already in the model)",
                        effect.id(),
                        p.name
                    )));
                }
            }
            parameters.extend(own);
            offsets.push(parameters.len());
        }
        Ok(Self {
            spec: spec.clone(),
            effects,
            parameters,
            offsets,
        })
    }

    pub fn len(&self) -> usize {
        self.parameters.len()
    }

    pub fn baseline(&self, p: &[f64]) -> Baseline {
        Baseline {
            youngs_modulus: p[0],
            poisson_ratio: p[POISSON_RATIO],
            shaft_density: p[2],
            probe_width: p[PROBE_WIDTH],
        }
    }

    /// Whether `a` and `b` differ only in parameters of effects that act
    /// after the solves ([`Effect::acts_after_solves`]): the bodies'
    /// solutions at one are then those at the other.
    pub fn solves_alike(&self, a: &[f64], b: &[f64]) -> bool {
        (0..self.len()).all(|k| {
            a[k] == b[k]
                || self
                    .offsets
                    .windows(2)
                    .zip(&self.effects)
                    .any(|(span, effect)| {
                        (span[0]..span[1]).contains(&k) && effect.acts_after_solves()
                    })
        })
    }

    /// Where parameter `k`'s effect says it acts only as a baseline
    /// parameter would ([`Effect::chain`]) on every one of `trials`, all in
    /// the same way: that parameter's index and, per trial, the factor
    /// $f_t$ with $\partial r_t / \partial p_k = f_t\,\partial r_t /
    /// \partial p_\text{source}$.
    pub fn chain(&self, p: &[f64], k: usize, trials: &[TrialContext]) -> Option<(usize, Vec<f64>)> {
        let e = self
            .offsets
            .windows(2)
            .position(|w| (w[0]..w[1]).contains(&k))?;
        let (effect, own) = (&self.effects[e], &p[self.offsets[e]..self.offsets[e + 1]]);
        let index = k - self.offsets[e];
        let chains: Vec<Chain> = trials
            .iter()
            .map(|t| effect.chain(own, index, t))
            .collect::<Option<_>>()?;
        let modulus = self.baseline(p).youngs_modulus;
        let factors = chains.iter().map(|c| match *c {
            Chain::ShaftDensity(rate) => (SHAFT_DENSITY, rate),
            Chain::Stiffness(rate) => (YOUNGS_MODULUS, rate * modulus),
        });
        let source = factors.clone().next().map_or(SHAFT_DENSITY, |(s, _)| s);
        factors
            .map(|(s, f)| (s == source).then_some(f))
            .collect::<Option<Vec<f64>>>()
            .map(|f| (source, f))
    }

    /// The effects with their own parameter slices.
    pub fn effects_with<'a>(
        &'a self,
        p: &'a [f64],
    ) -> impl Iterator<Item = (&'a dyn Effect, &'a [f64])> + 'a {
        self.effects
            .iter()
            .enumerate()
            .map(move |(k, e)| (e.as_ref(), &p[self.offsets[k]..self.offsets[k + 1]]))
    }

    /// Parameter specifications for the engine, starting at `start` where
    /// given (else each parameter's `initial`), with `fixed[k]` held.
    pub fn lsq_parameters(&self, start: &[f64], fixed: &[bool]) -> Vec<Parameter> {
        self.parameters
            .iter()
            .enumerate()
            .map(|(k, spec)| {
                let initial = start.get(k).copied().unwrap_or(spec.initial);
                let mut p = Parameter::new(spec.name.clone(), initial).with_scale(spec.scale);
                if let Some(lower) = spec.lower {
                    p = p.with_lower(lower);
                }
                if let Some(upper) = spec.upper {
                    p = p.with_upper(upper);
                }
                if fixed.get(k).copied().unwrap_or(false) {
                    p = p.fix();
                }
                p
            })
            .collect()
    }
}

/// A model of `effects` on the default phantom's geometry, for unit tests.
#[cfg(test)]
pub(crate) fn test_model(effects: &[&str]) -> Model {
    let spec = ModelSpec {
        effects: effects.iter().map(|e| e.to_string()).collect(),
    };
    let geometry = Geometry {
        width: 0.075,
        depth: 0.075,
        thickness: 0.0075,
        image_centre: [0.0375, 0.0375],
        image_radius: 0.05,
    };
    let start = Baseline {
        youngs_modulus: 25e3,
        poisson_ratio: 0.45,
        shaft_density: 10.0,
        probe_width: 0.002,
    };
    Model::new(&spec, &geometry, start).unwrap()
}
