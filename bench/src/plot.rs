//! Figures for the benchmark reports: panels of point series, drawn with plotters into an RGB
//! buffer and written as a PNG with the `png` crate.
//!
//! Why this shape: every benchmark here plots cost against quality (time per step against
//! error, latency against percentile), one series per contender, one point per setting or
//! percentile, and the points that no other beats marked. Figures are read at a glance, by
//! people who did not write them, so the module takes the decisions that make them readable
//! out of the callers' hands:
//!
//! * every coordinate is drawn on a plain linear axis in a transformed space (log10 for
//!   [`Scale::Log`] and [`Scale::Nines`], the index for [`Scale::Categories`]) and the ticks
//!   are chosen here, never by plotters: a log axis gets at least three ticks even when its
//!   data spans less than a decade (1-2-5, then 1..9), a percentile axis is labelled in nines
//!   (p50, p90, p99, p99.9, p99.99) while keeping HdrHistogram's 1 / (1 - q) log scale under
//!   it, and a category axis is labelled with the names;
//! * the label areas are sized from the tick labels actually drawn (measured in the font), and
//!   a title too wide for its panel is drawn smaller: no label is clipped;
//! * the legend is one column to the right of all panels, never over the data; a label has one
//!   colour in every panel;
//! * a value at or below an axis' floor (a zero on a log axis) is drawn hollow on the floor,
//!   whose tick says "0" (or "<= floor" when some were small but not zero), and the legend says
//!   what hollow means;
//! * points are joined only when the caller says the order means something ([`Panel::join`]).
//!
//! Text needs a font; plotters' own font stack (font-kit) needs fontconfig and freetype
//! development libraries, so the text goes through ab_glyph with a TrueType font found at run
//! time (DejaVu Sans, Debian's `fonts-dejavu-core`, or `HB_PLOT_FONT`). Without one the figure
//! is still drawn, without its labels, and [`Figure::write_png`] says so.

use std::path::{Path, PathBuf};

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// One contender's points, in the caller's units (a log axis' values must be positive; a
/// category axis' values are the category's index, fractions allowed to set points side by
/// side within a category).
#[derive(Debug, Clone)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// A histogram by percentile on HdrHistogram's "nines" axis: x = 1 / (1 - percentile)
    /// (an x axis of [`Scale::Nines`] labels 2, 10, 100, 1000 as p50, p90, p99, p99.9), y in
    /// us (the histogram holds ns).
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

/// How an axis maps values to the page.
#[derive(Debug, Clone, PartialEq)]
pub enum Scale {
    Linear,
    /// Log10; ticks at decades, or 1-2-5 (then 1..9) when the data spans less.
    Log,
    /// HdrHistogram's percentile axis: the value is 1 / (1 - q), on a log scale, and the ticks
    /// are the nines: p50 (2), p90 (10), p99 (100), p99.9 (1000), p99.99 (10^4), ...
    Nines,
    /// Named categories: a value is a category's index (0, 1, ...), each name a tick. On a y
    /// axis the first category is at the top, so a figure reads like its table.
    Categories(Vec<String>),
}

/// One axis of a panel.
#[derive(Debug, Clone)]
pub struct Axis {
    /// Its name, with its unit.
    pub label: String,
    pub scale: Scale,
    /// Values at or below this (zeros on a log axis) are drawn hollow on it, at the axis'
    /// start, whose tick reads "0" (or "<= floor" when some were not zero): a log axis
    /// cannot show a zero, and the reader must not take the floor for a measurement.
    pub floor: Option<f64>,
    /// False: no tick labels (a panel beside one with the same categories, which names them).
    pub tick_labels: bool,
    /// When not empty, the ticks are these values (the sizes measured, say), not chosen here.
    pub ticks_at: Vec<f64>,
}

impl Axis {
    fn new(label: &str, scale: Scale) -> Axis {
        Axis {
            label: label.to_string(),
            scale,
            floor: None,
            tick_labels: true,
            ticks_at: Vec::new(),
        }
    }

