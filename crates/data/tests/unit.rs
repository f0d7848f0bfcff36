//! Unit tests of needle-data: the tiny fixture, warnings, writer rules.

use std::fs;
use std::path::{Path, PathBuf};

use needle_data::{
    BundleBuilder, BundleError, Campaign, Face, IssueKind, MarkerObservation, MarkerRest,
    MarkerTrack, Noise, Overwrite, Phantom, Severity, ToolSample, Trial, TrialKind,
    ValidationReport, WriteOptions, read_bundle, read_markers_csv, validate_bundle, write_bundle,
    write_markers_csv,
};

mod common;

use common::{copy_tree, grey_png, tiny};

/// A copy of the tiny bundle in a fresh temporary folder.
fn tiny_copy() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("tiny");
    copy_tree(&tiny(), &root);
    (dir, root)
}

fn kinds(report: &ValidationReport, severity: Severity) -> Vec<IssueKind> {
    report
        .issues
        .iter()
        .filter(|i| i.severity == severity)
        .map(|i| i.kind)
        .collect()
}

fn phantom() -> Phantom {
    Phantom {
        width: 0.075,
        depth: 0.075,
        thickness: 0.0075,
        fixed: vec![Face::Back],
    }
}

fn sample(t: f64) -> ToolSample {
    ToolSample {
        t,
        tip_x: 0.03,
        tip_y: 0.001 * t,
        theta: 0.0,
        fx: 0.0,
        fy: 0.1 * t,
        mz: 0.0,
    }
}

fn small_campaign() -> Campaign {
    let mut builder = BundleBuilder::new("small", phantom());
    builder.markers_rest(vec![
        MarkerRest {
            id: 0,
            x: 0.01,
            y: 0.01,
        },
        MarkerRest {
            id: 1,
            x: 0.02,
            y: 0.01,
        },
    ]);
    let trial = builder.trial(Trial {
        id: "probe-01".into(),
        kind: TrialKind::Probe,
        velocity: 0.001,
        day: 0.0,
    });
    trial.tool = vec![sample(0.0), sample(0.5)];
    trial
        .markers_mut()
        .push_frame(0, 0.0, [(1, [0.02, 0.01]), (0, [0.01, 0.01])])
        .unwrap();
    builder.finish()
}

mod tiny_fixture {
    use super::*;

    #[test]
    fn reads_clean_with_every_optional_part() {
        let bundle = read_bundle(tiny()).unwrap();
        assert!(bundle.warnings.is_empty(), "{}", bundle.warnings);
        let campaign = &bundle.campaign;
        assert_eq!(campaign.name, "tiny");
        assert_eq!(campaign.phantom, phantom());
        assert_eq!(
            campaign.noise,
            Some(Noise {
                marker_sigma: 8.0e-6,
                force_sigma: 0.005
            })
        );
        assert_eq!(campaign.markers_rest.len(), 9);
        assert_eq!(
            campaign.markers_rest.get(4).map(|m| (m.x, m.y)),
            Some((0.0375, 0.0375))
        );
        let ids: Vec<_> = campaign
            .trials
            .iter()
            .map(|t| t.trial.id.as_str())
            .collect();
        assert_eq!(ids, ["probe-01", "needle-01", "needle-02"]);
        assert_eq!(campaign.compression.as_ref().map(Vec::len), Some(3));
        assert!(
            campaign
                .calibration_dir
                .as_ref()
                .is_some_and(|d| d.is_dir())
        );
    }

