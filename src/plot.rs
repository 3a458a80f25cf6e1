//! Figures in the style of the paper's Figs. 3–5, on plain data; every
//! figure is written as PNG and, beside it under the same stem, as SVG.
//!
//! * [`plot_curves`]: load–displacement curves (Fig. 3 style: dashed =
//!   local, solid = nonlocal, markers by [`Marker`], one colour per mesh,
//!   the legend in its own column right of the axes, never over the data),
//!   inputs for the M1–M3 metrics of [`crate::metrics`];
//! * [`plot_work_precision`]: error against wall time on log–log axes,
//!   ticks at whole decades labelled 10ᵏ;
//! * [`plot_field`] / [`plot_field_panels`]: material points drawn as filled
//!   squares of their current size coloured by a value (εq of \[D8\], κ̄ …)
//!   on the perceptual viridis map, a contour-like picture as in Figs. 4–5,
//!   several meshes side by side with one shared, labelled colour bar;
//! * [`run_curve`]: the plot of one run's `curve.csv`.
//!
//! Text uses DejaVu Sans compiled in from the `dejavu` crate and rendered by
//! plotters' pure-Rust `ab_glyph` backend, so no system font (fontconfig,
//! freetype) is needed on any machine; the SVG names the `sans-serif`
//! family and keeps its text as text.

use crate::atomic_file::AtomicPath;
use plotters::coord::Shift;
use plotters::element::{DashedPathElement, DynElement};
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use thiserror::Error;

pub mod run_curve;

/// Why a figure could not be drawn.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PlotError {
    /// Nothing (finite) to draw.
    #[error("nothing to plot: {0}")]
    Empty(&'static str),
    /// positions and values differ in length.
    #[error("length mismatch: {0}")]
    LengthMismatch(&'static str),
    /// Bounds or a colour range that is not finite or not increasing.
    #[error("invalid bounds or range: {0}")]
    Bounds(&'static str),
    /// The embedded font could not be registered.
    #[error("font registration failed")]
    Font,
    /// An input file (a run's `curve.csv`) that cannot be read.
    #[error("cannot read {0}")]
    Input(String),
    /// Rendering or writing the file failed.
    #[error("drawing failed: {0}")]
    Drawing(String),
}

/// Result type of this module.
pub type Result<T> = std::result::Result<T, PlotError>;

fn de<E: std::fmt::Display>(e: E) -> PlotError {
    PlotError::Drawing(e.to_string())
}

/// Registers DejaVu Sans (regular and bold) as plotters' "sans-serif"
/// family, once per process.
fn ensure_fonts() -> Result<()> {
    static OK: OnceLock<bool> = OnceLock::new();
    let ok = *OK.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .is_ok()
            && plotters::style::register_font("sans-serif", FontStyle::Bold, dejavu::sans::bold())
                .is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(PlotError::Font)
    }
}

fn prepare_path(path: &Path) -> Result<()> {
    if let Some(dir) = path.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir).map_err(de)?;
        }
    }
    ensure_fonts()
}

/// The SVG written beside the PNG `path`: the same stem, extension `svg`.
pub fn svg_path(path: &Path) -> PathBuf {
    path.with_extension("svg")
}

/// A figure that can draw itself on any plotters backend (PNG and SVG).
trait Figure {
    /// Draw on `root` (already filled white).
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<()>;
}

/// Write `figure` of `size` pixels as the PNG `path` and the SVG
/// [`svg_path`] beside it, each drawn under a temporary name and renamed
/// once whole (whole or absent).
fn render(path: &Path, size: (u32, u32), figure: &impl Figure) -> Result<()> {
    prepare_path(path)?;
    let png = AtomicPath::new(path);
    {
        let root = BitMapBackend::new(png.temp(), size).into_drawing_area();
        root.fill(&WHITE).map_err(de)?;
        figure.draw(&root)?;
        root.present().map_err(de)?;
    }
    let svg = AtomicPath::new(&svg_path(path));
    {
        let root = SVGBackend::new(svg.temp(), size).into_drawing_area();
        root.fill(&WHITE).map_err(de)?;
        figure.draw(&root)?;
        root.present().map_err(de)?;
    }
    png.commit().map_err(de)?;
    svg.commit().map_err(de)
}

// ---------------------------------------------------------------------------
// Colours
// ---------------------------------------------------------------------------

/// Line colours of the curve plots (one per mesh), indexed modulo length.
pub const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(23, 190, 207),
    RGBColor(127, 127, 127),
];

/// Colour of curve index `i` ([`PALETTE`] modulo its length).
pub fn series_color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// Control points of the field colour map: viridis (van der Walt & Smith,
/// matplotlib's default) at t = 0, 1/8, …, 1, piecewise linear between.
/// Perceptually uniform: its lightness L* rises steadily from dark purple
/// to yellow, so it reads in grey print and for colour-blind readers, and
/// no false bands appear where the rainbow map turned from cyan to green.
pub const COLORMAP: [RGBColor; 9] = [
    RGBColor(68, 1, 84),
    RGBColor(71, 45, 123),
    RGBColor(59, 82, 139),
    RGBColor(44, 114, 142),
    RGBColor(33, 144, 140),
    RGBColor(39, 173, 129),
    RGBColor(93, 200, 99),
    RGBColor(170, 220, 50),
    RGBColor(253, 231, 37),
];

/// Colour used for non-finite values.
pub const NAN_COLOR: RGBColor = RGBColor(160, 160, 160);

