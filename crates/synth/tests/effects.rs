//! The table of `docs/truth-world.md`: how much each effect, alone,
//! changes the final marker displacements and base forces of the default
//! campaign compared with the null scenario. Behind `#[ignore]` (minutes):
//! `cargo test -p needle-synth --test effects -- --ignored --nocapture`.

use needle_synth::{EffectId, Scenario, TrialResponse, respond};

/// Largest change of a final marker displacement and of a final force,
/// and the largest peak strain of `a`.
fn change(a: &[TrialResponse], b: &[TrialResponse]) -> (f64, f64, f64) {
    let (mut du, mut df, mut strain) = (0.0f64, 0.0f64, 0.0f64);
    for (a, b) in a.iter().zip(b) {
        for (p, q) in a
            .markers
            .last()
            .unwrap()
            .iter()
            .zip(b.markers.last().unwrap())
        {
            du = du.max((p[0] - q[0]).hypot(p[1] - q[1]));
        }
        df = df.max((a.force.last().unwrap() - b.force.last().unwrap()).abs());
        strain = strain.max(a.peak_strain);
    }
    (du, df, strain)
}

fn coarse_in_depth(mut s: Scenario) -> Scenario {
    s.resolution.depth_step = 0.005;
    s
}

#[test]
#[ignore = "minutes: every effect of the default campaign against the null one"]
fn every_effect_is_clearly_above_the_noise() {
    let null = respond(&coarse_in_depth(Scenario::null())).unwrap();
    let sigma = Scenario::null().sensors.marker_sigma;
    println!("| effect | max marker change (um) | / sigma | max force change (mN) | peak strain |");
    println!("|---|---|---|---|---|");
    for id in EffectId::ALL {
        let scenario = coarse_in_depth(Scenario::effect_alone(id));
        let (du, df, strain) = match id {
            // The distortion moves the tracks, not the phantom: its size is
            // the largest shift of a marker, at the corners.
            EffectId::LensDistortion => {
                let lens = scenario.effects.lens_distortion.unwrap();
                let p = scenario.phantom;
                let shift = [
                    [0.0, 0.0],
                    [p.width, 0.0],
                    [0.0, p.depth],
                    [p.width, p.depth],
                ]
                .iter()
                .map(|&c| {
                    let d = lens.distort(c);
                    (d[0] - c[0]).hypot(d[1] - c[1])
                })
                .fold(0.0, f64::max);
                (shift, 0.0, change(&null, &null).2)
            }
            // Nonlinearity is compared with the same loads on the linear
            // material (its scenario also raises the loads).
            EffectId::MaterialNonlinearity => {
                let mut linear = scenario.clone();
                linear.effects.material_nonlinearity = None;
                change(&respond(&scenario).unwrap(), &respond(&linear).unwrap())
            }
            _ => change(&respond(&scenario).unwrap(), &null),
        };
        println!(
            "| `{}` | {:.1} | {:.1} | {:.1} | {:.2} |",
            id.as_str(),
            du * 1e6,
            du / sigma,
            df * 1e3,
            strain
        );
        assert!(du > 5.0 * sigma, "{id:?} changes the markers by only {du}");
    }
}
