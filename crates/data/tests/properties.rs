//! Properties: random campaigns written then read back are equal; frames
//! keep their markers; arbitrary bytes never make the reader panic.

use std::collections::BTreeSet;
use std::fs;

use needle_data::{
    Campaign, CompressionPoint, Face, MarkerObservation, MarkerRest, MarkerSet, MarkerTrack, Noise,
    Phantom, ToolSample, Trial, TrialData, TrialKind, WriteOptions, read_bundle, validate_bundle,
    write_bundle,
};
use proptest::prelude::*;

/// Any finite `f64`, including subnormals, huge and tiny magnitudes: the
/// text written must parse back to the same bits.
fn finite() -> impl Strategy<Value = f64> {
    prop_oneof![
        -1.0..1.0f64,
        any::<f64>().prop_filter("finite", |v| v.is_finite()),
        Just(0.0),
        Just(-0.0),
        Just(f64::MIN_POSITIVE / 8.0),
    ]
}

fn phantom() -> impl Strategy<Value = Phantom> {
    let faces = prop::sample::subsequence(
        vec![Face::Front, Face::Back, Face::Left, Face::Right],
        0..=4,
    );
    (0.01..1.0f64, 0.01..1.0f64, 0.001..0.1f64, faces).prop_map(
        |(width, depth, thickness, fixed)| Phantom {
            width,
            depth,
            thickness,
            fixed,
        },
    )
}

fn tool() -> impl Strategy<Value = Vec<ToolSample>> {
    prop::collection::vec(
        (
            0.0..1.0f64,
            [finite(), finite(), finite(), finite(), finite(), finite()],
        ),
        1..8,
    )
    .prop_map(|rows| {
        let mut t = 0.0;
        rows.into_iter()
            .map(|(step, [tip_x, tip_y, theta, fx, fy, mz])| {
                t += step;
                ToolSample {
                    t,
                    tip_x,
                    tip_y,
                    theta,
                    fx,
                    fy,
                    mz,
                }
            })
            .collect()
    })
}

/// A track over the given marker ids: increasing frame numbers, time never
/// decreasing, each frame a non-empty subset of the markers.
fn track(ids: Vec<u32>) -> impl Strategy<Value = MarkerTrack> {
    let n = ids.len();
    let frame = (
        1..4u64,
        0.0..0.5f64,
        prop::sample::subsequence(ids, 1..=n),
        prop::collection::vec((finite(), finite(), 0.0..1e-3f64, 0.0..1e-3f64), n),
    );
    (any::<bool>(), prop::collection::vec(frame, 1..5)).prop_map(|(with_sigma, frames)| {
        let mut track = MarkerTrack::default();
        let (mut number, mut t) = (0u64, 0.0);
        for (gap, dt, chosen, values) in frames {
            number += gap;
            t += dt;
            // Reverse so that frames arrive unsorted and must be sorted on push.
            let rows = chosen.iter().rev().zip(&values);
            if with_sigma {
                track
                    .push_frame_with_sigma(
                        number,
                        t,
                        rows.map(|(&id, &(x, y, sx, sy))| (id, [x, y], [sx, sy])),
                    )
                    .unwrap();
            } else {
                track
                    .push_frame(number, t, rows.map(|(&id, &(x, y, _, _))| (id, [x, y])))
                    .unwrap();
            }
        }
        track
    })
}

fn campaign() -> impl Strategy<Value = Campaign> {
    let markers = prop::collection::btree_set(any::<u32>(), 1..12);
    (
        phantom(),
        "[a-zA-Z0-9 _\"\\\\é()-]{0,12}",
        prop::option::of((0.0..1e-4f64, 0.0..0.1f64)),
        markers,
    )
        .prop_flat_map(|(phantom, name, noise, ids)| {
            let ids: Vec<u32> = ids.into_iter().collect();
            let rest = prop::collection::vec((0.0..phantom.width, 0.0..phantom.depth), ids.len());
            let trial = (
                prop::sample::select(vec![
                    TrialKind::Probe,
                    TrialKind::Needle,
                    TrialKind::Compression,
                ]),
                0.0..0.01f64,
                0.0..30.0f64,
                tool(),
                prop::option::of(track(ids.clone())),
            );
            let compression =
                prop::option::of(prop::collection::vec((0.0..0.5f64, finite()), 0..5));
            (
                Just(phantom),
                Just(name),
                Just(noise),
                Just(ids),
                rest,
                prop::collection::vec(trial, 0..4),
                compression,
            )
        })
        .prop_map(
            |(phantom, name, noise, ids, rest, trials, compression)| Campaign {
                name,
                phantom,
                noise: noise.map(|(marker_sigma, force_sigma)| Noise {
                    marker_sigma,
                    force_sigma,
                }),
                markers_rest: MarkerSet::new(
                    ids.iter()
                        .zip(rest)
                        .map(|(&id, (x, y))| MarkerRest { id, x, y })
                        .collect(),
                ),
                trials: trials
                    .into_iter()
                    .enumerate()
                    .map(|(i, (kind, velocity, day, tool, markers))| TrialData {
                        trial: Trial {
                            id: format!("trial-{i}"),
                            kind,
                            velocity,
                            day,
                        },
                        tool,
                        markers,
                        frames: Vec::new(),
                    })
                    .collect(),
                compression: compression.map(|c| {
                    c.into_iter()
                        .map(|(strain, stress)| CompressionPoint { strain, stress })
                        .collect()
                }),
                calibration_dir: None,
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn written_campaigns_read_back_equal(campaign in campaign()) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bundle");
        write_bundle(&path, &campaign, WriteOptions::default()).unwrap();
        let loaded = read_bundle(&path).unwrap();
        prop_assert_eq!(&loaded.campaign, &campaign);
        prop_assert_eq!(loaded.warnings, validate_bundle(&path));
    }

    #[test]
    fn frames_find_every_marker_they_hold(track in track((0..30).map(|i| 7 * i).collect())) {
        let rows: Vec<MarkerObservation> = track.observations().collect();
        prop_assert_eq!(rows.len(), track.row_count());
        prop_assert_eq!(&MarkerTrack::from_observations(&rows).unwrap(), &track);
        for frame in track.frames() {
            prop_assert!(frame.ids.windows(2).all(|w| w[0] < w[1]));
            let map = frame.to_map();
            for id in (0..210).collect::<BTreeSet<u32>>() {
                prop_assert_eq!(frame.position(id), map.get(&id).copied());
            }
        }
    }

    #[test]
    fn arbitrary_files_never_panic(manifest in ".{0,200}", tool in prop::collection::vec(any::<u8>(), 0..300), markers in "[0-9a-z,.\\n -]{0,300}") {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        fs::create_dir_all(root.join("trials/a")).unwrap();
        fs::write(root.join("bundle.ron"), &manifest).unwrap();
        fs::write(root.join("markers_rest.csv"), "id,x,y\n0,0.01,0.01\n").unwrap();
        fs::write(root.join("trials/a/tool.csv"), &tool).unwrap();
        fs::write(root.join("trials/a/markers.csv"), format!("frame,t,id,x,y\n{markers}")).unwrap();
        let report = validate_bundle(root);
        // The manifest is garbage: at least that is an error, with a message.
        prop_assert!(report.has_errors());
        prop_assert!(report.issues.iter().all(|i| !i.message.is_empty()));
    }
}