/// Colour map at `t ∈ [0, 1]` (clamped): t = 0 → first [`COLORMAP`] entry,
/// t = 1 → last, linear in between; NaN → [`NAN_COLOR`].
pub fn colormap(t: f64) -> RGBColor {
    if t.is_nan() {
        return NAN_COLOR;
    }
    let n = COLORMAP.len() - 1;
    let s = t.clamp(0.0, 1.0) * n as f64;
    let k = (s.floor() as usize).min(n - 1);
    let f = s - k as f64;
    let (a, b) = (COLORMAP[k], COLORMAP[k + 1]);
    let mix = |x: u8, y: u8| (x as f64 + f * (y as f64 - x as f64)).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// Colour of `value` for the colour range `(lo, hi)`: lo → first colour,
/// hi → last, clamped outside; a degenerate range maps everything to the
/// middle colour.
pub fn map_value(value: f64, range: (f64, f64)) -> RGBColor {
    let (lo, hi) = range;
    if !value.is_finite() {
        return NAN_COLOR;
    }
    if hi > lo {
        colormap((value - lo) / (hi - lo))
    } else {
        colormap(0.5)
    }
}

/// Tick label with a precision suited to the axis span.
fn fmt_tick(v: f64, span: f64) -> String {
    let span = span.abs();
    if !(1e-3..1e5).contains(&span) {
        return format!("{v:.2e}");
    }
    // ticks are about span/10 apart: one significant digit of the step
    let dec = (1.0 - span.log10().floor()).clamp(0.0, 6.0) as usize;
    format!("{v:.dec$}")
}

// ---------------------------------------------------------------------------
// Curves (Fig. 3)
// ---------------------------------------------------------------------------

/// Marker shape drawn along a curve, so that curves differ by more than
/// colour (grey print, colour-blind readers): in comparisons local runs get
/// [`Marker::Triangle`] and nonlocal runs [`Marker::Circle`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marker {
    /// Filled circle.
    Circle,
    /// Filled triangle pointing up.
    Triangle,
    /// Filled square.
    Square,
    /// Diagonal cross.
    Cross,
}

impl Marker {
    /// The shapes in order, for series told apart by index.
    pub const ALL: [Marker; 4] = [
        Marker::Circle,
        Marker::Triangle,
        Marker::Square,
        Marker::Cross,
    ];

    /// Marker of series index `i` ([`Marker::ALL`] modulo its length).
    pub fn of_index(i: usize) -> Self {
        Self::ALL[i % Self::ALL.len()]
    }

    /// The marker of a run with (`true`) or without a length scale.
    pub fn of_regularisation(nonlocal: bool) -> Self {
        if nonlocal {
            Marker::Circle
        } else {
            Marker::Triangle
        }
    }

    /// This marker at pixel `at` of a backend, `color`.
    fn pixel_element<DB: DrawingBackend>(
        self,
        at: (i32, i32),
        color: RGBColor,
    ) -> DynElement<'static, DB, (i32, i32)> {
        let r = MARKER_RADIUS;
        match self {
            Marker::Circle => Circle::new(at, r, color.filled()).into_dyn(),
            Marker::Triangle => TriangleMarker::new(at, r + 1, color.filled()).into_dyn(),
            Marker::Square => {
                let (x, y) = at;
                let r = r - 1;
                Rectangle::new([(x - r, y - r), (x + r, y + r)], color.filled()).into_dyn()
            }
            Marker::Cross => Cross::new(at, r, color.stroke_width(2)).into_dyn(),
        }
    }
}

/// Radius of the curve markers, px.
const MARKER_RADIUS: i32 = 5;
/// Markers drawn along a curve of many points (evenly spread by index).
const MARKERS_PER_CURVE: usize = 12;

/// One curve of [`plot_curves`].
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry (e.g. "local, h = 2 mm"); empty: no legend entry.
    pub name: String,
    /// `(x, y)` points, drawn in order; non-finite points are dropped.
    pub points: Vec<(f64, f64)>,
    /// Dashed line (paper Fig. 3: local runs) instead of solid (nonlocal).
    pub dashed: bool,
    /// Colour index into [`PALETTE`] (same index = same mesh).
    pub color: usize,
    /// Markers along the curve (`None`: the line only).
    pub marker: Option<Marker>,
}

/// Default size of [`plot_curves`] in pixels (the legend column included).
pub const CURVE_SIZE: (u32, u32) = (1200, 680);

/// Load–displacement curves in paper Fig. 3 style, PNG of [`CURVE_SIZE`]
/// and SVG beside it.
pub fn plot_curves(
    path: impl AsRef<Path>,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<()> {
    plot_curves_sized(path, CURVE_SIZE, title, x_label, y_label, series)
}

/// [`plot_curves`] with an explicit image size `(width, height)`.
pub fn plot_curves_sized(
    path: impl AsRef<Path>,
    size: (u32, u32),
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<()> {
    let panel = CurvePanel {
        title,
        y_label,
        series,
    };
    plot_curve_panels_sized(path, size, x_label, &[panel])
}

/// One chart of [`plot_curve_panels`].
pub struct CurvePanel<'a> {
    /// Caption of the chart.
    pub title: &'a str,
    /// Label of its y axis, quantity and unit (e.g. "F (kN/m)").
    pub y_label: &'a str,
    /// Its curves.
    pub series: &'a [Series],
}

/// Charts of curves over one x quantity stacked in one figure, each
/// [`CURVE_SIZE`] high.
pub fn plot_curve_panels(
    path: impl AsRef<Path>,
    x_label: &str,
    panels: &[CurvePanel<'_>],
) -> Result<()> {
    let size = (CURVE_SIZE.0, CURVE_SIZE.1 * panels.len().max(1) as u32);
    plot_curve_panels_sized(path, size, x_label, panels)
}

/// [`plot_curve_panels`] with an explicit image size `(width, height)`.
pub fn plot_curve_panels_sized(
    path: impl AsRef<Path>,
    size: (u32, u32),
    x_label: &str,
    panels: &[CurvePanel<'_>],
) -> Result<()> {
    // refuse before any file is written
    for panel in panels {
        clean_points(panel.series)?;
    }
    if panels.is_empty() {
        return Err(PlotError::Empty("no curve panels"));
    }
    render(path.as_ref(), size, &CurveFigure { x_label, panels })
}

struct CurveFigure<'a, 'b> {
    x_label: &'a str,
    panels: &'a [CurvePanel<'b>],
}

impl Figure for CurveFigure<'_, '_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<()> {
        for (area, panel) in root
            .split_evenly((self.panels.len(), 1))
            .iter()
            .zip(self.panels)
        {
            draw_curves(area, self.x_label, panel)?;
        }
        Ok(())
    }
}

/// The finite points of each series; [`PlotError::Empty`] when there are none.
fn clean_points(series: &[Series]) -> Result<Vec<Vec<(f64, f64)>>> {
    let clean: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|s| {
            s.points
                .iter()
                .copied()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect()
        })
        .collect();
    if clean.iter().all(|c| c.is_empty()) {
        return Err(PlotError::Empty("no finite curve points"));
    }
    Ok(clean)
}