    pub fn linear(label: &str) -> Axis {
        Axis::new(label, Scale::Linear)
    }

    pub fn log(label: &str) -> Axis {
        Axis::new(label, Scale::Log)
    }

    /// The percentile axis, titled "percentile".
    pub fn nines() -> Axis {
        Axis::new("percentile", Scale::Nines)
    }

    pub fn categories(label: &str, names: Vec<String>) -> Axis {
        Axis::new(label, Scale::Categories(names))
    }

    /// Values at or below `floor` are drawn hollow on it (see [`Axis::floor`]).
    pub fn with_floor(mut self, floor: f64) -> Axis {
        self.floor = Some(floor);
        self
    }

    /// Ticks at these values (see [`Axis::ticks_at`]).
    pub fn with_ticks_at(mut self, values: Vec<f64>) -> Axis {
        self.ticks_at = values;
        self
    }

    /// No tick labels (see [`Axis::tick_labels`]).
    pub fn without_tick_labels(mut self) -> Axis {
        self.tick_labels = false;
        self
    }
}

/// One panel: a title, its axes, its series and the points to mark (a Pareto front).
#[derive(Debug, Clone)]
pub struct Panel {
    pub title: String,
    pub x: Axis,
    pub y: Axis,
    pub series: Vec<Series>,
    /// Drawn as rings over the series' points, joined by a thin black line.
    pub marked: Vec<(f64, f64)>,
    /// Whether and how each series' points are joined, in order of x.
    pub join: Join,
}

/// How a series' points are joined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Join {
    /// Not at all: the points are unrelated cases, and a line from one to the next would
    /// claim a trend that is not there.
    No,
    /// A thin light line under large points: the points are one contender's settings, from
    /// cheap to dear; the line reads as "this contender" and the points stay what one reads.
    Settings,
    /// A solid line over small points: the series is a curve (a histogram by percentile).
    Curve,
}

/// Panels on a grid, and one legend column to the right of them all.
#[derive(Debug, Clone)]
pub struct Figure {
    pub panels: Vec<Panel>,
    pub columns: usize,
    /// A column's width when `column_weights` is empty; else the mean column width.
    pub panel_width: u32,
    pub panel_height: u32,
    /// Relative widths of the columns (empty: all equal).
    pub column_weights: Vec<u32>,
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

/// Text sizes, px.
const TICK_FONT: u32 = 13;
const AXIS_FONT: u32 = 14;
const TITLE_FONT: u32 = 17;
const LEGEND_FONT: u32 = 14;
/// Space around a panel's chart, px.
const MARGIN: u32 = 14;
/// A legend entry's height, px.
const LEGEND_ROW: i32 = 24;

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

/// The width and height of `text` at `size` px in the registered font (a generous estimate
/// when there is none: then nothing is written anyway).
fn text_size(text: &str, size: u32) -> (u32, u32) {
    ("sans-serif", size)
        .into_font()
        .box_size(text)
        .unwrap_or(((text.chars().count() as u32 * size * 6) / 10, size))
}

/// A tick's number, short: up to three significant digits, trailing zeros dropped, and
/// powers of ten as `1e-7` outside 0.001 .. 1000000.
pub fn number_label(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return if v == 0.0 { "0".into() } else { format!("{v}") };
    }
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) {
        let e = a.log10().floor();
        let m = v / 10f64.powf(e);
        let m = (m * 10.0).round() / 10.0;
        return if m.fract() == 0.0 {
            format!("{m:.0}e{e:.0}")
        } else {
            format!("{m:.1}e{e:.0}")
        };
    }
    let decimals = (2.0 - a.log10().floor()).clamp(0.0, 6.0) as usize;
    trim_zeros(format!("{v:.decimals$}"))
}

fn trim_zeros(s: String) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// The percentile that x = 1 / (1 - q) stands for, in nines: 2 -> "p50", 100 -> "p99",
/// 10^4 -> "p99.99".
pub fn nines_label(x: f64) -> String {
    let pct = 100.0 * (1.0 - 1.0 / x);
    let decimals = (x.log10().round() - 2.0).clamp(0.0, 6.0) as usize;
    format!("p{}", trim_zeros(format!("{pct:.decimals$}")))
}

