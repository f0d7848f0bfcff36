//! The crate's figures as SVG strings (plotters, SVG backend), for the
//! pipeline's report: node forces (Fig. 9), shaft distributions
//! (Fig. 10), integrated against base force (Figs. 11 and 13), density
//! against velocity (Fig. 14) and the distribution in a layered phantom
//! (Fig. 15). Lengths are plotted in millimetres, forces in newtons.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::error::ForceError;
use crate::estimate::ShaftDistribution;
use crate::nodal::PaperNodalForces;
use crate::series::IntegratedSeries;
use crate::velocity::VelocityPoint;

const SIZE: (u32, u32) = (800, 520);
const MM: f64 = 1e3;

/// One curve along the shaft: positions from the entry (m) and values.
#[derive(Debug, Clone, PartialEq)]
pub struct ShaftCurve {
    /// Legend text.
    pub label: String,
    /// Arc length from the entry (m).
    pub s: Vec<f64>,
    /// Values (N/m for densities, N for node forces).
    pub values: Vec<f64>,
}

impl ShaftCurve {
    /// The density of a regularised distribution (N/m).
    pub fn from_distribution(label: impl Into<String>, d: &ShaftDistribution) -> Self {
        Self {
            label: label.into(),
            s: d.stations.clone(),
            values: d.density.clone(),
        }
    }

    /// The axial node forces along the shaft of the paper's method (N).
    pub fn from_nodal(label: impl Into<String>, n: &PaperNodalForces) -> Self {
        Self {
            label: label.into(),
            s: n.shaft_positions.clone(),
            values: n.shaft_axial_forces(),
        }
    }
}

fn plot_error(figure: &'static str) -> impl Fn(String) -> ForceError {
    move |message| ForceError::Plot { figure, message }
}

/// Runs `draw` on a white SVG canvas and returns the document.
fn render(
    figure: &'static str,
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> Result<(), String>,
) -> Result<String, ForceError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE)
            .map_err(|e| plot_error(figure)(e.to_string()))?;
        draw(&root).map_err(plot_error(figure))?;
        root.present()
            .map_err(|e| plot_error(figure)(e.to_string()))?;
    }
    Ok(svg)
}

/// A range around finite values with a 5% margin (and a unit range when
/// all values are equal).
fn range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return 0.0..1.0;
    }
    let pad = if hi > lo {
        0.05 * (hi - lo)
    } else {
        0.5 * lo.abs().max(1e-12)
    };
    (lo - pad)..(hi + pad)
}

fn palette(k: usize) -> RGBColor {
    const COLOURS: [RGBColor; 8] = [
        RGBColor(31, 119, 180),
        RGBColor(214, 39, 40),
        RGBColor(44, 160, 44),
        RGBColor(255, 127, 14),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(227, 119, 194),
        RGBColor(23, 190, 207),
    ];
    COLOURS[k % COLOURS.len()]
}

/// Fig. 9: node forces $f = Ku$ over the marker mesh, as arrows scaled to
/// the largest force; shaft nodes red, reaction nodes blue.
pub fn plot_nodal_forces(forces: &PaperNodalForces) -> Result<String, ForceError> {
    if forces.nodes.is_empty() {
        return Err(ForceError::Empty("plot of node forces"));
    }
    let x = range(forces.nodes.iter().map(|p| p[0] * MM));
    let y = range(forces.nodes.iter().map(|p| p[1] * MM));
    let spacing = (x.end - x.start).min(y.end - y.start) / (forces.nodes.len() as f64).sqrt();
    let largest = forces
        .forces
        .iter()
        .map(|f| f[0].hypot(f[1]))
        .fold(0.0, f64::max);
    let scale = if largest > 0.0 {
        1.5 * spacing / largest
    } else {
        0.0
    };
    render("node forces", |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!(
                    "Node forces f = Ku at depth {:.1} mm (largest {:.3} N)",
                    forces.length * MM,
                    largest
                ),
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(x.clone(), y.clone())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("x (mm)")
            .y_desc("y (mm), insertion direction")
            .draw()
            .map_err(|e| e.to_string())?;
        let shaft: std::collections::HashSet<usize> = forces.shaft_nodes.iter().copied().collect();
        let reaction: std::collections::HashSet<usize> =
            forces.reaction_nodes.iter().copied().collect();
        let tip = [
            forces.entry[0] + forces.length * forces.axis[0],
            forces.entry[1] + forces.length * forces.axis[1],
        ];
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![
                    (forces.entry[0] * MM, forces.entry[1] * MM),
                    (tip[0] * MM, tip[1] * MM),
                ],
                BLACK.stroke_width(2),
            )))
            .map_err(|e| e.to_string())?;
        for (n, (p, f)) in forces.nodes.iter().zip(&forces.forces).enumerate() {
            let colour = if shaft.contains(&n) {
                RED
            } else if reaction.contains(&n) {
                BLUE
            } else {
                RGBColor(120, 120, 120)
            };
            let start = (p[0] * MM, p[1] * MM);
            let end = (start.0 + scale * f[0], start.1 + scale * f[1]);
            chart
                .draw_series(
                    [Circle::new(start, 2, colour.filled())]
                        .into_iter()
                        .chain(std::iter::empty()),
                )
                .map_err(|e| e.to_string())?;
            chart
                .draw_series(std::iter::once(PathElement::new(vec![start, end], colour)))
                .map_err(|e| e.to_string())?;
        }
        Ok(())
    })
}