/// One legend row: the line (dashed or solid) with its marker, and the name.
struct LegendEntry {
    name: String,
    color: RGBColor,
    width: u32,
    dashed: bool,
    marker: Option<Marker>,
}

impl LegendEntry {
    fn of(s: &Series) -> Self {
        Self {
            name: s.name.clone(),
            color: series_color(s.color),
            width: 2,
            dashed: s.dashed,
            marker: s.marker,
        }
    }
}

const LEGEND_FONT: u32 = 15;
const LEGEND_ROW: i32 = 24;
const LEGEND_SAMPLE: i32 = 40;

/// Width in pixels of the legend column for `entries` (0 when empty),
/// at most 45 % of `width`.
fn legend_width<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, entries: &[LegendEntry]) -> u32 {
    let font = TextStyle::from(("sans-serif", LEGEND_FONT).into_font());
    let widest = entries
        .iter()
        .map(|e| area.estimate_text_size(&e.name, &font).map_or(0, |s| s.0))
        .max();
    match widest {
        None => 0,
        Some(w) => (w + LEGEND_SAMPLE as u32 + 36).min(area.dim_in_pixel().0 * 45 / 100),
    }
}

/// The legend in its own area (right of the axes), top-aligned at `top`.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[LegendEntry],
    top: i32,
) -> Result<()> {
    let font = ("sans-serif", LEGEND_FONT).into_font().color(&BLACK);
    for (k, e) in entries.iter().enumerate() {
        let y = top + LEGEND_ROW * k as i32 + LEGEND_ROW / 2;
        let (x0, x1) = (8, 8 + LEGEND_SAMPLE);
        let style = e.color.stroke_width(e.width);
        if e.dashed {
            area.draw(&DashedPathElement::new(vec![(x0, y), (x1, y)], 7, 4, style))
                .map_err(de)?;
        } else {
            area.draw(&PathElement::new(vec![(x0, y), (x1, y)], style))
                .map_err(de)?;
        }
        if let Some(m) = e.marker {
            area.draw(&m.pixel_element(((x0 + x1) / 2, y), e.color))
                .map_err(de)?;
        }
        let pos = plotters::style::text_anchor::Pos::new(
            plotters::style::text_anchor::HPos::Left,
            plotters::style::text_anchor::VPos::Center,
        );
        area.draw(&Text::new(
            e.name.clone(),
            (x1 + 8, y),
            font.clone().pos(pos),
        ))
        .map_err(de)?;
    }
    Ok(())
}

/// Indices of the points of a curve of `n` points that carry a marker:
/// about [`MARKERS_PER_CURVE`], evenly spread, shifted by `phase` ∈ [0, 1)
/// of their spacing (first and last included at phase 0) so that curves
/// lying on one another still show each one's markers.
fn marker_indices(n: usize, phase: f64) -> Vec<usize> {
    if n <= MARKERS_PER_CURVE {
        return (0..n).collect();
    }
    let m = MARKERS_PER_CURVE - 1;
    let step = (n - 1) as f64 / m as f64;
    (0..=m)
        .map(|k| ((k as f64 + phase) * step).round() as usize)
        .filter(|&i| i < n)
        .collect()
}

/// Marker phase of series `i` (three staggered positions).
fn marker_phase(i: usize) -> f64 {
    (i % 3) as f64 / 3.0
}

