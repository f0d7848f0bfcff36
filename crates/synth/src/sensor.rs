//! Measurement: the force sensor and the marker tracker, with their noise.
//!
//! - Force: Gaussian noise of standard deviation $\sigma_f$, then
//!   quantisation to the sensor resolution $r$ (12.5 mN for the paper's
//!   ATI Nano-17). The stated sigma is $\sqrt{\sigma_f^2 + r^2/12}$.
//! - Markers: Gaussian noise of standard deviation $\sigma_m$ per
//!   coordinate (the tracker's sub-pixel precision); positions are written
//!   rounded to 0.1 µm, which adds a negligible $10^{-7}/\sqrt{12}$ m.
//!
//! Every trial draws from its own ChaCha stream of the scenario seed, so
//! a trial's noise does not depend on which other trials are generated.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::scenario::Sensors;

/// Rounding of written marker positions (m).
pub const POSITION_ROUNDING: f64 = 1e-7;

/// The noisy instruments of one trial.
pub(crate) struct Instruments {
    rng: ChaCha8Rng,
    sensors: Sensors,
    force_noise: Normal<f64>,
    marker_noise: Normal<f64>,
}

impl Instruments {
    /// Instruments for trial number `stream` of a campaign seeded `seed`.
    pub fn new(sensors: Sensors, seed: u64, stream: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(stream);
        Self {
            rng,
            sensors,
            force_noise: Normal::new(0.0, sensors.force_sigma)
                .expect("sigma validated non-negative"),
            marker_noise: Normal::new(0.0, sensors.marker_sigma)
                .expect("sigma validated non-negative"),
        }
    }

    /// A force reading of the true force `f` (N).
    pub fn force(&mut self, f: f64) -> f64 {
        let noisy = f + self.force_noise.sample(&mut self.rng);
        let r = self.sensors.force_resolution;
        if r > 0.0 {
            (noisy / r).round() * r
        } else {
            noisy
        }
    }

    /// A tracked position of the true position `p` (m).
    pub fn marker(&mut self, p: [f64; 2]) -> [f64; 2] {
        let x = p[0] + self.marker_noise.sample(&mut self.rng);
        let y = p[1] + self.marker_noise.sample(&mut self.rng);
        [round_position(x), round_position(y)]
    }
}

/// The stated one-sigma force noise: Gaussian noise plus quantisation.
pub fn stated_force_sigma(sensors: &Sensors) -> f64 {
    (sensors.force_sigma.powi(2) + sensors.force_resolution.powi(2) / 12.0).sqrt()
}

fn round_position(x: f64) -> f64 {
    (x / POSITION_ROUNDING).round() * POSITION_ROUNDING
}

/// Sample times `n / rate` for a trial of `duration` s, rounded to the
/// microsecond, last sample at or before the end.
pub fn sample_times(rate: f64, duration: f64) -> Vec<f64> {
    let count = (duration * rate + 1e-9).floor() as usize;
    (0..=count)
        .map(|n| (n as f64 / rate * 1e6).round() / 1e6)
        .collect()
}
