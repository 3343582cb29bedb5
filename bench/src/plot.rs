//! Figures for the benchmark reports: panels of log-log (or linear) point series joined by
//! lines, drawn with plotters into an RGB buffer and written as a PNG with the `png` crate.
//!
//! Why this shape: every benchmark here plots cost against quality (time per step against
//! error, latency against load), one line per contender, one point per setting, and the
//! points that no other beats marked. Text needs a font; plotters' own font stack (font-kit)
//! needs fontconfig and freetype development libraries, so the text goes through ab_glyph
//! with a TrueType font found at run time (DejaVu Sans, Debian's `fonts-dejavu-core`, or
//! `HB_PLOT_FONT`). Without one the figure is still drawn, without its labels, and
//! [`Figure::write_png`] says so.

use std::path::{Path, PathBuf};

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// One contender's points, joined in the order given.
#[derive(Debug, Clone)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// A histogram by percentile on HdrHistogram's "nines" axis: x = 1 / (1 - percentile)
    /// (1, 10, 100, 1000: the median, p90, p99, p99.9), y in us (the histogram holds ns).
    pub fn nines(label: &str, h: &hdrhistogram::Histogram<u64>) -> Series {
        Series {
            label: label.to_string(),
            points: h
                .iter_quantiles(2)
                .filter(|v| v.quantile_iterated_to() < 1.0)
                .map(|v| {
                    (
                        1.0 / (1.0 - v.quantile_iterated_to()),
                        (v.value_iterated_to() as f64 / 1000.0).max(0.01),
                    )
                })
                .collect(),
        }
    }
}

/// One panel: a title, axis names, its series and the points to mark (a Pareto front).
#[derive(Debug, Clone)]
pub struct Panel {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub log_x: bool,
    pub log_y: bool,
    pub series: Vec<Series>,
    /// Drawn as rings over the series' points, joined by a dashed-looking thin line.
    pub marked: Vec<(f64, f64)>,
    /// The corner the legend goes in: the one the data leaves empty.
    pub legend: Legend,
}

/// Where a panel's legend goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Legend {
    /// In the upper right corner, over whatever data is there.
    UpperRight,
    /// In the upper left corner, above the data: the y axis reaches a third higher (on its
    /// own scale) than the data, for a legend of up to ~9 series over series that rise from
    /// left to right.
    AboveData,
}

/// Panels on a grid.
#[derive(Debug, Clone)]
pub struct Figure {
    pub panels: Vec<Panel>,
    pub columns: usize,
    pub panel_width: u32,
    pub panel_height: u32,
}

/// What went wrong writing a figure.
#[derive(Debug)]
pub struct PlotError(pub String);

impl std::fmt::Display for PlotError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for PlotError {}

const PALETTE: [RGBColor; 10] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0xe3, 0x77, 0xc2),
    RGBColor(0x7f, 0x7f, 0x7f),
    RGBColor(0xbc, 0xbd, 0x22),
    RGBColor(0x17, 0xbe, 0xcf),
];

/// Where a font may be: `HB_PLOT_FONT`, then the usual Debian and Fedora places.
fn font_candidates() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::env::var_os("HB_PLOT_FONT")
        .map(PathBuf::from)
        .into_iter()
        .collect();
    for p in [
        "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
        "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    ] {
        v.push(PathBuf::from(p));
    }
    v
}

/// Registers a font for plotters once per process; false when none was found.
fn ensure_font() -> bool {
    static FONT: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *FONT.get_or_init(|| {
        for p in font_candidates() {
            if let Ok(bytes) = std::fs::read(&p) {
                // plotters keeps fonts for the process's life: leak the bytes once.
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                if plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok() {
                    return true;
                }
            }
        }
        false
    })
}

fn range(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return if log { (0.1, 10.0) } else { (0.0, 1.0) };
    }
    if log {
        // At least a decade, so the log axis gets round labels.
        let (mut lo, mut hi) = (lo / 1.5, hi * 1.5);
        if hi / lo < 10.0 {
            let mid = (lo * hi).sqrt();
            lo = mid / 3.2;
            hi = mid * 3.2;
        }
        (lo, hi)
    } else {
        let pad = ((hi - lo) * 0.08).max(1e-9);
        (lo - pad, hi + pad)
    }
}

