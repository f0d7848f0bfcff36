//! The diagnosis part of a report, shared by `cargo xtask diagnose` and
//! the pipeline: the error ladder (table and plot), the candidates of the
//! final step, where the residual is on the phantom, and the residual
//! against every variable it may depend on.

use needle_diagnose::{
    Diagnosis, DiagnosisRun, MarkerResidual, energy_share_of_worst, residual_concentration,
};
use plotters::prelude::*;

use crate::report::Report;

const LADDER_HEADER: [&str; 8] = [
    "step",
    "added",
    "parameters",
    "rms marker (um)",
    "rms force (mN)",
    "chi2/dof marker",
    "chi2/dof force",
    "verdict",
];

/// The ladder as table rows (also printed by the commands).
pub fn ladder_rows(run: &DiagnosisRun) -> Vec<Vec<String>> {
    run.ladder
        .rows
        .iter()
        .map(|row| {
            vec![
                row.step.to_string(),
                row.added.clone().unwrap_or_else(|| "(model given)".into()),
                row.parameters.to_string(),
                fixed(row.fit.rms_marker * 1e6, 2),
                fixed(row.fit.rms_force * 1e3, 2),
                fixed(row.fit.chi2_marker, 2),
                fixed(row.fit.chi2_force, 2),
                format!("{:?}", row.verdict),
            ]
        })
        .collect()
}

/// `value` to `digits` decimals, or "-" for a channel without data (a
/// campaign without needle trials has no base force residuals).
fn fixed(value: f64, digits: usize) -> String {
    if value.is_finite() {
        format!("{value:.digits$}")
    } else {
        "-".into()
    }
}

/// Prints the ladder as a Markdown table.
pub fn print_ladder(run: &DiagnosisRun) {
    println!("| {} |", LADDER_HEADER.join(" | "));
    println!("|{}", "---|".repeat(LADDER_HEADER.len()));
    for row in ladder_rows(run) {
        println!("| {} |", row.join(" | "));
    }
    if let Some(text) = mesh_check(&run.diagnosis) {
        println!("mesh check: {text}");
    }
    for warning in step_warnings(run) {
        println!("warning: {warning}");
    }
}

/// The final model's warnings, after every step's doubt about the effect
/// it named: a doubt stays worth reading after the ladder has moved on.
fn step_warnings(run: &DiagnosisRun) -> Vec<String> {
    let doubts = (run.steps.iter().enumerate())
        .filter_map(|(step, d)| d.doubt.as_ref().map(|text| format!("(step {step}) {text}")));
    doubts
        .chain(run.diagnosis.warnings.iter().cloned())
        .collect()
}

/// What the mesh check found, in a sentence.
fn mesh_check(diagnosis: &Diagnosis) -> Option<String> {
    let c = diagnosis.discretisation?;
    let [coarse, fine] = c.refinements;
    Some(format!(
        "the plane model at refinement {fine} instead of {coarse} moves the first \
         fit's markers by {} um rms ({} um at most) and its base forces by {} mN rms, \
         a chi2 of {:.1}; an effect named with a likelihood ratio no larger is flagged",
        fixed(c.rms_marker * 1e6, 2),
        fixed(c.max_marker * 1e6, 2),
        fixed(c.rms_force * 1e3, 3),
        c.chi2
    ))
}