    #[test]
    fn probe_trial_has_frames_tool_and_a_lost_marker() {
        let bundle = read_bundle(tiny()).unwrap();
        let probe = bundle.trial("probe-01").unwrap();
        assert_eq!(probe.trial.kind, TrialKind::Probe);
        assert_eq!(probe.tool.len(), 4);
        assert_eq!(probe.tool[3].t, 1.5);
        assert_eq!(probe.tool[3].fy, 0.30000000000000004);
        let numbers: Vec<_> = probe.frames.iter().map(|f| f.number).collect();
        assert_eq!(numbers, [0, 1, 2]);
        assert!(
            probe.frames[2]
                .path
                .ends_with("trials/probe-01/frames/000002.png")
        );
        assert_eq!(
            bundle.frames_dir("probe-01"),
            bundle.root.join("trials/probe-01/frames")
        );
        let track = probe.markers.as_ref().unwrap();
        assert_eq!(track.frame_count(), 3);
        assert_eq!(track.row_count(), 26);
        let frame1 = track.frame(1).unwrap();
        assert_eq!((frame1.frame, frame1.t, frame1.len()), (1, 0.5, 8));
        assert_eq!(frame1.position(4), None, "marker 4 is lost in frame 1");
        assert_eq!(frame1.position(0), Some([0.0125, 0.0126]));
        assert_eq!(frame1.to_map().len(), 8);
        assert!(!track.has_sigma());
    }

    #[test]
    fn force_only_trial_and_sigma_columns() {
        let bundle = read_bundle(tiny()).unwrap();
        let force_only = bundle.trial("needle-01").unwrap();
        assert!(force_only.markers.is_none() && force_only.frames.is_empty());
        assert_eq!(force_only.tool.len(), 5);
        let with_sigma = bundle.trial("needle-02").unwrap().markers.as_ref().unwrap();
        assert!(with_sigma.has_sigma());
        let frame = with_sigma.frame(0).unwrap();
        // The file lists ids 8, 0, 3; frames are stored sorted by id.
        assert_eq!(frame.ids, [0, 3, 8]);
        assert_eq!(frame.sigmas.unwrap()[2], [1e-5, 1.2e-5]);
        assert_eq!(frame.position(8), Some([0.0625, 0.0625]));
        let rows: Vec<MarkerObservation> = with_sigma.observations().collect();
        assert_eq!(rows.len(), 6);
        assert_eq!(rows[3].frame, 11);
        assert_eq!(rows[3].sigma, Some([1e-5, 1.2e-5]));
    }

    #[test]
    fn blanks_crlf_and_byte_order_marks_are_accepted() {
        let (_dir, root) = tiny_copy();
        let tool = "\u{feff}t, tip_x ,tip_y,theta,fx,fy,mz\r\n0.0, 0.0375 ,0.0,0.0,0.0,0.5,0.0\r\n0.5,0.0375,0.0005,0.0,0.0,0.75,0.0\r\n";
        fs::write(root.join("trials/needle-01/tool.csv"), tool).unwrap();
        let manifest = fs::read_to_string(root.join("bundle.ron")).unwrap();
        fs::write(root.join("bundle.ron"), format!("\u{feff}{manifest}")).unwrap();
        let bundle = read_bundle(&root).unwrap();
        assert!(bundle.warnings.is_empty(), "{}", bundle.warnings);
        let samples = &bundle.trial("needle-01").unwrap().tool;
        assert_eq!(samples.len(), 2);
        assert_eq!((samples[0].tip_x, samples[1].fy), (0.0375, 0.75));
    }

    #[test]
    fn validate_reports_nothing() {
        let report = validate_bundle(tiny());
        assert!(report.is_empty(), "{report}");
    }

    #[test]
    fn copy_through_the_writer_reads_back_equal() {
        let original = read_bundle(tiny()).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let copy = dir.path().join("copy");
        write_bundle(&copy, &original.campaign, WriteOptions::default()).unwrap();
        let reread = read_bundle(&copy).unwrap();
        let mut expected = original.campaign.clone();
        // Paths point at the copy; everything else is equal.
        for (trial, copied) in expected.trials.iter_mut().zip(&reread.campaign.trials) {
            assert_eq!(trial.frames.len(), copied.frames.len());
            for (frame, copied) in trial.frames.iter_mut().zip(&copied.frames) {
                assert_eq!(
                    fs::read(&frame.path).unwrap(),
                    fs::read(&copied.path).unwrap()
                );
                frame.path = copied.path.clone();
            }
        }
        expected.calibration_dir = Some(copy.join("calibration"));
        assert_eq!(reread.campaign, expected);
        assert!(copy.join("calibration/README.md").is_file());
    }
}