/// The curves of `panel` on `area`, axes fitted to them (y from 0), the
/// legend in a column right of the axes.
fn draw_curves<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    x_label: &str,
    panel: &CurvePanel<'_>,
) -> Result<()> {
    let series = panel.series;
    let clean = clean_points(series)?;
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in clean.iter().flatten() {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    // load curves start at 0: include the origin line, pad the top
    y0 = y0.min(0.0);
    y1 = y1.max(0.0);
    let pad = |a: f64, b: f64| if b > a { (a, b) } else { (a - 0.5, b + 0.5) };
    let (x0, x1) = pad(x0, x1);
    let (y0, y1) = pad(y0, y1);
    let y1 = y1 + 0.05 * (y1 - y0);
    let (xs, ys) = (x1 - x0, y1 - y0);
    let entries: Vec<LegendEntry> = series
        .iter()
        .filter(|s| !s.name.is_empty())
        .map(LegendEntry::of)
        .collect();
    let (w, _) = area.dim_in_pixel();
    let (plot, legend) = area.split_horizontally(w - legend_width(area, &entries));
    let mut chart = ChartBuilder::on(&plot)
        .caption(panel.title, ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(de)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(panel.y_label)
        .label_style(("sans-serif", 16))
        .axis_desc_style(("sans-serif", 19))
        .x_label_formatter(&|v| fmt_tick(*v, xs))
        .y_label_formatter(&|v| fmt_tick(*v, ys))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()
        .map_err(de)?;
    for (k, (s, pts)) in series.iter().zip(&clean).enumerate() {
        let color = series_color(s.color);
        let style = color.stroke_width(2);
        if s.dashed {
            chart
                .draw_series(DashedLineSeries::new(pts.clone(), 10, 6, style))
                .map_err(de)?;
        } else {
            chart
                .draw_series(LineSeries::new(pts.clone(), style))
                .map_err(de)?;
        }
        if let Some(m) = s.marker {
            let idx = marker_indices(pts.len(), marker_phase(k));
            chart
                .draw_series(
                    idx.iter()
                        .map(|&i| EmptyElement::at(pts[i]) + m.pixel_element::<DB>((0, 0), color)),
                )
                .map_err(de)?;
        }
    }
    // the legend starts level with the top of the axes
    let top = chart.plotting_area().get_base_pixel().1 - area.get_base_pixel().1;
    draw_legend(&legend, &entries, top)
}

// ---------------------------------------------------------------------------
// Work–precision (log–log)
// ---------------------------------------------------------------------------

/// The whole decades 10ᵏ from ≤ `lo` to ≥ `hi` (`0 < lo ≤ hi`): the range
/// of a log axis that starts and ends on a labelled tick.
pub fn decade_bounds(lo: f64, hi: f64) -> (f64, f64) {
    let a = lo.log10().floor();
    let mut b = hi.log10().ceil();
    if b <= a {
        b = a + 1.0;
    }
    (10f64.powf(a), 10f64.powf(b))
}

/// Labelled ticks of a log axis over the decade range `(lo, hi)` (from
/// [`decade_bounds`]): every decade, or every 2nd, 3rd … so that at most
/// `max` are labelled.
pub fn decade_ticks(lo: f64, hi: f64, max: usize) -> Vec<f64> {
    let (a, b) = (lo.log10().round() as i32, hi.log10().round() as i32);
    let n = (b - a + 1).max(1) as usize;
    let every = n.div_ceil(max.max(1)).max(1);
    (a..=b)
        .filter(|k| ((k - a) as usize).is_multiple_of(every))
        .map(|k| 10f64.powi(k))
        .collect()
}

/// The unlabelled grid lines 2·10ᵏ … 9·10ᵏ within `(lo, hi)`.
fn minor_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let (a, b) = (lo.log10().round() as i32, hi.log10().round() as i32);
    (a..b)
        .flat_map(|k| (2..10).map(move |m| m as f64 * 10f64.powi(k)))
        .filter(|v| *v > lo && *v < hi)
        .collect()
}

/// Label of a decade tick `10^k`: "1", "10", "0.1" for k = 0, 1, −1, else
/// `10` with a superscript exponent ("10⁻³", "10⁴").
pub fn decade_label(v: f64) -> String {
    let k = v.log10().round() as i32;
    match k {
        0 => "1".into(),
        1 => "10".into(),
        -1 => "0.1".into(),
        _ => {
            let sup: String = k
                .to_string()
                .chars()
                .map(|c| match c {
                    '-' => '⁻',
                    d => ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹']
                        [d.to_digit(10).unwrap_or(0) as usize],
                })
                .collect();
            format!("10{sup}")
        }
    }
}

/// Work-precision figure of a study: error against wall time, both axes
/// logarithmic with whole decades labelled, one line with a distinct marker
/// per method ([`Series::marker`], [`Marker::of_index`] when unset), the
/// Pareto front (`front`, sorted by time) as a black dashed step line with
/// open circles, the legend right of the axes. Points that are not finite
/// and positive are dropped. PNG of [`CURVE_SIZE`] and SVG beside it.
pub fn plot_work_precision(
    path: impl AsRef<Path>,
    title: &str,
    series: &[Series],
    front: &[(f64, f64)],
) -> Result<()> {
    let keep = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite() && p.0 > 0.0 && p.1 > 0.0;
    let clean: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|s| s.points.iter().filter(keep).copied().collect())
        .collect();
    let all: Vec<(f64, f64)> = clean.iter().flatten().copied().collect();
    if all.is_empty() {
        return Err(PlotError::Empty("no run with a finite positive error"));
    }
    let bounds = |f: fn(&(f64, f64)) -> f64| {
        let (lo, hi) = all
            .iter()
            .map(f)
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            });
        decade_bounds(lo / 1.2, hi * 1.2)
    };
    let figure = WorkPrecision {
        title,
        series,
        clean,
        front: front.iter().filter(keep).copied().collect(),
        x: bounds(|p| p.0),
        y: bounds(|p| p.1),
    };
    render(path.as_ref(), CURVE_SIZE, &figure)
}

struct WorkPrecision<'a> {
    title: &'a str,
    series: &'a [Series],
    clean: Vec<Vec<(f64, f64)>>,
    front: Vec<(f64, f64)>,
    x: (f64, f64),
    y: (f64, f64),
}

impl WorkPrecision<'_> {
    fn marker(&self, i: usize) -> Marker {
        self.series[i].marker.unwrap_or(Marker::of_index(i))
    }

    fn legend(&self) -> Vec<LegendEntry> {
        let mut entries: Vec<LegendEntry> = self
            .series
            .iter()
            .enumerate()
            .map(|(i, s)| LegendEntry {
                marker: Some(self.marker(i)),
                ..LegendEntry::of(s)
            })
            .collect();
        if !self.front.is_empty() {
            entries.push(LegendEntry {
                name: "Pareto front".into(),
                color: BLACK,
                width: 1,
                dashed: true,
                marker: None,
            });
        }
        entries
    }
}