fn draw_panel<DB: DrawingBackend, X, Y>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    panel: &Panel,
    x: X,
    y: Y,
    text: bool,
) -> Result<(), String>
where
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let mut b = ChartBuilder::on(area);
    b.margin(12);
    if text {
        b.caption(&panel.title, ("sans-serif", 18))
            .x_label_area_size(36)
            .y_label_area_size(56);
    } else {
        b.x_label_area_size(8).y_label_area_size(8);
    }
    let mut chart = b.build_cartesian_2d(x, y).map_err(e)?;
    {
        let mut mesh = chart.configure_mesh();
        mesh.light_line_style(RGBColor(235, 235, 235));
        if text {
            mesh.x_desc(&panel.x_label)
                .y_desc(&panel.y_label)
                .x_labels(5)
                .y_labels(5)
                .label_style(("sans-serif", 12))
                .axis_desc_style(("sans-serif", 13));
        } else {
            mesh.x_labels(0).y_labels(0);
        }
        mesh.draw().map_err(e)?;
    }
    for (k, s) in panel.series.iter().enumerate() {
        let color = PALETTE[k % PALETTE.len()];
        let mut pts: Vec<(f64, f64)> = s
            .points
            .iter()
            .copied()
            .filter(|(a, b)| a.is_finite() && b.is_finite())
            .collect();
        // The line joins a model's settings in order of cost, thin and light, so that it reads
        // as "this model, cheap to dear" and the points (the settings) stay what one looks at.
        pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        let line = chart
            .draw_series(LineSeries::new(
                pts.clone(),
                color.mix(0.45).stroke_width(1),
            ))
            .map_err(e)?;
        if text {
            line.label(&s.label).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
        }
        chart
            .draw_series(pts.iter().map(|p| Circle::new(*p, 4, color.filled())))
            .map_err(e)?;
    }
    if !panel.marked.is_empty() {
        let mut front = panel.marked.clone();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(front.clone(), BLACK.stroke_width(1)))
            .map_err(e)?;
        let rings = chart
            .draw_series(
                front
                    .iter()
                    .map(|p| Circle::new(*p, 8, BLACK.stroke_width(2))),
            )
            .map_err(e)?;
        if text {
            rings
                .label("Pareto front")
                .legend(|(x, y)| Circle::new((x + 9, y), 6, BLACK.stroke_width(2)));
        }
    }
    if text {
        chart
            .configure_series_labels()
            .position(match panel.legend {
                Legend::AboveData => SeriesLabelPosition::UpperLeft,
                Legend::UpperRight => SeriesLabelPosition::UpperRight,
            })
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .label_font(("sans-serif", 12))
            .draw()
            .map_err(e)?;
    }
    Ok(())
}

impl Figure {
    /// Draws the figure and writes it as an 8-bit RGB PNG. Returns whether text was drawn
    /// (false: no font was found; the figure has no labels).
    pub fn write_png(&self, path: &Path) -> Result<bool, PlotError> {
        let text = ensure_font();
        let columns = self.columns.max(1);
        let rows = self.panels.len().div_ceil(columns).max(1);
        let (w, h) = (
            self.panel_width * columns as u32,
            self.panel_height * rows as u32,
        );
        let mut buf = vec![0u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| PlotError(e.to_string()))?;
            let areas = root.split_evenly((rows, columns));
            for (panel, area) in self.panels.iter().zip(areas.iter()) {
                let xs = panel
                    .series
                    .iter()
                    .flat_map(|s| s.points.iter().map(|p| p.0));
                let ys = panel
                    .series
                    .iter()
                    .flat_map(|s| s.points.iter().map(|p| p.1));
                let (x0, x1) = range(xs, panel.log_x);
                let (y0, mut y1) = range(ys, panel.log_y);
                if panel.legend == Legend::AboveData {
                    y1 = if panel.log_y {
                        y1 * (y1 / y0).powf(0.55)
                    } else {
                        y1 + 0.55 * (y1 - y0)
                    };
                }
                let r = match (panel.log_x, panel.log_y) {
                    (true, true) => draw_panel(
                        area,
                        panel,
                        (x0..x1).log_scale(),
                        (y0..y1).log_scale(),
                        text,
                    ),
                    (true, false) => draw_panel(area, panel, (x0..x1).log_scale(), y0..y1, text),
                    (false, true) => draw_panel(area, panel, x0..x1, (y0..y1).log_scale(), text),
                    (false, false) => draw_panel::<_, RangedCoordf64, RangedCoordf64>(
                        area,
                        panel,
                        (x0..x1).into(),
                        (y0..y1).into(),
                        text,
                    ),
                };
                r.map_err(|e| PlotError(format!("panel {:?}: {e}", panel.title)))?;
            }
            root.present().map_err(|e| PlotError(e.to_string()))?;
        }
        write_rgb_png(path, w, h, &buf)?;
        Ok(text)
    }
}

fn write_rgb_png(path: &Path, w: u32, h: u32, rgb: &[u8]) -> Result<(), PlotError> {
    let fail = |e: &dyn std::fmt::Display| PlotError(format!("{}: {e}", path.display()));
    let file = std::fs::File::create(path).map_err(|e| fail(&e))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::High);
    let mut writer = enc.write_header().map_err(|e| fail(&e))?;
    writer.write_image_data(rgb).map_err(|e| fail(&e))?;
    writer.finish().map_err(|e| fail(&e))?;
    Ok(())
}

/// The points of `points` (cost, error) that no other point beats in both (lower is better in
/// both): the Pareto front, sorted by cost.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[a].1.total_cmp(&points[b].1))
    });
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for i in idx {
        if points[i].1 < best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pareto_front_keeps_only_points_no_other_beats() {
        let p = [
            (1.0, 10.0),
            (2.0, 5.0),
            (3.0, 7.0),
            (4.0, 1.0),
            (0.5, 20.0),
            (5.0, 1.0),
        ];
        assert_eq!(pareto_front(&p), vec![4, 0, 1, 3]);
    }

    #[test]
    fn a_figure_is_written_as_a_png() {
        let dir = std::env::temp_dir().join(format!("hb-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = Figure {
            panels: vec![Panel {
                title: "t".into(),
                x_label: "x".into(),
                y_label: "y".into(),
                log_x: true,
                log_y: true,
                series: vec![Series {
                    label: "a".into(),
                    points: vec![(1.0, 2.0), (10.0, 0.5)],
                }],
                marked: vec![(1.0, 2.0)],
                legend: Legend::UpperRight,
            }],
            columns: 1,
            panel_width: 200,
            panel_height: 150,
        };
        let path = dir.join("f.png");
        f.write_png(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