/// Entries the format names that exist but are not what it names: each is
/// an issue, never a silent skip, and a pipe is never opened (reading one
/// would wait for ever).
mod entries_that_cannot_be_read {
    use super::*;
    use std::os::unix::ffi::OsStrExt;

    /// The issues of one kind in the report of a tiny copy changed by `change`.
    fn issues_after(change: impl FnOnce(&Path), kind: IssueKind) -> Vec<(String, Severity)> {
        let (_dir, root) = tiny_copy();
        change(&root);
        validate_bundle(&root)
            .issues
            .iter()
            .filter(|i| i.kind == kind)
            .map(|i| (i.file.to_string_lossy().into_owned(), i.severity))
            .collect()
    }

    fn replace_by_folder(path: &Path) {
        fs::remove_file(path).unwrap();
        fs::create_dir(path).unwrap();
    }

    fn replace_by_dangling_link(path: &Path) {
        fs::remove_file(path).unwrap();
        std::os::unix::fs::symlink("/nonexistent/file.csv", path).unwrap();
    }

    fn replace_by_pipe(path: &Path) {
        fs::remove_file(path).unwrap();
        let status = std::process::Command::new("mkfifo")
            .arg(path)
            .status()
            .unwrap();
        assert!(status.success(), "mkfifo {}", path.display());
    }

    #[test]
    fn a_required_file_that_is_a_folder_or_a_dangling_link_is_unreadable_not_missing() {
        let io = |change: fn(&Path), file: &'static str| {
            let found = issues_after(|root| change(&root.join(file)), IssueKind::Io);
            assert_eq!(found, [(file.to_owned(), Severity::Error)], "{file}");
            let missing = issues_after(|root| change(&root.join(file)), IssueKind::MissingFile);
            assert!(missing.is_empty(), "{file}: {missing:?}");
        };
        io(replace_by_folder, "trials/needle-01/tool.csv");
        io(replace_by_folder, "markers_rest.csv");
        io(replace_by_dangling_link, "trials/needle-01/tool.csv");
        io(replace_by_pipe, "trials/needle-01/tool.csv");
    }

    #[test]
    fn an_optional_file_that_cannot_be_read_is_an_error_not_left_out() {
        let io = |change: fn(&Path), file: &'static str| {
            let found = issues_after(|root| change(&root.join(file)), IssueKind::Io);
            assert_eq!(found, [(file.to_owned(), Severity::Error)], "{file}");
        };
        io(replace_by_folder, "trials/probe-01/markers.csv");
        io(replace_by_dangling_link, "trials/probe-01/markers.csv");
        io(replace_by_pipe, "trials/probe-01/markers.csv");
        io(replace_by_folder, "compression.csv");
    }

    #[test]
    fn a_frames_entry_that_is_a_file_is_flagged() {
        let found = issues_after(
            |root| {
                let frames = root.join("trials/probe-01/frames");
                fs::remove_dir_all(&frames).unwrap();
                fs::write(&frames, "x").unwrap();
            },
            IssueKind::Suspicious,
        );
        assert_eq!(
            found,
            [("trials/probe-01/frames".to_owned(), Severity::Warning)]
        );
    }

    #[test]
    fn a_trial_folder_whose_name_is_not_text_is_unlisted_and_still_read() {
        let (_dir, root) = tiny_copy();
        let raw = std::ffi::OsStr::from_bytes(b"n\xffx");
        let folder = root.join("trials").join(raw);
        copy_tree(&root.join("trials/needle-01"), &folder);
        fs::write(
            folder.join("tool.csv"),
            "t,tip_x,tip_y,theta,fx,fy,mz\n0,0,0,0,0,x,0\n",
        )
        .unwrap();
        let report = validate_bundle(&root);
        let kinds: Vec<IssueKind> = report.issues.iter().map(|i| i.kind).collect();
        // Read through its real name: its bad value is found, and no file
        // is said to be missing.
        assert_eq!(
            kinds,
            [IssueKind::UnlistedTrialFolder, IssueKind::BadNumber],
            "{report}"
        );
        assert_eq!(report.issues[1].line, Some(2));
    }
}