impl Figure for WorkPrecision<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<()> {
        let entries = self.legend();
        let (w, _) = root.dim_in_pixel();
        let (plot, legend) = root.split_horizontally(w - legend_width(root, &entries));
        let ((x0, x1), (y0, y1)) = (self.x, self.y);
        let x_axis = (x0..x1)
            .log_scale()
            .with_key_points(decade_ticks(x0, x1, 8))
            .with_light_points(minor_ticks(x0, x1));
        let y_axis = (y0..y1)
            .log_scale()
            .with_key_points(decade_ticks(y0, y1, 10))
            .with_light_points(minor_ticks(y0, y1));
        let mut chart = ChartBuilder::on(&plot)
            .caption(self.title, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(56)
            .y_label_area_size(90)
            .build_cartesian_2d(x_axis, y_axis)
            .map_err(de)?;
        chart
            .configure_mesh()
            .x_desc("wall time (s), median of the repeats")
            .y_desc("error (relative, 1)")
            .label_style(("sans-serif", 16))
            .axis_desc_style(("sans-serif", 19))
            .x_label_formatter(&|v| decade_label(*v))
            .y_label_formatter(&|v| decade_label(*v))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(205, 205, 205))
            .draw()
            .map_err(de)?;
        for (i, (s, pts)) in self.series.iter().zip(&self.clean).enumerate() {
            let color = series_color(s.color);
            let style = color.stroke_width(2);
            if s.dashed {
                chart
                    .draw_series(DashedLineSeries::new(pts.clone(), 10, 6, style))
                    .map_err(de)?;
            } else {
                chart
                    .draw_series(LineSeries::new(pts.clone(), style))
                    .map_err(de)?;
            }
            let m = self.marker(i);
            chart
                .draw_series(
                    pts.iter()
                        .map(|&p| EmptyElement::at(p) + m.pixel_element::<DB>((0, 0), color)),
                )
                .map_err(de)?;
        }
        let front = &self.front;
        if !front.is_empty() {
            let mut steps = Vec::new();
            for (i, &p) in front.iter().enumerate() {
                if i > 0 {
                    steps.push((p.0, front[i - 1].1));
                }
                steps.push(p);
            }
            let black = BLACK.stroke_width(1);
            chart
                .draw_series(DashedLineSeries::new(steps, 6, 4, black))
                .map_err(de)?;
            chart
                .draw_series(
                    front
                        .iter()
                        .map(|&p| Circle::new(p, 9, BLACK.stroke_width(2))),
                )
                .map_err(de)?;
        }
        let top = chart.plotting_area().get_base_pixel().1 - root.get_base_pixel().1;
        draw_legend(&legend, &entries, top)
    }
}

// ---------------------------------------------------------------------------
// Fields (Figs. 4–5)
// ---------------------------------------------------------------------------

/// A rectangle of the plane, `x = (x_min, x_max)`, `y = (y_min, y_max)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// (x_min, x_max)
    pub x: (f64, f64),
    /// (y_min, y_max)
    pub y: (f64, f64),
}

impl Bounds {
    /// Bounds from corners.
    pub fn new(x_min: f64, x_max: f64, y_min: f64, y_max: f64) -> Self {
        Self {
            x: (x_min, x_max),
            y: (y_min, y_max),
        }
    }

    fn check(&self) -> Result<()> {
        let ok = |(a, b): (f64, f64)| a.is_finite() && b.is_finite() && b > a;
        if ok(self.x) && ok(self.y) {
            Ok(())
        } else {
            Err(PlotError::Bounds("plot bounds"))
        }
    }

    fn width(&self) -> f64 {
        self.x.1 - self.x.0
    }

    fn height(&self) -> f64 {
        self.y.1 - self.y.0
    }
}

/// One field picture of [`plot_field_panels`] (e.g. one mesh of Fig. 4).
///
/// Each point is drawn as a filled square of its current size, rather than
/// the field being interpolated to a grid: the picture then shows the
/// material where it is (a run-out, a crack-like band, lost points) and no
/// value that no point holds, and needs no mask of the body's outline.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel<'a> {
    /// Caption above the panel (e.g. "(a) h = 3.3 mm").
    pub title: String,
    /// Material point positions, m.
    pub positions: &'a [[f64; 2]],
    /// One value per point (εq, κ̄ …); non-finite values are drawn grey.
    pub values: &'a [f64],
    /// Plotted region, m (equal axis scales are kept).
    pub bounds: Bounds,
    /// Current volume V_p of each point, m³ per m (m² in the plane): each
    /// point is drawn as a rectangle of its current extent ([`extents`]):
    /// sides [`EXTENT_FACTOR`]·√V_p, widened to the box of its Voronoi cell
    /// where the points have been stretched further apart (up to
    /// [`EXTENT_CAP`]·√V_p), larger rectangles drawn first, so that a band
    /// whose points have spread apart shows no gap and is not drawn wider
    /// than it is. Takes precedence over `marker`.
    pub volumes: Option<&'a [f64]>,
    /// Side of the square drawn per point, in model units, when `volumes`
    /// is `None`. Slightly more than the MP spacing closes the gaps between
    /// squares: for 2×2 MPs per cell at the Gauss positions the spacing
    /// alternates 0.42h and 0.58h, so use 0.6h. `None` =
    /// [`AUTO_MARKER_FACTOR`]·sqrt(area of the points' bounding box / number
    /// of points) (= 0.6h for that layout).
    pub marker: Option<f64>,
}

/// Factor on the mean MP spacing for the automatic marker size.
pub const AUTO_MARKER_FACTOR: f64 = 1.2;

/// Factor on √V_p for the least side of a point's square: √V_p is the
/// point's spacing in a uniform layout, but 2×2 points per cell at the
/// Gauss positions sit 0.58h apart with √V_p = 0.5h; 1.2 closes that.
pub const EXTENT_FACTOR: f64 = 1.2;

/// Reach of a point's rectangle, in √V_p: a point stretched apart from its
/// neighbours (along a shear band) is drawn out to the box of its Voronoi
/// cell among the points this near, up to half this many √V_p from it.
pub const EXTENT_CAP: f64 = 3.0;