/// Adds the diagnosis sections to `report`, numbered from `number`.
pub fn add_sections(report: &mut Report, run: &DiagnosisRun, number: &str) -> Result<(), String> {
    let d = &run.diagnosis;
    let mut warnings: String = mesh_check(d)
        .map(|text| format!(" Mesh check: {text}."))
        .unwrap_or_default();
    warnings.extend(
        step_warnings(run)
            .iter()
            .map(|w| format!(" <b>Warning</b> {w}.")),
    );
    report.section(
        &format!("{number} Diagnosis: compare the model with the measurements"),
        &format!(
            "Bundle <code>{}</code>. Every trial is fitted jointly; residuals are whitened \
             by the noise ({}). Candidates (catalog effects not in the model) are ranked \
             by a score test at the fit and confirmed by refitting with the effect added; \
             an effect is named only when its likelihood-ratio p-value is below {:.2e} \
             (a family-wise false-alarm rate of 1%). Final model {:?}; verdict <b>{:?}</b>.\
             {warnings}",
            d.bundle, d.noise, d.threshold_p, d.model, d.verdict
        ),
        &[ladder_plot(run)?],
    );
    report.table(
        &format!("{number}a The error ladder"),
        &LADDER_HEADER,
        &ladder_rows(run),
    );
    let candidates: Vec<Vec<String>> = run
        .steps
        .iter()
        .enumerate()
        .flat_map(|(step, diagnosis)| {
            diagnosis.candidates.iter().map(move |c| {
                let or_dash = |value: Option<String>| value.unwrap_or_else(|| "-".into());
                let with = |chi2: f64| or_dash(c.refitted.then(|| fixed(chi2, 2)));
                vec![
                    step.to_string(),
                    c.effect.clone(),
                    format!("{:.1}", c.score),
                    format!("{:.2e}", c.score_p),
                    or_dash(c.likelihood_ratio.map(|v| format!("{v:.1}"))),
                    or_dash(c.likelihood_ratio_p.map(|v| format!("{v:.2e}"))),
                    with(c.fit_with.chi2_marker),
                    with(c.fit_with.chi2_force),
                ]
            })
        })
        .collect();
    report.table(
        &format!("{number}b Candidates at every step, best first"),
        &[
            "step",
            "effect",
            "score",
            "score p",
            "likelihood ratio (- : not refitted, score too small)",
            "p",
            "chi2/dof marker with it",
            "chi2/dof force with it",
        ],
        &candidates,
    );
    let parameters: Vec<Vec<String>> = run
        .fitted
        .parameters
        .iter()
        .map(|p| {
            vec![
                p.name.clone(),
                format!("{:.5e}", p.value),
                p.interval.map_or("not determined".into(), |(lo, hi)| {
                    format!("{lo:.4e} .. {hi:.4e}")
                }),
                p.meaning.clone(),
            ]
        })
        .collect();
    report.table(
        &format!("{number}c The fitted model"),
        &["parameter", "value", "95% interval", "meaning"],
        &parameters,
    );
    let trials: Vec<Vec<String>> = run
        .trials
        .iter()
        .map(|t| {
            vec![
                t.trial.clone(),
                fixed(t.rms_marker * 1e6, 2),
                fixed(t.chi2_marker, 3),
                fixed(t.rms_force * 1e3, 2),
                fixed(t.chi2_force, 3),
                t.near_field_left_out.to_string(),
            ]
        })
        .collect();
    report.table(
        &format!(
            "{number}d Misfit per trial (mean square of the whitened residuals: about 1 \
             where only the noise is left; a probe frame's markers near the contact, by \
             default within one phantom thickness, are left out: there the model's \
             idealised punch differs from any real one)"
        ),
        &[
            "trial",
            "rms marker (um)",
            "chi2 per value, marker",
            "rms force (mN)",
            "chi2 per value, force",
            "marker positions left out near the probe",
        ],
        &trials,
    );
    report.section(
        &format!("{number}e Where the final model fails"),
        &format!(
            "Residual (model minus data) of the final model: the RMS per marker over all \
             frames (colour), with the residual vectors of the worst frame (arrows); then \
             the marker residual against every variable it may depend on, the base-force \
             residual against tip depth per insertion, and where the residual energy \
             concentrates compared with where the markers are (last panel): the worst 10% \
             of the markers hold {:.0}% of it (an even residual: 10%).",
            100.0 * energy_share_of_worst(&residual_concentration(&run.marker_residuals), 0.1)
        ),
        &[residual_map(&run.marker_residuals)?, residual_panels(run)?],
    );
    Ok(())
}

fn draw_error<E>(e: DrawingAreaErrorKind<E>) -> String
where
    E: std::error::Error + Send + Sync,
{
    format!("plotting the diagnosis: {e:?}")
}