mod warnings {
    use super::*;

    /// Rewrites one file of a tiny copy and returns the validation report.
    fn with_file(relative: &str, text: &str) -> ValidationReport {
        let (_dir, root) = tiny_copy();
        fs::write(root.join(relative), text).unwrap();
        let report = validate_bundle(&root);
        assert!(!report.has_errors(), "warnings only expected:\n{report}");
        // A bundle with warnings only still reads, and returns the warnings.
        let bundle = read_bundle(&root).unwrap();
        assert_eq!(bundle.warnings.issues, report.issues);
        report
    }

    fn single_warning(report: &ValidationReport) -> &needle_data::Issue {
        assert_eq!(report.issues.len(), 1, "{report}");
        &report.issues[0]
    }

    #[test]
    fn marker_positions_in_millimetres() {
        let report = with_file(
            "markers_rest.csv",
            "id,x,y\n0,12.5,12.5\n1,37.5,12.5\n2,62.5,12.5\n3,12.5,37.5\n4,37.5,37.5\n5,62.5,37.5\n6,12.5,62.5\n7,37.5,62.5\n8,62.5,62.5\n",
        );
        let issue = single_warning(&report);
        assert_eq!(issue.kind, IssueKind::Units);
        assert_eq!(issue.line, Some(2));
        assert!(
            issue.message.contains("millimetres") && issue.message.contains("9 rows"),
            "{issue}"
        );
    }

    #[test]
    fn tracked_positions_in_millimetres() {
        let report = with_file(
            "trials/needle-02/markers.csv",
            "frame,t,id,x,y\n0,0.0,0,12.5,12.5\n0,0.0,1,0.0375,0.0125\n",
        );
        let issue = single_warning(&report);
        assert_eq!((issue.kind, issue.line), (IssueKind::Units, Some(2)));
        assert_eq!(issue.file, Path::new("trials/needle-02/markers.csv"));
    }

    #[test]
    fn forces_in_the_kilonewton_range() {
        let report = with_file(
            "trials/needle-01/tool.csv",
            "t,tip_x,tip_y,theta,fx,fy,mz\n0.0,0.0375,0.0,0.0,0.0,0.5,0.0\n0.5,0.0375,0.0005,0.0,0.0,1500.0,0.0\n",
        );
        let issue = single_warning(&report);
        assert_eq!(
            (issue.kind, issue.line, issue.field.as_deref()),
            (IssueKind::Units, Some(3), Some("fx,fy"))
        );
        assert!(issue.message.contains("kilonewton"));
    }

    #[test]
    fn angles_in_degrees_and_tip_in_millimetres() {
        let report = with_file(
            "trials/needle-01/tool.csv",
            "t,tip_x,tip_y,theta,fx,fy,mz\n0.0,37.5,0.0,30.0,0.0,0.5,0.0\n",
        );
        let found = kinds(&report, Severity::Warning);
        assert_eq!(found, [IssueKind::Units, IssueKind::Units], "{report}");
        assert!(
            report
                .issues
                .iter()
                .any(|i| i.field.as_deref() == Some("theta"))
        );
        assert!(
            report
                .issues
                .iter()
                .any(|i| i.field.as_deref() == Some("tip_x,tip_y"))
        );
    }

    #[test]
    fn time_in_milliseconds() {
        let report = with_file(
            "trials/needle-01/tool.csv",
            "t,tip_x,tip_y,theta,fx,fy,mz\n0.0,0.0375,0.0,0.0,0.0,0.5,0.0\n5000.0,0.0375,0.005,0.0,0.0,0.6,0.0\n",
        );
        let issue = single_warning(&report);
        assert_eq!(
            (issue.kind, issue.field.as_deref()),
            (IssueKind::Units, Some("t"))
        );
    }

