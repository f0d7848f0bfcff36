//! The 3-D correction on needle-synth's default campaign, with the material
//! identified from the same bundle's probing trials by needle-identify (the
//! pipeline's chain): the integrated shaft force against the measured base
//! force at every frame past 10 mm. Slow (minutes), so ignored; run with
//!
//! ```text
//! cargo test -p needle-force --test synth_campaign -- --ignored --nocapture
//! ```

use needle_data::read_bundle;
use needle_force::{
    EstimatorOptions, MaterialField, Regularisation, observe_insertion, shaft_force_distributions,
};
use needle_identify::{IdentifyOptions, PlaneModel, identify_material};
use needle_synth::{Scenario, generate};

#[test]
#[ignore = "generates a 3-D campaign; minutes"]
fn slab_correction_with_identified_material() {
    // The default campaign's physics (out-of-plane, velocity-dependent
    // friction, the tip peak, stiffening over days), its four probes on
    // day 1 and one insertion at 3 mm/s on day 2; no camera images (the
    // markers are read from the truth with the sensor's noise).
    let mut scenario = Scenario::paper_default();
    scenario.name = "force-check".into();
    scenario.compression = None;
    scenario.frames = None;
    scenario.needles.velocities = vec![0.003];
    scenario.needles.days = vec![2.0];
    let dir = tempfile::tempdir().unwrap();
    let (path, truth) = (dir.path().join("bundle"), dir.path().join("truth.ron"));
    generate(&scenario, &path, &truth, |_| {}).unwrap();
    let bundle = read_bundle(&path).unwrap();

    // As the pipeline identifies (xtask/src/pipeline.rs), with this
    // crate's default probe model (the fitted flat punch).
    let fit = identify_material(
        &bundle,
        &IdentifyOptions {
            plane: PlaneModel::Slab,
            refinement: 1,
            force_window: Some(0.5),
            ..IdentifyOptions::default()
        },
    )
    .unwrap();
    println!("{fit}");
    let day = scenario.needles.days[0];
    let rate = scenario
        .effects
        .material_stiffening
        .map_or(0.0, |s| s.rate_per_day);
    println!(
        "truth E on the needle day {:.1} Pa (probes on day 1: {:.1} Pa)",
        scenario.phantom.youngs_modulus * (1.0 + rate * day),
        scenario.phantom.youngs_modulus * (1.0 + rate)
    );
    let material =
        needle_fem::material::Material::new(fit.youngs_modulus.value, fit.poisson_ratio.value)
            .unwrap();
    let field = MaterialField::Homogeneous(material);
    let sigma = bundle.campaign.noise.unwrap().marker_sigma;
    let needle = bundle
        .campaign
        .trials
        .iter()
        .find(|t| t.trial.kind == needle_data::TrialKind::Needle)
        .unwrap()
        .trial
        .id
        .clone();
    let insertion = observe_insertion(&bundle, &needle).unwrap();
    let mut thinned = insertion.clone();
    // Every 30th frame past 5 mm (about 1 mm of depth apart at 3 mm/s).
    thinned.frames = insertion
        .frames
        .iter()
        .filter(|f| f.tip[1] > 5e-3)
        .step_by(30)
        .cloned()
        .collect();
    let distributions = shaft_force_distributions(
        &thinned,
        &field,
        EstimatorOptions::slab(Regularisation::Discrepancy { sigma }),
    )
    .unwrap();
    let mut worst: f64 = 0.0;
    for d in &distributions {
        let error = d.integrated / d.base_force - 1.0;
        if d.length > 10e-3 {
            worst = worst.max(error.abs());
        }
        println!(
            "depth {:5.1} mm  integrated {:.4} N  base {:.4} N  error {:+.4}  {:?}",
            d.length * 1e3,
            d.integrated,
            d.base_force,
            error,
            d.choice
        );
    }
    println!("largest |error| past 10 mm: {worst:.4}");
}