/// Chi-square per dof of each channel after every ladder step (log scale).
fn ladder_plot(run: &DiagnosisRun) -> Result<String, String> {
    let rows = &run.ladder.rows;
    let values: Vec<f64> = rows
        .iter()
        .flat_map(|r| [r.fit.chi2_marker, r.fit.chi2_force])
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let top = values.iter().copied().fold(2.0, f64::max) * 1.5;
    let bottom = values.iter().copied().fold(0.5, f64::min) * 0.7;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720, 400)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error)?;
        let steps = rows.len().max(1) as f64;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "The error ladder: chi2/dof after each step",
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.5..steps - 0.5, (bottom..top).log_scale())
            .map_err(draw_error)?;
        let labels: Vec<String> = rows
            .iter()
            .map(|r| r.added.clone().unwrap_or_else(|| "model given".into()))
            .collect();
        chart
            .configure_mesh()
            .x_labels(rows.len().max(1))
            .x_label_formatter(&|x| {
                let k = x.round();
                if (x - k).abs() < 1e-6 && k >= 0.0 {
                    labels.get(k as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .y_desc("chi2 / dof")
            .draw()
            .map_err(draw_error)?;
        chart
            .draw_series(LineSeries::new(
                [(-0.5, 1.0), (steps - 0.5, 1.0)],
                BLACK.stroke_width(1),
            ))
            .map_err(draw_error)?
            .label("noise level")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        for (channel, colour, pick) in [("markers", BLUE, 0usize), ("base force", RED, 1usize)] {
            let points: Vec<(f64, f64)> = rows
                .iter()
                .enumerate()
                .map(|(k, r)| {
                    let v = if pick == 0 {
                        r.fit.chi2_marker
                    } else {
                        r.fit.chi2_force
                    };
                    (k as f64, v)
                })
                .filter(|(_, v)| v.is_finite() && *v > 0.0)
                .collect();
            chart
                .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
                .map_err(draw_error)?
                .label(channel)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
            chart
                .draw_series(points.iter().map(|&p| Circle::new(p, 4, colour.filled())))
                .map_err(draw_error)?;
        }
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE)
            .draw()
            .map_err(draw_error)?;
        root.present().map_err(draw_error)?;
    }
    Ok(svg)
}

/// RMS residual per marker (colour) and the worst frame's residual arrows.
fn residual_map(residuals: &[MarkerResidual]) -> Result<String, String> {
    let mut per_marker: std::collections::BTreeMap<usize, ([f64; 2], f64, usize)> =
        Default::default();
    for r in residuals {
        let entry = per_marker.entry(r.marker).or_insert(([r.x, r.y], 0.0, 0));
        entry.1 += r.rx * r.rx + r.ry * r.ry;
        entry.2 += 1;
    }
    // The worst frame: largest summed squared residual.
    let mut frames: std::collections::BTreeMap<(usize, u64), f64> = Default::default();
    for r in residuals {
        *frames.entry((r.trial, r.t.to_bits())).or_default() += r.rx * r.rx + r.ry * r.ry;
    }
    let worst = frames
        .iter()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(k, _)| *k);
    let arrows: Vec<&MarkerResidual> = residuals
        .iter()
        .filter(|r| Some((r.trial, r.t.to_bits())) == worst)
        .collect();
    let rms: Vec<([f64; 2], f64)> = per_marker
        .values()
        .map(|(p, sum, n)| (*p, (sum / *n as f64).sqrt()))
        .collect();
    let largest_rms = rms.iter().map(|(_, v)| *v).fold(0.0, f64::max);
    let largest_arrow = arrows.iter().map(|r| r.rx.hypot(r.ry)).fold(0.0, f64::max);
    let (x_max, y_max) = rms.iter().fold((0.0f64, 0.0f64), |(a, b), (p, _)| {
        (a.max(p[0]), b.max(p[1]))
    });
    let extent = x_max.max(y_max).max(1e-3);
    let magnification = if largest_arrow > 0.0 {
        0.08 * extent / largest_arrow
    } else {
        1.0
    };
    let mm = 1e3;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720, 720)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!(
                    "Residual per marker: RMS up to {:.1} um (colour); worst frame x{magnification:.0}",
                    largest_rms * 1e6
                ),
                ("sans-serif", 16),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(
                -3.0..x_max * mm + 3.0,
                y_max * mm + 3.0..-3.0,
            )
            .map_err(draw_error)?;
        chart
            .configure_mesh()
            .light_line_style(WHITE)
            .x_desc("x (mm)")
            .y_desc("y (mm), insertion direction")
            .draw()
            .map_err(draw_error)?;
        chart
            .draw_series(rms.iter().map(|(p, v)| {
                let level = if largest_rms > 0.0 {
                    v / largest_rms
                } else {
                    0.0
                };
                let colour = HSLColor(0.66 * (1.0 - level), 0.9, 0.45);
                Circle::new((p[0] * mm, p[1] * mm), 5, colour.filled())
            }))
            .map_err(draw_error)?;
        chart
            .draw_series(arrows.iter().map(|r| {
                PathElement::new(
                    vec![
                        (r.x * mm, r.y * mm),
                        (
                            (r.x + magnification * r.rx) * mm,
                            (r.y + magnification * r.ry) * mm,
                        ),
                    ],
                    BLACK.stroke_width(1),
                )
            }))
            .map_err(draw_error)?;
        root.present().map_err(draw_error)?;
    }
    Ok(svg)
}