/// An axis' ticks, in page space (see [`Axis::page`]): the labelled ones and the light lines
/// between them.
struct Ticks {
    bold: Vec<f64>,
    light: Vec<f64>,
    labels: Vec<(f64, String)>,
}

impl Ticks {
    fn label_of(&self, v: f64) -> String {
        self.labels
            .iter()
            .find(|(t, _)| (t - v).abs() < 1e-9)
            .map(|(_, s)| s.clone())
            .unwrap_or_default()
    }
}

/// A "nice" step (1, 2 or 5 times a power of ten) of at least `raw`.
fn nice_step(raw: f64) -> f64 {
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|s| *s >= raw * 0.999)
        .unwrap_or(10.0 * p)
}

/// Linear ticks over `lo..hi` (about five), as values.
fn linear_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let step = nice_step(((hi - lo) / 5.0).max(1e-300));
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last)
        .map(|k| {
            let v = k as f64 * step;
            if v.abs() < step * 1e-9 {
                0.0
            } else {
                v
            }
        })
        .collect()
}

impl Axis {
    fn is_log(&self) -> bool {
        matches!(self.scale, Scale::Log | Scale::Nines)
    }

    /// A value's place on the page's linear axis, and whether it is drawn on the floor
    /// (hollow); None for what cannot be drawn (NaN, or not positive on a log axis without a
    /// floor).
    fn page(&self, v: f64) -> Option<(f64, bool)> {
        if !v.is_finite() {
            return None;
        }
        let (v, floored) = match self.floor {
            Some(f) if v <= f => (f, true),
            _ => (v, false),
        };
        let t = match &self.scale {
            Scale::Linear => v,
            Scale::Log | Scale::Nines if v > 0.0 => v.log10(),
            Scale::Log | Scale::Nines => return None,
            Scale::Categories(_) => v,
        };
        Some((t, floored))
    }

    /// The page range for these page values; `floor` is the floor's page value when some
    /// value was drawn on it: then the axis starts there (nothing is below a floor), and
    /// reaches at least a decade (log) above it even when every value is on it.
    fn range(&self, values: &[f64], floor: Option<f64>) -> (f64, f64) {
        if let Scale::Categories(names) = &self.scale {
            return (-0.5, names.len().max(1) as f64 - 0.5);
        }
        let (mut lo, mut hi) = values
            .iter()
            .chain(&floor)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        if !lo.is_finite() {
            return (0.0, 1.0);
        }
        let least = if self.is_log() {
            1.0
        } else {
            (lo.abs() * 0.2).max(1.0)
        };
        if hi - lo < 1e-12 {
            match floor {
                Some(_) => hi = lo + least,
                None => {
                    lo -= least / 2.0;
                    hi += least / 2.0;
                }
            }
        }
        let pad = 0.06 * (hi - lo);
        (lo - pad, hi + pad)
    }

