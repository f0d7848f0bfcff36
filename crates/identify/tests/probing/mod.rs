//! Probing campaigns from needle-synth's truth world, read back from their
//! bundles as the pipeline reads them: shared by the flat-punch and the
//! slab tests.

use needle_data::{LoadedBundle, read_bundle};
use needle_synth::{Scenario, generate};

/// `scenario` cut down to probing (no needles, no compression test), with
/// `markers` x `markers` markers at 4 µm noise and the truth meshed at
/// `refinement` mesh lines per marker spacing. With `exact_force` the force
/// sensor has neither noise nor quantisation (the model takes the force as
/// exact).
pub fn probing_only(
    mut scenario: Scenario,
    name: &str,
    markers: usize,
    refinement: usize,
    exact_force: bool,
) -> Scenario {
    scenario.name = name.into();
    scenario.phantom.markers = (markers, markers);
    scenario.resolution.refinement = refinement;
    scenario.compression = None;
    scenario.needles.days.clear();
    scenario.sensors.marker_sigma = 4e-6;
    if exact_force {
        scenario.sensors.force_sigma = 0.0;
        scenario.sensors.force_resolution = 0.0;
    }
    scenario
}

/// The bundle needle-synth writes for `scenario`, read back.
pub fn bundle_of(scenario: &Scenario) -> LoadedBundle {
    let dir = tempfile::tempdir().unwrap();
    let (bundle, truth) = (dir.path().join("bundle"), dir.path().join("truth.ron"));
    generate(scenario, &bundle, &truth, |_| {}).unwrap();
    read_bundle(&bundle).unwrap()
}
