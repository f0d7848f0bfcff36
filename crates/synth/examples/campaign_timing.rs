//! Times the stages of one paper-default campaign, and writes or compares
//! its noise-free responses (to check that a speed change leaves the
//! physics alone).
//!
//! ```text
//! cargo run --profile bench -p needle-synth --example campaign_timing -- generate [OUT]
//! cargo run --profile bench -p needle-synth --example campaign_timing -- respond OUT.txt
//! cargo run --profile bench -p needle-synth --example campaign_timing -- compare A.txt B.txt
//! ```
//!
//! With `SCENARIO=FILE` in the environment, `generate` and `respond` use
//! that scenario file instead of the paper default.
//!
//! `respond` writes one line per state: trial id, state, force and every
//! marker displacement (x, y), in Rust's shortest round-trip notation.
//! `compare` prints the largest difference of the marker displacements (m)
//! and of the forces (N) between two such files.

use std::time::Instant;

use needle_synth::{Scenario, Stage, generate, load_scenario, respond};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scenario = std::env::var("SCENARIO").map_or_else(
        |_| Scenario::paper_default(),
        |file| load_scenario(&file).expect("a valid scenario file"),
    );
    match args.first().map(String::as_str) {
        Some("generate") => {
            // Into a fresh temporary folder, or into OUT to keep the files.
            let temporary = tempfile::tempdir().expect("a temporary folder");
            let dir = args.get(1).map_or(temporary.path(), std::path::Path::new);
            let started = Instant::now();
            let summary = generate(
                &scenario,
                &dir.join("bundle"),
                &dir.join("truth.ron"),
                |stage| {
                    if !matches!(stage, Stage::Probes { .. }) {
                        eprintln!("{:8.2} s {stage:?}", started.elapsed().as_secs_f64());
                    }
                },
            )
            .expect("the campaign generates");
            eprintln!(
                "{:8.2} s done: {} needle solves, {} dofs, {} frames",
                summary.seconds, summary.needle_solves, summary.dofs, summary.frames
            );
        }
        Some("respond") => {
            let out = args.get(1).expect("respond OUT");
            let mut text = String::new();
            for r in respond(&scenario).expect("the campaign responds") {
                for ((state, force), markers) in r.states.iter().zip(&r.force).zip(&r.markers) {
                    text.push_str(&format!("{} {state:?} {force:?}", r.id));
                    for m in markers {
                        text.push_str(&format!(" {:?} {:?}", m[0], m[1]));
                    }
                    text.push('\n');
                }
            }
            std::fs::write(out, text).expect("the responses are written");
        }
        Some("compare") => {
            let read = |p: &String| std::fs::read_to_string(p).expect("a responses file");
            let (a, b) = (read(&args[1]), read(&args[2]));
            let (mut markers, mut force, mut lines) = (0.0f64, 0.0f64, 0);
            for (la, lb) in a.lines().zip(b.lines()) {
                let fa: Vec<&str> = la.split(' ').collect();
                let fb: Vec<&str> = lb.split(' ').collect();
                assert_eq!(fa[..2], fb[..2], "the same trial and state");
                let num = |s: &str| s.parse::<f64>().expect("a number");
                force = force.max((num(fa[2]) - num(fb[2])).abs());
                for (x, y) in fa[3..].iter().zip(&fb[3..]) {
                    markers = markers.max((num(x) - num(y)).abs());
                }
                lines += 1;
            }
            assert_eq!(a.lines().count(), b.lines().count(), "the same states");
            println!(
                "{lines} states: markers differ by at most {markers:e} m, forces by {force:e} N"
            );
        }
        _ => eprintln!("usage: campaign_timing generate [OUT] | respond OUT | compare A B"),
    }
}
