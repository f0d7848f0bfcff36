//! Write a diagnosis: `diagnosis.ron`, `ladder.csv`, `model.ron` (fitted
//! parameters with 95 % intervals), `residuals_markers.csv` and
//! `residuals_forces.csv` (one row per residual with every variable it can
//! be plotted against: time, tip depth, velocity, day, position, distance
//! from the tool, radius from the image centre), and `residuals_trials.csv`
//! (the misfit of every trial, and the marker positions left out near
//! the probes).

use std::path::Path;

use ron::ser::PrettyConfig;
use serde::Serialize;

use crate::diagnose::DiagnosisRun;
use crate::error::DiagnoseError;

fn ron_file<T: Serialize>(path: &Path, value: &T) -> Result<(), DiagnoseError> {
    let config = PrettyConfig::new().struct_names(true);
    let text = ron::ser::to_string_pretty(value, config).map_err(|e| DiagnoseError::Serialize {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    std::fs::write(path, text + "\n").map_err(|source| DiagnoseError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn csv_file(path: &Path, header: &[&str], rows: Vec<Vec<String>>) -> Result<(), DiagnoseError> {
    let fail = |e: csv::Error| DiagnoseError::Serialize {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let mut writer = csv::Writer::from_path(path).map_err(fail)?;
    writer.write_record(header).map_err(fail)?;
    for row in rows {
        writer.write_record(&row).map_err(fail)?;
    }
    writer.flush().map_err(|source| DiagnoseError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes every output of `run` into `out_dir` (created if needed).
pub fn write_outputs(run: &DiagnosisRun, out_dir: &Path) -> Result<(), DiagnoseError> {
    std::fs::create_dir_all(out_dir).map_err(|source| DiagnoseError::Io {
        path: out_dir.to_path_buf(),
        source,
    })?;
    ron_file(&out_dir.join("diagnosis.ron"), &run.diagnosis)?;
    ron_file(&out_dir.join("model.ron"), &run.fitted)?;
    let ladder = run
        .ladder
        .rows
        .iter()
        .map(|row| {
            vec![
                row.step.to_string(),
                row.added.clone().unwrap_or_default(),
                row.model.join(" "),
                row.parameters.to_string(),
                row.fit.rms_marker.to_string(),
                row.fit.rms_force.to_string(),
                row.fit.chi2_marker.to_string(),
                row.fit.chi2_force.to_string(),
                format!("{:?}", row.verdict),
            ]
        })
        .collect();
    csv_file(
        &out_dir.join("ladder.csv"),
        &[
            "step",
            "added",
            "model",
            "parameters",
            "rms_marker",
            "rms_force",
            "chi2_marker",
            "chi2_force",
            "verdict",
        ],
        ladder,
    )?;
    let markers = run
        .marker_residuals
        .iter()
        .map(|r| {
            vec![
                run.trial_ids[r.trial].clone(),
                r.t.to_string(),
                r.marker.to_string(),
                r.x.to_string(),
                r.y.to_string(),
                r.rx.to_string(),
                r.ry.to_string(),
                r.velocity.to_string(),
                r.day.to_string(),
                r.tip_depth.to_string(),
                r.distance_from_tool.to_string(),
                r.radius.to_string(),
            ]
        })
        .collect();
    csv_file(
        &out_dir.join("residuals_markers.csv"),
        &[
            "trial",
            "t",
            "marker",
            "x",
            "y",
            "rx",
            "ry",
            "velocity",
            "day",
            "tip_depth",
            "distance_from_tool",
            "radius",
        ],
        markers,
    )?;
    let forces = run
        .force_residuals
        .iter()
        .map(|r| {
            vec![
                run.trial_ids[r.trial].clone(),
                r.t.to_string(),
                r.tip_depth.to_string(),
                r.velocity.to_string(),
                r.day.to_string(),
                r.rx.to_string(),
                r.ry.to_string(),
            ]
        })
        .collect();
    csv_file(
        &out_dir.join("residuals_forces.csv"),
        &["trial", "t", "tip_depth", "velocity", "day", "rx", "ry"],
        forces,
    )?;
    let trials = run
        .trials
        .iter()
        .map(|t| {
            vec![
                t.trial.clone(),
                t.marker_values.to_string(),
                t.rms_marker.to_string(),
                t.chi2_marker.to_string(),
                t.force_values.to_string(),
                t.rms_force.to_string(),
                t.chi2_force.to_string(),
                t.near_field_left_out.to_string(),
            ]
        })
        .collect();
    csv_file(
        &out_dir.join("residuals_trials.csv"),
        &[
            "trial",
            "marker_values",
            "rms_marker",
            "chi2_marker",
            "force_values",
            "rms_force",
            "chi2_force",
            "near_field_left_out",
        ],
        trials,
    )
}