/// Fig. 10: curves along the shaft, e.g. the paper's node forces at
/// several depths (Fig. 10a, N) or regularised densities at several
/// velocities (Fig. 10b, N/m). `unit` labels the value axis.
pub fn plot_shaft_distributions(
    title: &str,
    unit: &str,
    curves: &[ShaftCurve],
) -> Result<String, ForceError> {
    if curves.iter().all(|c| c.s.is_empty()) {
        return Err(ForceError::Empty("plot of shaft distributions"));
    }
    let x = range(
        curves
            .iter()
            .flat_map(|c| c.s.iter().map(|s| s * MM))
            .chain([0.0]),
    );
    let y = range(
        curves
            .iter()
            .flat_map(|c| c.values.iter().copied())
            .chain([0.0]),
    );
    render("shaft distributions", |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x.clone(), y.clone())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("distance from entry along the shaft (mm)")
            .y_desc(unit)
            .draw()
            .map_err(|e| e.to_string())?;
        for (k, c) in curves.iter().enumerate() {
            let colour = palette(k);
            let points: Vec<(f64, f64)> =
                c.s.iter()
                    .zip(&c.values)
                    .map(|(s, v)| (s * MM, *v))
                    .collect();
            chart
                .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label(c.label.clone())
                .legend(move |(a, b)| {
                    PathElement::new(vec![(a, b), (a + 20, b)], colour.stroke_width(2))
                });
            chart
                .draw_series(
                    points
                        .into_iter()
                        .map(|p| Circle::new(p, 2, colour.filled())),
                )
                .map_err(|e| e.to_string())?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| e.to_string())?;
        Ok(())
    })
}

/// Figs. 11 and 13: integrated shaft force of each series against depth,
/// with the measured base force of the first series (black, dashed).
pub fn plot_integrated_vs_base(
    title: &str,
    series: &[IntegratedSeries],
) -> Result<String, ForceError> {
    let first = series
        .first()
        .filter(|s| !s.points.is_empty())
        .ok_or(ForceError::Empty("plot of integrated force"))?;
    let x = range(
        series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.depth * MM))
            .chain([0.0]),
    );
    let y = range(
        series
            .iter()
            .flat_map(|s| s.points.iter().flat_map(|p| [p.integrated, p.base_force]))
            .chain([0.0]),
    );
    render("integrated against base force", |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x.clone(), y.clone())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("needle depth (mm)")
            .y_desc("axial force (N)")
            .draw()
            .map_err(|e| e.to_string())?;
        let base: Vec<(f64, f64)> = first
            .points
            .iter()
            .map(|p| (p.depth * MM, p.base_force))
            .collect();
        chart
            .draw_series(DashedLineSeries::new(base, 6, 4, BLACK.stroke_width(2)))
            .map_err(|e| e.to_string())?
            .label("measured base force")
            .legend(|(a, b)| PathElement::new(vec![(a, b), (a + 20, b)], BLACK.stroke_width(2)));
        for (k, s) in series.iter().enumerate() {
            let colour = palette(k);
            let points: Vec<(f64, f64)> = s
                .points
                .iter()
                .map(|p| (p.depth * MM, p.integrated))
                .collect();
            chart
                .draw_series(LineSeries::new(points, colour.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label(format!("{} ({})", s.method, s.trial))
                .legend(move |(a, b)| {
                    PathElement::new(vec![(a, b), (a + 20, b)], colour.stroke_width(2))
                });
            let flagged: Vec<(f64, f64)> = s
                .points
                .iter()
                .filter(|p| p.flagged)
                .map(|p| (p.depth * MM, p.integrated))
                .collect();
            chart
                .draw_series(
                    flagged
                        .into_iter()
                        .map(|p| Cross::new(p, 4, colour.stroke_width(1))),
                )
                .map_err(|e| e.to_string())?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| e.to_string())?;
        Ok(())
    })
}

