//! SVG plots drawn by the pipeline itself (the library crates draw their own).

use plotters::prelude::*;

/// Marker displacement field: rest positions and arrows to the displaced
/// positions, magnified so that the largest arrow is a tenth of the phantom.
pub fn marker_displacements(
    rest: &[[f64; 2]],
    displacement: &[[f64; 2]],
    (width, depth): (f64, f64),
    (entry, tip): ([f64; 2], [f64; 2]),
    title: &str,
) -> Result<String, String> {
    let largest = displacement
        .iter()
        .map(|d| d[0].hypot(d[1]))
        .fold(0.0, f64::max);
    let magnification = if largest > 0.0 {
        0.1 * width.max(depth) / largest
    } else {
        1.0
    };
    let mm = 1e3;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720, 720)).into_drawing_area();
        let draw_error = |e: DrawingAreaErrorKind<_>| format!("plotting {title}: {e:?}");
        root.fill(&WHITE).map_err(draw_error)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("{title} (arrows x{magnification:.0})"),
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(-2.0..width * mm + 2.0, depth * mm + 2.0..-2.0)
            .map_err(draw_error)?;
        chart
            .configure_mesh()
            .light_line_style(WHITE)
            .x_desc("x (mm)")
            .y_desc("y (mm), insertion direction")
            .draw()
            .map_err(draw_error)?;
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(entry[0] * mm, entry[1] * mm), (tip[0] * mm, tip[1] * mm)],
                RED.stroke_width(3),
            )))
            .map_err(draw_error)?
            .label("needle")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(3)));
        chart
            .draw_series(rest.iter().zip(displacement).map(|(p, d)| {
                PathElement::new(
                    vec![
                        (p[0] * mm, p[1] * mm),
                        (
                            (p[0] + magnification * d[0]) * mm,
                            (p[1] + magnification * d[1]) * mm,
                        ),
                    ],
                    BLUE.stroke_width(1),
                )
            }))
            .map_err(draw_error)?;
        chart
            .draw_series(
                rest.iter()
                    .map(|p| Circle::new((p[0] * mm, p[1] * mm), 2, BLACK.filled())),
            )
            .map_err(draw_error)?
            .label("marker at rest")
            .legend(|(x, y)| Circle::new((x + 10, y), 3, BLACK.filled()));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(draw_error)?;
        root.present().map_err(draw_error)?;
    }
    Ok(svg)
}