/// Label of the x axis of the field plots (positions are in metres).
pub const FIELD_X_LABEL: &str = "x (m)";
/// Label of the y axis of the field plots.
pub const FIELD_Y_LABEL: &str = "y (m)";

/// Height in pixels of a field panel's drawing region (auto sizing).
const PANEL_PLOT_H: f64 = 520.0;
const PANEL_TITLE_H: u32 = 34;
const PANEL_MARGIN: u32 = 10;
const PANEL_XLAB: u32 = 56;
const PANEL_YLAB: u32 = 84;
const COLORBAR_W: u32 = 150;
const FIG_TITLE_H: u32 = 40;

/// A single field in the style of paper Figs. 4–5: each point a filled
/// square coloured by its value, with a colour bar labelled `label` (the
/// field and its unit, e.g. "εq (1)"). `range = None` uses the values' min
/// and max. Size chosen from the bounds' aspect ratio; PNG and SVG.
#[allow(clippy::too_many_arguments)]
pub fn plot_field(
    path: impl AsRef<Path>,
    title: &str,
    positions: &[[f64; 2]],
    values: &[f64],
    volumes: Option<&[f64]>,
    bounds: Bounds,
    range: Option<(f64, f64)>,
    label: &str,
) -> Result<()> {
    let panel = Panel {
        title: String::new(),
        positions,
        values,
        bounds,
        volumes,
        marker: None,
    };
    plot_field_panels(path, title, &[panel], range, label)
}

/// The narrowest panel of a field figure, pixels (a slender body's panel is
/// widened to it).
const MIN_PANEL_W: u32 = 160;