/// Marker residual magnitude against seven variables, the base-force
/// residual against tip depth, and the concentration curve of the residual
/// energy over the markers.
fn residual_panels(run: &DiagnosisRun) -> Result<String, String> {
    type Pick = fn(&MarkerResidual) -> f64;
    let variables: [(&str, Pick); 7] = [
        ("time (s)", |r| r.t),
        ("tip depth (mm)", |r| r.tip_depth * 1e3),
        ("velocity (mm/s)", |r| r.velocity * 1e3),
        ("day", |r| r.day),
        ("distance from tool (mm)", |r| r.distance_from_tool * 1e3),
        ("image radius (mm)", |r| r.radius * 1e3),
        ("marker depth y (mm)", |r| r.y * 1e3),
    ];
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 900)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error)?;
        let panels = root.split_evenly((3, 3));
        for (panel, (label, pick)) in panels.iter().zip(variables) {
            let points: Vec<(f64, f64)> = run
                .marker_residuals
                .iter()
                .map(|r| (pick(r), r.rx.hypot(r.ry) * 1e6))
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect();
            scatter(panel, &points, label, "|residual| (um)")?;
        }
        let forces: Vec<(f64, f64)> = run
            .force_residuals
            .iter()
            .map(|r| (r.tip_depth * 1e3, r.rx.hypot(r.ry).copysign(r.ry) * 1e3))
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        scatter(&panels[7], &forces, "tip depth (mm)", "force residual (mN)")?;
        concentration_panel(&panels[8], &residual_concentration(&run.marker_residuals))?;
        root.present().map_err(draw_error)?;
    }
    Ok(svg)
}

/// The concentration curve (worst markers first) against the diagonal an
/// even residual would follow.
fn concentration_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    curve: &[(f64, f64)],
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let fail = |e: DrawingAreaErrorKind<DB::ErrorType>| format!("plotting concentration: {e:?}");
    let mut chart = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(32)
        .y_label_area_size(48)
        .build_cartesian_2d(0.0..1.0, 0.0..1.0)
        .map_err(fail)?;
    chart
        .configure_mesh()
        .x_desc("share of markers, worst first")
        .y_desc("share of residual energy")
        .x_labels(5)
        .y_labels(5)
        .draw()
        .map_err(fail)?;
    chart
        .draw_series(LineSeries::new([(0.0, 0.0), (1.0, 1.0)], BLACK.mix(0.4)))
        .map_err(fail)?;
    chart
        .draw_series(LineSeries::new(curve.iter().copied(), RED.stroke_width(2)))
        .map_err(fail)?;
    Ok(())
}

fn scatter<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    points: &[(f64, f64)],
    x_label: &str,
    y_label: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let fail = |e: DrawingAreaErrorKind<DB::ErrorType>| format!("plotting {x_label}: {e:?}");
    let range = |values: &mut dyn Iterator<Item = f64>| {
        let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
        if lo.is_finite() && hi > lo {
            let pad = 0.05 * (hi - lo);
            (lo - pad, hi + pad)
        } else if lo.is_finite() {
            (lo - 1.0, lo + 1.0)
        } else {
            (0.0, 1.0)
        }
    };
    let (x0, x1) = range(&mut points.iter().map(|p| p.0));
    let (y0, y1) = range(&mut points.iter().map(|p| p.1));
    let mut chart = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(32)
        .y_label_area_size(48)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(fail)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .x_labels(5)
        .y_labels(5)
        .draw()
        .map_err(fail)?;
    chart
        .draw_series(
            points
                .iter()
                .map(|&p| Circle::new(p, 2, BLUE.mix(0.4).filled())),
        )
        .map_err(fail)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::fixed;

    #[test]
    fn a_channel_without_data_is_a_dash_not_nan() {
        assert_eq!(fixed(f64::NAN, 2), "-");
        assert_eq!(fixed(f64::INFINITY, 2), "-");
        assert_eq!(fixed(1.2345, 2), "1.23");
        assert_eq!(fixed(0.99713, 3), "0.997");
    }
}