    #[test]
    fn velocity_above_one_metre_per_second() {
        let text = fs::read_to_string(tiny().join("bundle.ron"))
            .unwrap()
            .replace("velocity: 0.002", "velocity: 2.0");
        let report = with_file("bundle.ron", &text);
        let issue = single_warning(&report);
        assert_eq!(issue.kind, IssueKind::Units);
        assert_eq!(issue.field.as_deref(), Some("trials[2].velocity"));
        assert_eq!(issue.line, Some(20));
    }

    #[test]
    fn phantom_in_millimetres() {
        let text = fs::read_to_string(tiny().join("bundle.ron"))
            .unwrap()
            .replace("thickness: 0.0075", "thickness: 7.5");
        let report = with_file("bundle.ron", &text);
        let issue = single_warning(&report);
        assert_eq!((issue.kind, issue.line), (IssueKind::Units, Some(10)));
    }

    #[test]
    fn strain_in_percent() {
        let report = with_file("compression.csv", "strain,stress\n0,0\n5,250\n10,520\n");
        let issue = single_warning(&report);
        assert_eq!((issue.kind, issue.line), (IssueKind::Units, Some(3)));
    }

    #[test]
    fn unknown_files_and_repeated_time() {
        let (_dir, root) = tiny_copy();
        fs::write(root.join("notes.txt"), "x").unwrap();
        fs::write(root.join("trials/needle-01/marker.csv"), "x").unwrap();
        fs::write(root.join("trials/probe-01/frames/thumbs.db"), "x").unwrap();
        fs::write(root.join(".DS_Store"), "x").unwrap();
        fs::write(
            root.join("trials/needle-01/tool.csv"),
            "t,tip_x,tip_y,theta,fx,fy,mz\n0.0,0.0375,0.0,0.0,0.0,0.5,0.0\n0.0,0.0375,0.0,0.0,0.0,0.5,0.0\n",
        )
        .unwrap();
        let report = validate_bundle(&root);
        assert!(!report.has_errors(), "{report}");
        let files: Vec<_> = report
            .issues
            .iter()
            .map(|i| i.file.to_string_lossy().into_owned())
            .collect();
        // Root first, then the trials in manifest order.
        assert_eq!(
            files,
            [
                "notes.txt",
                "trials/probe-01/frames/thumbs.db",
                "trials/needle-01/marker.csv",
                "trials/needle-01/tool.csv"
            ],
            "{report}"
        );
        assert!(
            kinds(&report, Severity::Warning)
                .iter()
                .all(|k| *k == IssueKind::Suspicious)
        );
    }

    #[test]
    fn many_bad_rows_are_listed_then_counted() {
        let (_dir, root) = tiny_copy();
        let mut text = String::from("t,tip_x,tip_y,theta,fx,fy,mz\n");
        for k in 0..100 {
            text.push_str(&format!("{k},0.0375,NaN,0.0,0.0,0.5,0.0\n"));
        }
        fs::write(root.join("trials/needle-01/tool.csv"), text).unwrap();
        let report = validate_bundle(&root);
        let non_finite = report
            .issues
            .iter()
            .filter(|i| i.kind == IssueKind::NonFinite)
            .count();
        assert_eq!(non_finite, 20);
        let summary = report
            .issues
            .iter()
            .find(|i| i.kind == IssueKind::Suppressed)
            .unwrap();
        assert!(
            summary.message.contains("80 more") && summary.message.contains("100 in all"),
            "{summary}"
        );
        assert_eq!(summary.severity, Severity::Error);
    }

    #[test]
    fn report_display_names_file_line_and_field() {
        let (_dir, root) = tiny_copy();
        fs::write(root.join("trials/needle-01/tool.csv"), "t,tip_x,tip_y,theta,fx,fy,mz\n0.5,0.0375,0.0,0.0,0.0,0.5,0.0\n0.25,0.0375,0.0,0.0,0.0,0.5,0.0\n").unwrap();
        let Err(BundleError::Invalid { report }) = read_bundle(&root) else {
            panic!("time going backwards must fail");
        };
        let text = report.to_string();
        assert!(text.contains("1 error, 0 warnings"), "{text}");
        assert!(text.contains("error: trials/needle-01/tool.csv, line 3, t: time goes backwards: 0.25 s after 0.5 s at line 2"), "{text}");
    }
}