/// Fig. 14: mean shaft density behind the tip against insertion velocity,
/// with the spread over trials as error bars.
pub fn plot_density_vs_velocity(points: &[VelocityPoint]) -> Result<String, ForceError> {
    if points.is_empty() {
        return Err(ForceError::Empty("plot of density against velocity"));
    }
    let x = range(points.iter().map(|p| p.velocity * MM).chain([0.0]));
    let y = range(
        points
            .iter()
            .flat_map(|p| [p.density - p.spread, p.density + p.spread])
            .chain([0.0]),
    );
    render("density against velocity", |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                "Shaft force density behind the tip against insertion velocity",
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x.clone(), y.clone())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("velocity (mm/s)")
            .y_desc("shaft force density (N/m)")
            .draw()
            .map_err(|e| e.to_string())?;
        let colour = palette(0);
        chart
            .draw_series(LineSeries::new(
                points.iter().map(|p| (p.velocity * MM, p.density)),
                colour.stroke_width(2),
            ))
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(points.iter().map(|p| {
                ErrorBar::new_vertical(
                    p.velocity * MM,
                    p.density - p.spread,
                    p.density,
                    p.density + p.spread,
                    colour.filled(),
                    8,
                )
            }))
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(
                points
                    .iter()
                    .map(|p| Circle::new((p.velocity * MM, p.density), 4, colour.filled())),
            )
            .map_err(|e| e.to_string())?;
        Ok(())
    })
}

/// Fig. 15: distributions during an insertion into a layered phantom, with
/// the layer interfaces (y, m) as vertical lines.
pub fn plot_layered_distribution(
    distributions: &[ShaftDistribution],
    interfaces: &[f64],
) -> Result<String, ForceError> {
    if distributions.is_empty() {
        return Err(ForceError::Empty("plot of a layered distribution"));
    }
    let x = range(
        distributions
            .iter()
            .flat_map(|d| d.stations.iter().map(|s| s * MM))
            .chain([0.0]),
    );
    let y = range(
        distributions
            .iter()
            .flat_map(|d| d.density.iter().copied())
            .chain([0.0]),
    );
    render("layered distribution", |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                "Shaft force density in a layered phantom",
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x.clone(), y.clone())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("distance from entry along the shaft (mm)")
            .y_desc("axial force density (N/m)")
            .draw()
            .map_err(|e| e.to_string())?;
        for &b in interfaces {
            chart
                .draw_series(DashedLineSeries::new(
                    vec![(b * MM, y.start), (b * MM, y.end)],
                    4,
                    4,
                    BLACK.stroke_width(1),
                ))
                .map_err(|e| e.to_string())?;
        }
        for (k, d) in distributions.iter().enumerate() {
            let colour = palette(k);
            let points: Vec<(f64, f64)> = d
                .stations
                .iter()
                .zip(&d.density)
                .map(|(s, q)| (s * MM, *q))
                .collect();
            chart
                .draw_series(LineSeries::new(points, colour.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label(format!("depth {:.1} mm", d.length * MM))
                .legend(move |(a, b)| {
                    PathElement::new(vec![(a, b), (a + 20, b)], colour.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| e.to_string())?;
        Ok(())
    })
}
