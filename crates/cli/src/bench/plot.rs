//! Line charts for the bench (plotters, bitmap backend, the DejaVu Sans font shipped in the repo),
//! saved as PNG with image 0.25 through `output::write_atomically`.

use std::path::Path;

use plotters::prelude::*;

use crate::CliError;
use crate::output::write_atomically;

const FONT: &[u8] = include_bytes!("../../../../assets/fonts/DejaVuSans.ttf");
const WIDTH: u32 = 960;
const HEIGHT: u32 = 540;

/// One named line of a chart.
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Draw a dot on every point (for sparse data such as the budget sweep).
    pub markers: bool,
    /// Index into the palette: fixed per meaning (a mode, a policy), so a mode keeps its colour
    /// whatever `--modes` asks for and in what order.
    pub color: usize,
}

/// A horizontal reference line (e.g. the millisecond budget).
pub struct HLine {
    pub name: String,
    pub y: f64,
}

pub struct Chart<'a> {
    pub title: String,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub series: Vec<Series>,
    pub hline: Option<HLine>,
}

/// Draws `chart` and writes it to `path` as an RGB PNG.
pub fn write_chart(path: &Path, chart: &Chart) -> Result<(), CliError> {
    let rgb = draw(chart).map_err(|e| CliError::failure(format!("{}: cannot draw chart: {e}", path.display())))?;
    write_atomically(path, |tmp| {
        let img = image::RgbImage::from_raw(WIDTH, HEIGHT, rgb).ok_or("chart buffer has the wrong size")?;
        img.save_with_format(tmp, image::ImageFormat::Png).map_err(|e| e.to_string())
    })
}

/// The axis range covering `values` with a little margin (a unit range around a single value).
fn range(values: impl Iterator<Item = f64>, from_zero: bool) -> (f64, f64) {
    let (mut lo, mut hi) = values.filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if from_zero {
        lo = lo.min(0.0);
    }
    if hi - lo < 1e-9 {
        hi = lo + lo.abs().max(1.0) * 0.5;
    }
    let pad = (hi - lo) * 0.05;
    (if from_zero && lo >= 0.0 { lo } else { lo - pad }, hi + pad)
}

fn draw(chart: &Chart) -> Result<Vec<u8>, String> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).map_err(|_| "the bundled font is not a valid TTF".to_string())?;
    let mut rgb = vec![0u8; (WIDTH * HEIGHT * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let xs = range(chart.series.iter().flat_map(|s| s.points.iter().map(|p| p.0)), false);
        let ys = range(chart.series.iter().flat_map(|s| s.points.iter().map(|p| p.1)).chain(chart.hline.as_ref().map(|h| h.y)), true);
        let mut ctx = ChartBuilder::on(&root)
            .caption(chart.title.as_str(), ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(xs.0..xs.1, ys.0..ys.1)
            .map_err(|e| e.to_string())?;
        ctx.configure_mesh()
            .x_desc(chart.x_label)
            .y_desc(chart.y_label)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .draw()
            .map_err(|e| e.to_string())?;
        for s in &chart.series {
            let color = Palette99::pick(s.color).to_rgba();
            ctx.draw_series(LineSeries::new(s.points.iter().copied(), color.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label(s.name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            if s.markers {
                ctx.draw_series(s.points.iter().map(|&p| Circle::new(p, 4, color.filled()))).map_err(|e| e.to_string())?;
            }
        }
        if let Some(h) = &chart.hline {
            let style = BLACK.mix(0.6).stroke_width(1);
            ctx.draw_series(LineSeries::new([(xs.0, h.y), (xs.1, h.y)], style))
                .map_err(|e| e.to_string())?
                .label(h.name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        }
        ctx.configure_series_labels()
            .label_font(("sans-serif", 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(rgb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges() {
        assert_eq!(range([1.0, 3.0].into_iter(), true), (0.0, 3.15));
        let (lo, hi) = range([2.0, 4.0].into_iter(), false);
        assert!((lo - 1.9).abs() < 1e-9 && (hi - 4.1).abs() < 1e-9);
        // One value or none still gives a non-empty range.
        let (lo, hi) = range([5.0].into_iter(), false);
        assert!(hi > lo && lo < 5.0 && hi > 5.0);
        assert_eq!(range(std::iter::empty(), true), (0.0, 1.0));
    }

    #[test]
    fn draws_a_chart_with_text() {
        let chart = Chart {
            title: "t".into(),
            x_label: "x",
            y_label: "y",
            series: vec![Series { name: "a".into(), points: vec![(0.0, 1.0), (1.0, 2.0)], markers: true, color: 0 }],
            hline: Some(HLine { name: "budget".into(), y: 1.5 }),
        };
        let rgb = draw(&chart).unwrap();
        assert_eq!(rgb.len(), (WIDTH * HEIGHT * 3) as usize);
        // Something other than the white background was drawn.
        assert!(rgb.iter().filter(|&&b| b < 128).count() > 1000);
    }
}