mod writer {
    use super::*;

    #[test]
    fn refuses_to_overwrite_unless_asked() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bundle");
        let campaign = small_campaign();
        write_bundle(&path, &campaign, WriteOptions::default()).unwrap();
        let err = write_bundle(&path, &campaign, WriteOptions::default()).unwrap_err();
        assert!(matches!(err, BundleError::AlreadyExists { .. }), "{err}");

        let mut renamed = campaign.clone();
        renamed.name = "renamed".into();
        write_bundle(
            &path,
            &renamed,
            WriteOptions {
                overwrite: Overwrite::Allow,
            },
        )
        .unwrap();
        assert_eq!(read_bundle(&path).unwrap().campaign, renamed);
        // Only the bundle remains: no staging or replaced copies left behind.
        let entries: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(entries, ["bundle"]);
    }

    #[test]
    fn never_replaces_a_folder_that_is_not_a_bundle() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("precious");
        fs::create_dir(&path).unwrap();
        fs::write(path.join("thesis.tex"), "years of work").unwrap();
        let err = write_bundle(&path, &small_campaign(), WriteOptions::overwrite()).unwrap_err();
        assert!(matches!(err, BundleError::NotABundle { .. }), "{err}");
        assert!(path.join("thesis.tex").is_file());
    }

    #[test]
    fn an_invalid_campaign_is_not_published() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bundle");
        let mut campaign = small_campaign();
        campaign.trials[0].tool.push(sample(f64::NAN));
        campaign.trials[0]
            .markers_mut()
            .push_frame(1, 1.0, [(7, [0.0, 0.0])])
            .unwrap();
        let Err(BundleError::Invalid { report }) =
            write_bundle(&path, &campaign, WriteOptions::default())
        else {
            panic!("an invalid campaign must not be written");
        };
        // t, tip_y and fy of the NaN sample, then the unknown marker.
        assert_eq!(
            kinds(&report, Severity::Error),
            [
                IssueKind::NonFinite,
                IssueKind::NonFinite,
                IssueKind::NonFinite,
                IssueKind::UnknownMarker
            ],
            "{report}"
        );
        assert_eq!(report.root, path);
        assert_eq!(
            fs::read_dir(dir.path()).unwrap().count(),
            0,
            "nothing left behind"
        );
    }

    #[test]
    fn an_invalid_campaign_leaves_the_old_bundle_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bundle");
        let campaign = small_campaign();
        write_bundle(&path, &campaign, WriteOptions::default()).unwrap();
        let mut broken = campaign.clone();
        broken.phantom.width = -1.0;
        assert!(write_bundle(&path, &broken, WriteOptions::overwrite()).is_err());
        assert_eq!(read_bundle(&path).unwrap().campaign, campaign);
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_bad_trial_id_never_writes_outside_the_bundle() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("inner").join("bundle");
        let mut campaign = small_campaign();
        campaign.trials[0].trial.id = "../../escape".into();
        let Err(BundleError::Invalid { report }) =
            write_bundle(&path, &campaign, WriteOptions::default())
        else {
            panic!("a bad trial id must be refused");
        };
        assert_eq!(
            kinds(&report, Severity::Error),
            [IssueKind::BadTrialId],
            "{report}"
        );
        assert!(!dir.path().join("escape").exists());
        assert_eq!(fs::read_dir(dir.path().join("inner")).unwrap().count(), 0);
    }

    #[test]
    fn builder_copies_frame_files() {
        let dir = tempfile::tempdir().unwrap();
        let scratch = dir.path().join("scratch.png");
        fs::write(&scratch, grey_png()).unwrap();
        let mut builder = BundleBuilder::new("frames", phantom());
        builder.markers_rest(vec![MarkerRest {
            id: 3,
            x: 0.01,
            y: 0.01,
        }]);
        let trial = builder.trial(Trial {
            id: "n".into(),
            kind: TrialKind::Needle,
            velocity: 0.001,
            day: 2.0,
        });
        trial.tool.push(sample(0.0));
        trial.add_frame_file(7, &scratch).unwrap();
        trial.add_frame_file(2, &scratch).unwrap();
        assert!(matches!(
            trial.add_frame_file(1_000_000, &scratch),
            Err(BundleError::FrameNumber { .. })
        ));
        let path = dir.path().join("bundle");
        builder.write(&path, WriteOptions::default()).unwrap();
        let bundle = read_bundle(&path).unwrap();
        let frames = &bundle.trial("n").unwrap().frames;
        assert_eq!(frames.iter().map(|f| f.number).collect::<Vec<_>>(), [2, 7]);
        assert_eq!(frames[1].path, path.join("trials/n/frames/000007.png"));
        assert_eq!(fs::read(&frames[1].path).unwrap(), grey_png());
    }

    #[test]
    fn markers_csv_round_trip_keeps_row_order_and_sigma() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("markers.csv");
        let rows: Vec<MarkerObservation> = (0..3u64)
            .flat_map(|frame| {
                [5u32, 2].map(move |id| MarkerObservation {
                    frame,
                    t: 0.1 * frame as f64,
                    id,
                    x: 0.01 + 1e-7 * f64::from(id),
                    y: 0.02,
                    sigma: Some([1e-6, 2e-6]),
                })
            })
            .collect();
        write_markers_csv(&path, &rows, WriteOptions::default()).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("frame,t,id,x,y,sx,sy\n0,0.0,5,"), "{text}");
        let (track, warnings) = read_markers_csv(&path).unwrap();
        assert!(warnings.is_empty());
        assert_eq!(track, MarkerTrack::from_observations(&rows).unwrap());
        assert!(matches!(
            write_markers_csv(&path, &rows, WriteOptions::default()),
            Err(BundleError::AlreadyExists { .. })
        ));
        write_markers_csv(&path, &rows[..2], WriteOptions::overwrite()).unwrap();
        assert_eq!(read_markers_csv(&path).unwrap().0.row_count(), 2);
    }

    #[test]
    fn markers_csv_refuses_invalid_rows() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("markers.csv");
        let row = |frame, id, x| MarkerObservation {
            frame,
            t: frame as f64,
            id,
            x,
            y: 0.0,
            sigma: None,
        };
        let rows = [row(1, 0, 0.0), row(1, 0, 0.0), row(0, 1, f64::INFINITY)];
        let Err(BundleError::Invalid { report }) =
            write_markers_csv(&path, &rows, WriteOptions::default())
        else {
            panic!("invalid rows must be refused");
        };
        assert_eq!(
            kinds(&report, Severity::Error),
            [
                IssueKind::DuplicateRow,
                IssueKind::NonFinite,
                IssueKind::FrameBackwards,
                IssueKind::TimeBackwards
            ],
            "{report}"
        );
        let mixed = [
            row(0, 0, 0.0),
            MarkerObservation {
                sigma: Some([0.0, 0.0]),
                ..row(0, 1, 0.0)
            },
        ];
        assert!(matches!(
            write_markers_csv(&path, &mixed, WriteOptions::default()),
            Err(BundleError::MixedSigma { row: 1 })
        ));
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn marker_track_keeps_sigma_mode() {
        let mut track = MarkerTrack::default();
        track.push_frame(0, 0.0, [(1, [0.0, 0.0])]).unwrap();
        assert!(matches!(
            track.push_frame_with_sigma(1, 1.0, [(1, [0.0, 0.0], [1e-6, 1e-6])]),
            Err(BundleError::MixedSigma { row: 1 })
        ));
        track.push_frame(1, 1.0, []).unwrap();
        assert_eq!(track.frame_count(), 1, "an empty frame is not stored");
    }
}