    /// The ticks over the page range `lo..hi`; `floored` is whether any value was drawn on
    /// the floor, and `all_zero` whether those were all exactly 0.
    fn ticks(&self, lo: f64, hi: f64, floored: bool, all_zero: bool) -> Ticks {
        let mut t = Ticks {
            bold: Vec::new(),
            light: Vec::new(),
            labels: Vec::new(),
        };
        let inside = |v: f64| v >= lo - 1e-12 && v <= hi + 1e-12;
        let at: Vec<(f64, String)> = self
            .ticks_at
            .iter()
            .filter_map(|v| Some((self.page(*v)?.0, number_label(*v))))
            .filter(|(t, _)| inside(*t))
            .collect();
        match &self.scale {
            _ if !at.is_empty() => t.labels = at,
            Scale::Categories(names) => {
                for (i, n) in names.iter().enumerate() {
                    t.labels.push((i as f64, n.clone()));
                }
            }
            Scale::Linear => {
                for v in linear_ticks(lo, hi) {
                    t.labels.push((v, number_label(v)));
                }
            }
            Scale::Nines => {
                let mut xs: Vec<f64> = [2.0f64, 10.0, 100.0, 1e3, 1e4, 1e5, 1e6, 1e7]
                    .into_iter()
                    .filter(|x: &f64| inside(x.log10()))
                    .collect();
                if xs.len() < 3 {
                    // A short histogram: p75 and p95 as well.
                    xs.extend([4.0, 20.0].into_iter().filter(|x: &f64| inside(x.log10())));
                    xs.sort_by(f64::total_cmp);
                }
                for x in xs {
                    t.labels.push((x.log10(), nines_label(x)));
                }
            }
            Scale::Log => {
                let (d0, d1) = (lo.floor() as i32 - 1, hi.ceil() as i32 + 1);
                let with = |ms: &[f64]| -> Vec<f64> {
                    (d0..=d1)
                        .flat_map(|d| ms.iter().map(move |m| m * 10f64.powi(d)))
                        .filter(|v| inside(v.log10()))
                        .collect()
                };
                let mut vs = with(&[1.0]);
                if vs.len() >= 3 {
                    // Decades labelled; the 2..9 multiples as light lines when not crowded.
                    if vs.len() <= 4 {
                        t.light = with(&[2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0])
                            .into_iter()
                            .map(f64::log10)
                            .collect();
                    }
                } else {
                    vs = with(&[1.0, 2.0, 5.0]);
                    if vs.len() < 3 {
                        vs = with(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
                    }
                    if vs.len() < 3 {
                        vs = linear_ticks(10f64.powf(lo), 10f64.powf(hi))
                            .into_iter()
                            .filter(|v| *v > 0.0)
                            .collect();
                    }
                }
                for v in vs {
                    t.labels.push((v.log10(), number_label(v)));
                }
            }
        }
        if let (true, Some(f)) = (floored, self.floor) {
            if let Some((fp, _)) = self.page(f) {
                // The floor's tick replaces any too close to it to read apart.
                // Nothing is below the floor.
                let gap = 0.15 * (hi - lo);
                t.labels.retain(|(v, _)| *v > fp + gap);
                t.light.retain(|v| *v > fp + gap);
                let label = if all_zero {
                    "0".to_string()
                } else {
                    format!("≤{}", number_label(f))
                };
                t.labels.insert(0, (fp, label));
            }
        }
        t.bold = t.labels.iter().map(|(v, _)| *v).collect();
        t
    }
}

/// A linear page axis whose ticks are the ones chosen here ([`Ticks`]), never plotters' own.
struct Keyed {
    lo: f64,
    hi: f64,
    bold: Vec<f64>,
    light: Vec<f64>,
}

impl Ranged for Keyed {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, v: &f64, limit: (i32, i32)) -> i32 {
        let f = (v - self.lo) / (self.hi - self.lo);
        limit.0 + (f * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<H: KeyPointHint>(&self, hint: H) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

/// A label's colour: the palette in order of the labels' first appearance in the figure, so
/// one contender has one colour in every panel.
struct Colours(Vec<String>);

impl Colours {
    fn of(&self, label: &str) -> RGBColor {
        let k = self.0.iter().position(|l| l == label).unwrap_or(0);
        PALETTE[k % PALETTE.len()]
    }
}

/// A point on the page: x, y (page space), and whether it is drawn hollow on a floor.
type Placed = (f64, f64, bool);

/// A panel laid out: its points in page space (x, y, hollow), its ranges and ticks.
struct Layout {
    series: Vec<(String, Vec<Placed>)>,
    marked: Vec<(f64, f64)>,
    x: (f64, f64, Ticks),
    y: (f64, f64, Ticks),
    any_floored: bool,
    all_floored_zero: bool,
}

impl Panel {
    fn layout(&self) -> Layout {
        let flip_y = |t: f64| match &self.y.scale {
            Scale::Categories(names) => (names.len().max(1) - 1) as f64 - t,
            _ => t,
        };
        let place = |p: &(f64, f64)| -> Option<(f64, f64, bool, bool)> {
            let (x, fx) = self.x.page(p.0)?;
            let (y, fy) = self.y.page(p.1)?;
            let zero = (!fx || p.0 == 0.0) && (!fy || p.1 == 0.0);
            Some((x, flip_y(y), fx || fy, zero))
        };
        let (mut any_floored, mut all_zero) = ([false; 2], true);
        let series: Vec<(String, Vec<Placed>)> = self
            .series
            .iter()
            .map(|s| {
                let pts = s
                    .points
                    .iter()
                    .filter_map(|p| {
                        let (x, y, hollow, zero) = place(p)?;
                        if hollow {
                            any_floored[0] |= self.x.page(p.0).is_some_and(|v| v.1);
                            any_floored[1] |= self.y.page(p.1).is_some_and(|v| v.1);
                            all_zero &= zero;
                        }
                        Some((x, y, hollow))
                    })
                    .collect();
                (s.label.clone(), pts)
            })
            .collect();
        let marked: Vec<(f64, f64)> = self
            .marked
            .iter()
            .filter_map(|p| place(p).map(|(x, y, _, _)| (x, y)))
            .collect();
        let axis = |axis: &Axis, floored: bool, get: &dyn Fn(&Placed) -> f64| {
            let values: Vec<f64> = series.iter().flat_map(|(_, p)| p.iter().map(get)).collect();
            let floor = axis
                .floor
                .and_then(|f| axis.page(f))
                .map(|(f, _)| f)
                .filter(|_| floored);
            let (lo, hi) = axis.range(&values, floor);
            let ticks = axis.ticks(lo, hi, floored, all_zero);
            (lo, hi, ticks)
        };
        let x = axis(&self.x, any_floored[0], &|p| p.0);
        let (ylo, yhi, mut yt) = axis(&self.y, any_floored[1], &|p| p.1);
        for (v, _) in yt.labels.iter_mut() {
            *v = flip_y(*v);
        }
        yt.bold = yt.labels.iter().map(|(v, _)| *v).collect();
        Layout {
            series,
            marked,
            x,
            y: (ylo, yhi, yt),
            any_floored: any_floored[0] || any_floored[1],
            all_floored_zero: all_zero,
        }
    }
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    panel: &Panel,
    layout: &Layout,
    colours: &Colours,
    text: bool,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let (x0, x1, xt) = &layout.x;
    let (y0, y1, yt) = &layout.y;
    let mut b = ChartBuilder::on(area);
    b.margin(MARGIN).margin_right(MARGIN + 6);
    if text {
        // The title in the largest size up to TITLE_FONT that fits the panel's width.
        let room = area.dim_in_pixel().0.saturating_sub(2 * MARGIN);
        let size = (10..=TITLE_FONT)
            .rev()
            .find(|s| text_size(&panel.title, *s).0 <= room)
            .unwrap_or(10);
        let widest = |t: &Ticks, on: bool| {
            if on {
                t.labels
                    .iter()
                    .map(|(_, s)| text_size(s, TICK_FONT).0)
                    .max()
                    .unwrap_or(0)
            } else {
                0
            }
        };
        let y_area = widest(yt, panel.y.tick_labels) + 14 + AXIS_FONT + 10;
        let x_area = TICK_FONT + 12 + AXIS_FONT + 12;
        b.caption(&panel.title, ("sans-serif", size))
            .x_label_area_size(x_area)
            .y_label_area_size(y_area);
        // The last x tick's label hangs half its width past the chart: room for it.
        if let Some((_, s)) = xt.labels.last() {
            b.margin_right(MARGIN + text_size(s, TICK_FONT).0 / 2);
        }
    } else {
        b.x_label_area_size(8).y_label_area_size(8);
    }
    let xr = Keyed {
        lo: *x0,
        hi: *x1,
        bold: xt.bold.clone(),
        light: xt.light.clone(),
    };
    let yr = Keyed {
        lo: *y0,
        hi: *y1,
        bold: yt.bold.clone(),
        light: yt.light.clone(),
    };
    let mut chart = b.build_cartesian_2d(xr, yr).map_err(e)?;
    {
        let x_fmt = |v: &f64| {
            if panel.x.tick_labels {
                xt.label_of(*v)
            } else {
                String::new()
            }
        };
        let y_fmt = |v: &f64| {
            if panel.y.tick_labels {
                yt.label_of(*v)
            } else {
                String::new()
            }
        };
        let mut mesh = chart.configure_mesh();
        mesh.bold_line_style(RGBColor(222, 222, 222))
            .light_line_style(RGBColor(243, 243, 243));
        if text {
            mesh.x_desc(&panel.x.label)
                .y_desc(&panel.y.label)
                .x_label_formatter(&x_fmt)
                .y_label_formatter(&y_fmt)
                .label_style(("sans-serif", TICK_FONT))
                .axis_desc_style(("sans-serif", AXIS_FONT));
        } else {
            mesh.x_label_formatter(&|_| String::new())
                .y_label_formatter(&|_| String::new());
        }
        mesh.draw().map_err(e)?;
    }
    for (label, pts) in &layout.series {
        let colour = colours.of(label);
        let dense = panel.join == Join::Curve;
        if panel.join != Join::No {
            let mut line: Vec<(f64, f64)> = pts.iter().map(|p| (p.0, p.1)).collect();
            line.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
            let style = if dense {
                colour.stroke_width(2)
            } else {
                colour.mix(0.45).stroke_width(1)
            };
            chart.draw_series(LineSeries::new(line, style)).map_err(e)?;
        }
        let radius = if dense { 2 } else { 4 };
        chart
            .draw_series(
                pts.iter()
                    .filter(|p| !p.2)
                    .map(|p| Circle::new((p.0, p.1), radius, colour.filled())),
            )
            .map_err(e)?;
        chart
            .draw_series(
                pts.iter()
                    .filter(|p| p.2)
                    .map(|p| Circle::new((p.0, p.1), 4, WHITE.filled())),
            )
            .map_err(e)?;
        chart
            .draw_series(
                pts.iter()
                    .filter(|p| p.2)
                    .map(|p| Circle::new((p.0, p.1), 4, colour.stroke_width(2))),
            )
            .map_err(e)?;
    }
    if !layout.marked.is_empty() {
        let mut front = layout.marked.clone();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(front.clone(), BLACK.stroke_width(1)))
            .map_err(e)?;
        chart
            .draw_series(
                front
                    .iter()
                    .map(|p| Circle::new(*p, 8, BLACK.stroke_width(2))),
            )
            .map_err(e)?;
    }
    Ok(())
}

/// One line of the legend column.
enum Entry {
    Series { label: String, joined: bool },
    Front,
    Hollow { all_zero: bool },
}

impl Entry {
    fn text(&self) -> String {
        match self {
            Entry::Series { label, .. } => label.clone(),
            Entry::Front => "Pareto front".into(),
            Entry::Hollow { all_zero: true } => "hollow: 0 (on the \"0\" tick)".into(),
            Entry::Hollow { all_zero: false } => "hollow: at or below the first (≤) tick".into(),
        }
    }
}

fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    entries: &[Entry],
    colours: &Colours,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let style = ("sans-serif", LEGEND_FONT)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    // Level with the panels' charts (below their titles).
    let top = (MARGIN + TITLE_FONT + 16) as i32;
    for (k, entry) in entries.iter().enumerate() {
        let y = top + k as i32 * LEGEND_ROW;
        match entry {
            Entry::Series { label, joined } => {
                let c = colours.of(label);
                if *joined {
                    area.draw(&PathElement::new(
                        vec![(6, y), (30, y)],
                        c.mix(0.6).stroke_width(2),
                    ))
                    .map_err(e)?;
                }
                area.draw(&Circle::new((18, y), 4, c.filled())).map_err(e)?;
            }
            Entry::Front => {
                area.draw(&Circle::new((18, y), 8, BLACK.stroke_width(2)))
                    .map_err(e)?;
            }
            Entry::Hollow { .. } => {
                area.draw(&Circle::new(
                    (18, y),
                    4,
                    RGBColor(90, 90, 90).stroke_width(2),
                ))
                .map_err(e)?;
            }
        }
        area.draw_text(&entry.text(), &style, (38, y)).map_err(e)?;
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
        let layouts: Vec<Layout> = self.panels.iter().map(Panel::layout).collect();

        let mut labels: Vec<String> = Vec::new();
        let mut entries = Vec::new();
        for p in &self.panels {
            for s in &p.series {
                if !labels.contains(&s.label) {
                    labels.push(s.label.clone());
                    let joined = self
                        .panels
                        .iter()
                        .any(|q| q.join != Join::No && q.series.iter().any(|t| t.label == s.label));
                    entries.push(Entry::Series {
                        label: s.label.clone(),
                        joined,
                    });
                }
            }
        }
        if layouts.iter().any(|l| !l.marked.is_empty()) {
            entries.push(Entry::Front);
        }
        if layouts.iter().any(|l| l.any_floored) {
            entries.push(Entry::Hollow {
                all_zero: layouts
                    .iter()
                    .filter(|l| l.any_floored)
                    .all(|l| l.all_floored_zero),
            });
        }
        let colours = Colours(labels);
        let legend_w = if text {
            entries
                .iter()
                .map(|en| text_size(&en.text(), LEGEND_FONT).0)
                .max()
                .unwrap_or(0)
                + 38
                + 16
        } else {
            0
        };

        let total_cols_w = self.panel_width * columns as u32;
        let weights: Vec<u32> = if self.column_weights.len() == columns {
            self.column_weights.iter().map(|w| (*w).max(1)).collect()
        } else {
            vec![1; columns]
        };
        let weight_sum: u32 = weights.iter().sum();
        let mut x_breaks = Vec::new();
        let mut acc = 0;
        for w in &weights[..columns - 1] {
            acc += total_cols_w * w / weight_sum;
            x_breaks.push(acc as i32);
        }
        let y_breaks: Vec<i32> = (1..rows)
            .map(|r| (r as u32 * self.panel_height) as i32)
            .collect();
        let legend_h = (MARGIN + TITLE_FONT + 16) as i32 + entries.len() as i32 * LEGEND_ROW;
        let (w, h) = (
            total_cols_w + legend_w,
            (self.panel_height * rows as u32).max(legend_h as u32 + MARGIN),
        );
        let mut buf = vec![0u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| PlotError(e.to_string()))?;
            let (grid, legend) = root.split_horizontally(total_cols_w);
            let grid = grid.shrink((0, 0), (total_cols_w, self.panel_height * rows as u32));
            let areas = grid.split_by_breakpoints(&x_breaks, &y_breaks);
            for ((panel, layout), area) in self.panels.iter().zip(&layouts).zip(areas.iter()) {
                draw_panel(area, panel, layout, &colours, text)
                    .map_err(|e| PlotError(format!("panel {:?}: {e}", panel.title)))?;
            }
            if text {
                draw_legend(&legend, &entries, &colours).map_err(PlotError)?;
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
    fn percentiles_are_labelled_in_nines() {
        let labels: Vec<String> = [2.0, 10.0, 100.0, 1e3, 1e4, 1e5]
            .into_iter()
            .map(nines_label)
            .collect();
        assert_eq!(labels, ["p50", "p90", "p99", "p99.9", "p99.99", "p99.999"]);
        let t = Axis::nines().ticks(0.0, 3.5, false, false);
        let names: Vec<&str> = t.labels.iter().map(|(_, s)| s.as_str()).collect();
        assert_eq!(names, ["p50", "p90", "p99", "p99.9"]);
    }

    #[test]
    fn numbers_are_short() {
        for (v, s) in [
            (0.0, "0"),
            (1.0, "1"),
            (1000.0, "1000"),
            (0.001, "0.001"),
            (0.25, "0.25"),
            (1e-7, "1e-7"),
            (2e5, "200000"),
            (2e6, "2e6"),
            (0.30000000000000004, "0.3"),
        ] {
            assert_eq!(number_label(v), s, "{v}");
        }
    }

    #[test]
    fn a_log_axis_has_at_least_three_ticks_however_narrow_its_data() {
        let axis = Axis::log("e");
        for (lo, hi) in [(0.1, 0.5), (2.0, 2.2), (-3.0, 3.0), (1.31, 1.32)] {
            let t = axis.ticks(lo, hi, false, false);
            assert!(t.labels.len() >= 3, "{lo}..{hi}: {:?}", t.labels);
            let mut seen: Vec<&String> = t.labels.iter().map(|(_, s)| s).collect();
            seen.dedup();
            assert_eq!(seen.len(), t.labels.len(), "{lo}..{hi}: labels repeat");
        }
    }

    #[test]
    fn a_floor_is_labelled_zero_and_its_points_hollow() {
        let axis = Axis::log("e").with_floor(1e-3);
        assert_eq!(axis.page(0.0), Some((-3.0, true)));
        assert_eq!(axis.page(1.0), Some((0.0, false)));
        let t = axis.ticks(-3.2, 0.5, true, true);
        assert_eq!(t.labels[0], (-3.0, "0".to_string()));
        assert!(t.labels.iter().all(|(v, _)| *v == -3.0 || *v > -2.9));
    }

    /// Every kind of axis, drawn; with HB_PLOT_SAMPLES=DIR the PNG stays there to be looked at.
    #[test]
    fn a_figure_of_every_kind_of_axis_is_written_as_a_png() {
        let keep = std::env::var_os("HB_PLOT_SAMPLES").map(PathBuf::from);
        let dir = keep.clone().unwrap_or_else(|| {
            std::env::temp_dir().join(format!("hb-plot-{}", std::process::id()))
        });
        std::fs::create_dir_all(&dir).unwrap();
        let mut h = hdrhistogram::Histogram::<u64>::new(3).unwrap();
        for k in 1..20_000u64 {
            h.record(20_000 + (k * 7919) % 30_000 + if k % 997 == 0 { 400_000 } else { 0 })
                .unwrap();
        }
        let names: Vec<String> = ["tower-3", "pyramid-knocked", "far-10000km"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let f = Figure {
            panels: vec![
                Panel {
                    title: "a histogram by percentile".into(),
                    x: Axis::nines(),
                    y: Axis::log("latency (us)"),
                    series: vec![Series::nines("a stage with a long name", &h)],
                    marked: Vec::new(),
                    join: Join::Curve,
                },
                Panel {
                    title: "a narrow log axis, zeros on the floor, a front".into(),
                    x: Axis::log("us per simulated second"),
                    y: Axis::log("error (m)").with_floor(1e-3),
                    series: vec![Series {
                        label: "b".into(),
                        points: vec![(100.0, 0.0), (130.0, 0.02), (180.0, 0.05)],
                    }],
                    marked: vec![(100.0, 1e-3)],
                    join: Join::Settings,
                },
                Panel {
                    title: "cases by name".into(),
                    x: Axis::log("drift (m)").with_floor(1e-9),
                    y: Axis::categories("", names),
                    series: vec![Series {
                        label: "c".into(),
                        points: vec![(0.0, 0.0), (1e-6, 1.0), (3e-3, 2.0)],
                    }],
                    marked: Vec::new(),
                    join: Join::No,
                },
            ],
            columns: 3,
            panel_width: 420,
            panel_height: 320,
            column_weights: Vec::new(),
        };
        let path = dir.join("every-axis.png");
        f.write_png(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        if keep.is_none() {
            std::fs::remove_dir_all(&dir).unwrap();
        }
    }
}