/// Automatic figure size of [`plot_field_panels`] for these panels.
pub fn field_figure_size(panels: &[Panel<'_>]) -> (u32, u32) {
    let mut w = COLORBAR_W;
    for p in panels {
        let aspect = if p.bounds.height() > 0.0 && p.bounds.width() > 0.0 {
            (p.bounds.width() / p.bounds.height()).clamp(0.1, 10.0)
        } else {
            1.0
        };
        let natural = (PANEL_PLOT_H * aspect).round() as u32 + PANEL_YLAB + 2 * PANEL_MARGIN;
        w += natural.max(MIN_PANEL_W);
    }
    let h = FIG_TITLE_H + PANEL_TITLE_H + PANEL_PLOT_H as u32 + PANEL_XLAB + 2 * PANEL_MARGIN;
    (w.max(200), h)
}

/// Several fields side by side (one per mesh, paper Figs. 4/5 a–d) with one
/// shared colour range and colour bar labelled `colorbar_label` (the field
/// and its unit); axes labelled [`FIELD_X_LABEL`] and [`FIELD_Y_LABEL`].
/// `range = None` uses min and max over all panels' finite values.
pub fn plot_field_panels(
    path: impl AsRef<Path>,
    title: &str,
    panels: &[Panel<'_>],
    range: Option<(f64, f64)>,
    colorbar_label: &str,
) -> Result<()> {
    let size = field_figure_size(panels);
    plot_field_panels_sized(path, size, title, panels, range, colorbar_label)
}

/// [`plot_field_panels`] with an explicit image size `(width, height)`.
pub fn plot_field_panels_sized(
    path: impl AsRef<Path>,
    size: (u32, u32),
    title: &str,
    panels: &[Panel<'_>],
    range: Option<(f64, f64)>,
    colorbar_label: &str,
) -> Result<()> {
    if panels.is_empty() {
        return Err(PlotError::Empty("no panels"));
    }
    for p in panels {
        if p.positions.len() != p.values.len() {
            return Err(PlotError::LengthMismatch("positions vs values"));
        }
        if p.volumes.is_some_and(|v| v.len() != p.positions.len()) {
            return Err(PlotError::LengthMismatch("positions vs volumes"));
        }
        p.bounds.check()?;
    }
    let range = colour_range(panels, range)?;
    let (w, h) = size;
    if w < COLORBAR_W + MIN_PANEL_W * panels.len() as u32 || h < FIG_TITLE_H + 180 {
        return Err(PlotError::Bounds("image too small"));
    }
    let figure = FieldFigure {
        title,
        panels,
        range,
        colorbar_label,
    };
    render(path.as_ref(), size, &figure)
}

/// The colour range: `range` checked, or min and max of the finite values.
fn colour_range(panels: &[Panel<'_>], range: Option<(f64, f64)>) -> Result<(f64, f64)> {
    if let Some((lo, hi)) = range {
        if !(lo.is_finite() && hi.is_finite() && hi >= lo) {
            return Err(PlotError::Bounds("colour range"));
        }
        return Ok((lo, hi));
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in panels.iter().flat_map(|p| p.values.iter()) {
        if v.is_finite() {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    Ok(if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) })
}

struct FieldFigure<'a, 'b> {
    title: &'a str,
    panels: &'a [Panel<'b>],
    range: (f64, f64),
    colorbar_label: &'a str,
}

impl Figure for FieldFigure<'_, '_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<()> {
        let (w, _) = root.dim_in_pixel();
        let (head, body) = root.split_vertically(FIG_TITLE_H);
        draw_title(&head, self.title, 24)?;
        let (fields, bar) = body.split_horizontally(w - COLORBAR_W);
        // panel widths proportional to their natural widths
        let natural: Vec<f64> = self
            .panels
            .iter()
            .map(|p| {
                PANEL_PLOT_H * (p.bounds.width() / p.bounds.height()).clamp(0.1, 10.0)
                    + (PANEL_YLAB + 2 * PANEL_MARGIN) as f64
            })
            .collect();
        let total: f64 = natural.iter().sum();
        let avail = (w - COLORBAR_W) as f64;
        let mut breaks = Vec::with_capacity(self.panels.len());
        let mut acc = 0.0;
        for nat in &natural[..natural.len() - 1] {
            acc += nat / total * avail;
            breaks.push(acc.round() as i32);
        }
        let areas = fields.split_by_breakpoints(breaks, Vec::<i32>::new());
        for (p, area) in self.panels.iter().zip(&areas) {
            draw_panel(area, p, self.range)?;
        }
        draw_colorbar(&bar, self.range, self.colorbar_label)
    }
}

/// `title` centred in `head` (nothing for an empty title), `size` px.
fn draw_title<DB: DrawingBackend>(
    head: &DrawingArea<DB, Shift>,
    title: &str,
    size: u32,
) -> Result<()> {
    if title.is_empty() {
        return Ok(());
    }
    let (w, h) = head.dim_in_pixel();
    head.draw(&Text::new(
        title.to_string(),
        ((w / 2) as i32, (h / 2) as i32),
        ("sans-serif", size)
            .into_font()
            .color(&BLACK)
            .pos(text_center()),
    ))
    .map_err(de)
}

fn text_center() -> plotters::style::text_anchor::Pos {
    use plotters::style::text_anchor::{HPos, Pos, VPos};
    Pos::new(HPos::Center, VPos::Center)
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &Panel<'_>,
    range: (f64, f64),
) -> Result<()> {
    let (aw, ah) = area.dim_in_pixel();
    let (head, plot) = area.split_vertically(PANEL_TITLE_H);
    draw_title(&head, &p.title, 20)?;
    // equal axis scales: shrink the data box to the bounds' aspect, centred
    let ph = ah.saturating_sub(PANEL_TITLE_H);
    let avail_w = aw.saturating_sub(PANEL_YLAB + 2 * PANEL_MARGIN).max(1) as f64;
    let avail_h = ph.saturating_sub(PANEL_XLAB + 2 * PANEL_MARGIN).max(1) as f64;
    let b = p.bounds;
    let scale = (avail_w / b.width()).min(avail_h / b.height());
    let extra_w = (avail_w - scale * b.width()).max(0.0) as u32;
    let extra_h = (avail_h - scale * b.height()).max(0.0) as u32;
    let mut chart = ChartBuilder::on(&plot)
        .margin_left(PANEL_MARGIN + extra_w / 2)
        .margin_right(PANEL_MARGIN + extra_w - extra_w / 2)
        .margin_top(PANEL_MARGIN + extra_h / 2)
        .margin_bottom(PANEL_MARGIN + extra_h - extra_h / 2)
        .x_label_area_size(PANEL_XLAB)
        .y_label_area_size(PANEL_YLAB)
        .build_cartesian_2d(b.x.0..b.x.1, b.y.0..b.y.1)
        .map_err(de)?;
    let (xs, ys) = (b.width(), b.height());
    chart
        .configure_mesh()
        .disable_mesh()
        .x_labels(4)
        .y_labels(6)
        .x_desc(FIELD_X_LABEL)
        .y_desc(FIELD_Y_LABEL)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .x_label_formatter(&|v| fmt_tick(*v, xs))
        .y_label_formatter(&|v| fmt_tick(*v, ys))
        .draw()
        .map_err(de)?;

    let finite: Vec<usize> = (0..p.positions.len())
        .filter(|&i| p.positions[i][0].is_finite() && p.positions[i][1].is_finite())
        .collect();
    let sides = point_sides(p, &finite);
    let area = |k: usize| sides[k].0 * sides[k].1;
    // larger rectangles first, so that each point's own neighbourhood is
    // painted by the smallest rectangle there, the large ones showing only
    // in the gaps; among equal sizes low values first so that bands are
    // drawn on top where points overlap
    let mut order: Vec<usize> = (0..finite.len()).collect();
    let value = |k: usize| {
        let v = p.values[finite[k]];
        if v.is_finite() {
            v
        } else {
            f64::NEG_INFINITY
        }
    };
    order.sort_by(|&a, &b| {
        area(b)
            .total_cmp(&area(a))
            .then(value(a).total_cmp(&value(b)))
    });
    chart
        .draw_series(order.iter().map(|&k| {
            let i = finite[k];
            let [x, y] = p.positions[i];
            let (hx, hy) = (0.5 * sides[k].0, 0.5 * sides[k].1);
            Rectangle::new(
                [(x - hx, y - hy), (x + hx, y + hy)],
                map_value(p.values[i], range).filled(),
            )
        }))
        .map_err(de)?;
    Ok(())
}

/// Sides (x, y) of the rectangle of each point of `idx`: from the panel's
/// volumes ([`extents`]; a volume that is not finite and positive takes the
/// panel's fallback), else the panel's marker, else the automatic size.
fn point_sides(p: &Panel<'_>, idx: &[usize]) -> Vec<(f64, f64)> {
    let fallback = match p.marker {
        Some(m) if m.is_finite() && m > 0.0 => m,
        _ => auto_marker(p.positions, idx, p.bounds),
    };
    let Some(volumes) = p.volumes else {
        return vec![(fallback, fallback); idx.len()];
    };
    let base: Vec<f64> = idx
        .iter()
        .map(|&i| {
            let v = volumes[i];
            if v.is_finite() && v > 0.0 {
                v.sqrt()
            } else {
                fallback / EXTENT_FACTOR
            }
        })
        .collect();
    let points: Vec<[f64; 2]> = idx.iter().map(|&i| p.positions[i]).collect();
    extents(&points, &base)
}

/// Directions sampled around a point by [`extents`].
const EXTENT_DIRECTIONS: usize = 32;
/// Factor on the sampled distances to the Voronoi cell's boundary: covers
/// the corners between the sampled rays and the rounding of the rectangles
/// to whole pixels, where two cells' boxes only touch.
const CELL_MARGIN: f64 = 1.1;

/// Sides (x, y) of the rectangles of points at `points` of sizes `base`
/// (√V_p): the box of the point's Voronoi cell among the points within
/// [`EXTENT_CAP`]·base, sampled along 32 rays (with a
/// 10 % margin), at least
/// [`EXTENT_FACTOR`]·base wide and high. A ray with no point within 45° of
/// it leaves the body (the boundary's outward side, a lost point) and
/// reaches [`EXTENT_FACTOR`]·base / 2 only. So a stretched layout (a shear
/// band's points) leaves no gap and the body is not drawn larger.
pub fn extents(points: &[[f64; 2]], base: &[f64]) -> Vec<(f64, f64)> {
    let mut sorted = base.to_vec();
    sorted.sort_by(f64::total_cmp);
    let Some(&median) = sorted.get(sorted.len() / 2) else {
        return Vec::new();
    };
    let cell = EXTENT_CAP * median;
    if !(cell.is_finite() && cell > 0.0) {
        return base
            .iter()
            .map(|b| (EXTENT_FACTOR * b, EXTENT_FACTOR * b))
            .collect();
    }
    let key = |p: [f64; 2]| ((p[0] / cell).floor() as i64, (p[1] / cell).floor() as i64);
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = Default::default();
    for (i, &p) in points.iter().enumerate() {
        grid.entry(key(p)).or_default().push(i);
    }
    let rays: Vec<(f64, f64)> = (0..EXTENT_DIRECTIONS)
        .map(|k| (std::f64::consts::TAU * k as f64 / EXTENT_DIRECTIONS as f64).sin_cos())
        .map(|(s, c)| (c, s))
        .collect();
    points
        .iter()
        .zip(base)
        .enumerate()
        .map(|(i, (&p, &b))| {
            let reach = EXTENT_CAP * b;
            let rings = (reach / cell).ceil().clamp(1.0, 8.0) as i64;
            let (cx, cy) = key(p);
            let mut near: Vec<(f64, f64)> = Vec::new();
            for gx in cx - rings..=cx + rings {
                for gy in cy - rings..=cy + rings {
                    for &j in grid.get(&(gx, gy)).map_or(&[][..], |v| &v[..]) {
                        let v = (points[j][0] - p[0], points[j][1] - p[1]);
                        let d = v.0.hypot(v.1);
                        if j != i && d > 0.0 && d <= reach {
                            near.push(v);
                        }
                    }
                }
            }
            let own = 0.5 * EXTENT_FACTOR * b;
            let (mut hx, mut hy) = (own, own);
            for &(ux, uy) in &rays {
                let t = ray_to_cell_boundary((ux, uy), &near)
                    .map_or(own, |t| (CELL_MARGIN * t).min(0.5 * reach));
                hx = hx.max(t * ux.abs());
                hy = hy.max(t * uy.abs());
            }
            (2.0 * hx, 2.0 * hy)
        })
        .collect()
}

/// Distance from a point along the unit ray `u` to the boundary of its
/// Voronoi cell among its neighbours at offsets `near`; `None` when no
/// neighbour lies within 45° of the ray (the ray leaves the body).
fn ray_to_cell_boundary(u: (f64, f64), near: &[(f64, f64)]) -> Option<f64> {
    let mut inside = false;
    let mut t = f64::INFINITY;
    for &(vx, vy) in near {
        let along = u.0 * vx + u.1 * vy;
        let d2 = vx * vx + vy * vy;
        if along > 0.0 {
            // the bisector of the point and this neighbour
            t = t.min(d2 / (2.0 * along));
            inside |= along >= std::f64::consts::FRAC_1_SQRT_2 * d2.sqrt();
        }
    }
    inside.then_some(t)
}

fn auto_marker(positions: &[[f64; 2]], idx: &[usize], b: Bounds) -> f64 {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &i in idx {
        let [x, y] = positions[i];
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let area = (x1 - x0) * (y1 - y0);
    if idx.len() > 1 && area > 0.0 {
        AUTO_MARKER_FACTOR * (area / idx.len() as f64).sqrt()
    } else {
        0.01 * b.width().min(b.height())
    }
}

fn draw_colorbar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    range: (f64, f64),
    label: &str,
) -> Result<()> {
    let (lo, hi) = if range.1 > range.0 {
        range
    } else {
        (range.0 - 0.5, range.0 + 0.5)
    };
    let span = hi - lo;
    let mut chart = ChartBuilder::on(area)
        .margin_top(PANEL_TITLE_H + PANEL_MARGIN)
        .margin_bottom(PANEL_XLAB + PANEL_MARGIN)
        .margin_left(12)
        .margin_right(40)
        .right_y_label_area_size(66)
        .build_cartesian_2d(0.0..1.0, lo..hi)
        .map_err(de)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(8)
        .label_style(("sans-serif", 14))
        .y_label_formatter(&|v| fmt_tick(*v, span))
        .draw()
        .map_err(de)?;
    let n = 200;
    chart
        .draw_series((0..n).map(|k| {
            let a = lo + span * k as f64 / n as f64;
            let b = lo + span * (k + 1) as f64 / n as f64;
            let c = colormap((k as f64 + 0.5) / n as f64);
            Rectangle::new([(0.0, a), (1.0, b)], c.filled())
        }))
        .map_err(de)?;
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(0.0, lo), (1.0, hi)],
            BLACK.stroke_width(1),
        )))
        .map_err(de)?;
    if !label.is_empty() {
        let (w, h) = area.dim_in_pixel();
        area.draw(&Text::new(
            label.to_string(),
            ((w as i32) - 18, (h / 2) as i32),
            ("sans-serif", 18)
                .into_font()
                .transform(FontTransform::Rotate270)
                .color(&BLACK)
                .pos(text_center()),
        ))
        .map_err(de)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests;
