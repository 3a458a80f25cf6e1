//! PNG figures in the style of the paper's Figs. 3–5, on plain data.
//!
//! * [`plot_curves`]: load–displacement curves (Fig. 3 style: dashed = local,
//!   solid = nonlocal, one colour per mesh, legend), inputs for the M1–M3
//!   metrics of [`crate::metrics`];
//! * [`plot_field`] / [`plot_field_panels`]: material points drawn as filled
//!   squares coloured by a value (εq of \[D8\], κ̄ …), a contour-like picture
//!   as in Figs. 4–5, several meshes side by side with one shared colour bar.
//!
//! Text uses DejaVu Sans compiled in from the `dejavu` crate and rendered by
//! plotters' pure-Rust `ab_glyph` backend, so no system font (fontconfig,
//! freetype) is needed on any machine.

use crate::atomic_file::AtomicPath;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::OnceLock;
use thiserror::Error;

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

/// Control points of the field colour map (blue → cyan → green → yellow →
/// red, the rainbow of the paper's contour plots); piecewise linear between.
pub const COLORMAP: [RGBColor; 5] = [
    RGBColor(0, 0, 180),
    RGBColor(0, 200, 255),
    RGBColor(40, 200, 40),
    RGBColor(255, 230, 0),
    RGBColor(220, 0, 0),
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

/// One curve of [`plot_curves`].
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry (e.g. "local, h = 2 mm").
    pub name: String,
    /// `(x, y)` points, drawn in order; non-finite points are dropped.
    pub points: Vec<(f64, f64)>,
    /// Dashed line (paper Fig. 3: local runs) instead of solid (nonlocal).
    pub dashed: bool,
    /// Colour index into [`PALETTE`] (same index = same mesh).
    pub color: usize,
}

/// Default size of [`plot_curves`] in pixels.
pub const CURVE_SIZE: (u32, u32) = (960, 680);

/// Load–displacement curves in paper Fig. 3 style, PNG of [`CURVE_SIZE`].
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
    /// Label of its y axis.
    pub y_label: &'a str,
    /// Its curves.
    pub series: &'a [Series],
}

/// Charts of curves over one x quantity stacked in one PNG, each
/// [`CURVE_SIZE`] high.
pub fn plot_curve_panels(
    path: impl AsRef<Path>,
    x_label: &str,
    panels: &[CurvePanel<'_>],
) -> Result<()> {
    let size = (CURVE_SIZE.0, CURVE_SIZE.1 * panels.len().max(1) as u32);
    plot_curve_panels_sized(path, size, x_label, panels)
}

fn plot_curve_panels_sized(
    path: impl AsRef<Path>,
    size: (u32, u32),
    x_label: &str,
    panels: &[CurvePanel<'_>],
) -> Result<()> {
    let path = path.as_ref();
    prepare_path(path)?;
    // drawn under a temporary name, renamed once presented: whole or absent
    let target = AtomicPath::new(path);
    let temp = target.temp().to_path_buf();
    let root = BitMapBackend::new(&temp, size).into_drawing_area();
    root.fill(&WHITE).map_err(de)?;
    for (area, panel) in root.split_evenly((panels.len(), 1)).iter().zip(panels) {
        draw_curves(area, x_label, panel)?;
    }
    root.present().map_err(de)?;
    drop(root);
    target.commit().map_err(de)
}

/// The curves of `panel` on `area`, axes fitted to them (y from 0).
fn draw_curves<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    x_label: &str,
    panel: &CurvePanel<'_>,
) -> Result<()> {
    let series = panel.series;
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
    let all = clean.iter().flatten();
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in all {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if !x0.is_finite() {
        return Err(PlotError::Empty("no finite curve points"));
    }
    // load curves start at 0: include the origin line, pad the top
    y0 = y0.min(0.0);
    y1 = y1.max(0.0);
    let pad = |a: f64, b: f64| if b > a { (a, b) } else { (a - 0.5, b + 0.5) };
    let (x0, x1) = pad(x0, x1);
    let (y0, y1) = pad(y0, y1);
    let y1 = y1 + 0.05 * (y1 - y0);
    let (xs, ys) = (x1 - x0, y1 - y0);
    let mut chart = ChartBuilder::on(area)
        .caption(panel.title, ("sans-serif", 26))
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
    for (s, pts) in series.iter().zip(&clean) {
        let style = series_color(s.color).stroke_width(2);
        let anno = if s.dashed {
            chart
                .draw_series(DashedLineSeries::new(pts.clone(), 10, 6, style))
                .map_err(de)?
        } else {
            chart
                .draw_series(LineSeries::new(pts.clone(), style))
                .map_err(de)?
        };
        let dashed = s.dashed;
        anno.label(s.name.clone()).legend(move |(x, y)| {
            let pts = vec![(x, y), (x + 30, y)];
            if dashed {
                DashedPathElement::new(pts, 7, 4, style).into_dyn()
            } else {
                PathElement::new(pts, style).into_dyn()
            }
        });
    }
    chart
        .configure_series_labels()
        .label_font(("sans-serif", 16))
        .legend_area_size(40)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(de)?;
    Ok(())
}

/// Tick label of a logarithmic axis: plain decimals from 1e-3 to 1e4, else
/// scientific.
fn log_tick(v: f64) -> String {
    if (1e-3..1e4).contains(&v.abs()) {
        let text = format!("{v:.3}");
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.0e}")
    }
}

/// Work-precision figure of a study: error against wall time, both axes
/// logarithmic, one line with markers per method, the Pareto front (`front`,
/// sorted by time) as a black step line with open circles. Points that are
/// not finite and positive are dropped.
pub fn plot_work_precision(
    path: impl AsRef<Path>,
    title: &str,
    series: &[Series],
    front: &[(f64, f64)],
) -> Result<()> {
    let path = path.as_ref();
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
        (lo / 1.5, hi * 1.5)
    };
    let ((x0, x1), (y0, y1)) = (bounds(|p| p.0), bounds(|p| p.1));
    prepare_path(path)?;
    // drawn under a temporary name, renamed once presented: whole or absent
    let target = AtomicPath::new(path);
    let temp = target.temp().to_path_buf();
    let root = BitMapBackend::new(&temp, CURVE_SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(de)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(90)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(de)?;
    chart
        .configure_mesh()
        .x_desc("wall time (s), median of the repeats")
        .y_desc("error (relative)")
        .label_style(("sans-serif", 16))
        .axis_desc_style(("sans-serif", 19))
        .x_labels(6)
        .y_labels(8)
        .x_label_formatter(&|v| log_tick(*v))
        .y_label_formatter(&|v| log_tick(*v))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()
        .map_err(de)?;
    for (s, pts) in series.iter().zip(&clean) {
        let color = series_color(s.color);
        let style = color.stroke_width(2);
        chart
            .draw_series(LineSeries::new(pts.clone(), style))
            .map_err(de)?
            .label(s.name.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 30, y)], style));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
            .map_err(de)?;
    }
    let front: Vec<(f64, f64)> = front.iter().filter(keep).copied().collect();
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
            .map_err(de)?
            .label("Pareto front")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 30, y)], black));
        chart
            .draw_series(
                front
                    .iter()
                    .map(|&p| Circle::new(p, 8, BLACK.stroke_width(2))),
            )
            .map_err(de)?;
    }
    chart
        .configure_series_labels()
        .label_font(("sans-serif", 15))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(de)?;
    root.present().map_err(de)?;
    drop(root);
    target.commit().map_err(de)
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
#[derive(Debug, Clone, PartialEq)]
pub struct Panel<'a> {
    /// Caption above the panel (e.g. "(a) h = 3.3 mm").
    pub title: String,
    /// Material point positions.
    pub positions: &'a [[f64; 2]],
    /// One value per point (εq, κ̄ …); non-finite values are drawn grey.
    pub values: &'a [f64],
    /// Plotted region (equal axis scales are kept).
    pub bounds: Bounds,
    /// Side of the square drawn per point, in model units. Slightly more
    /// than the MP spacing closes the gaps between squares: for 2×2 MPs per
    /// cell at the Gauss positions the spacing alternates 0.42h and 0.58h,
    /// so use 0.6h. `None` = [`AUTO_MARKER_FACTOR`]·sqrt(area of the points'
    /// bounding box / number of points) (= 0.6h for that layout).
    pub marker: Option<f64>,
}

/// Factor on the mean MP spacing for the automatic marker size.
pub const AUTO_MARKER_FACTOR: f64 = 1.2;

/// Height in pixels of a field panel's drawing region (auto sizing).
const PANEL_PLOT_H: f64 = 520.0;
const PANEL_TITLE_H: u32 = 34;
const PANEL_MARGIN: u32 = 10;
const PANEL_XLAB: u32 = 34;
const PANEL_YLAB: u32 = 56;
const COLORBAR_W: u32 = 130;
const FIG_TITLE_H: u32 = 40;

/// A single field in the style of paper Figs. 4–5: each point a filled
/// square coloured by its value, with a colour bar. `range = None` uses the
/// values' min and max. Size chosen from the bounds' aspect ratio.
pub fn plot_field(
    path: impl AsRef<Path>,
    title: &str,
    positions: &[[f64; 2]],
    values: &[f64],
    bounds: Bounds,
    range: Option<(f64, f64)>,
) -> Result<()> {
    let panel = Panel {
        title: String::new(),
        positions,
        values,
        bounds,
        marker: None,
    };
    plot_field_panels(path, title, &[panel], range, "")
}

/// Automatic figure size of [`plot_field_panels`] for these panels.
pub fn field_figure_size(panels: &[Panel<'_>]) -> (u32, u32) {
    let mut w = COLORBAR_W;
    for p in panels {
        let aspect = if p.bounds.height() > 0.0 && p.bounds.width() > 0.0 {
            (p.bounds.width() / p.bounds.height()).clamp(0.1, 10.0)
        } else {
            1.0
        };
        w += (PANEL_PLOT_H * aspect).round() as u32 + PANEL_YLAB + 2 * PANEL_MARGIN;
    }
    let h = FIG_TITLE_H + PANEL_TITLE_H + PANEL_PLOT_H as u32 + PANEL_XLAB + 2 * PANEL_MARGIN;
    (w.max(200), h)
}

/// Several fields side by side (one per mesh, paper Figs. 4/5 a–d) with one
/// shared colour range and colour bar labelled `colorbar_label`.
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
    let path = path.as_ref();
    if panels.is_empty() {
        return Err(PlotError::Empty("no panels"));
    }
    for p in panels {
        if p.positions.len() != p.values.len() {
            return Err(PlotError::LengthMismatch("positions vs values"));
        }
        p.bounds.check()?;
    }
    let range = match range {
        Some((lo, hi)) => {
            if !(lo.is_finite() && hi.is_finite() && hi >= lo) {
                return Err(PlotError::Bounds("colour range"));
            }
            (lo, hi)
        }
        None => {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for v in panels.iter().flat_map(|p| p.values.iter()) {
                if v.is_finite() {
                    lo = lo.min(*v);
                    hi = hi.max(*v);
                }
            }
            if !lo.is_finite() {
                (0.0, 1.0)
            } else {
                (lo, hi)
            }
        }
    };
    let (w, h) = size;
    if w < COLORBAR_W + 120 * panels.len() as u32 || h < FIG_TITLE_H + 140 {
        return Err(PlotError::Bounds("image too small"));
    }

    prepare_path(path)?;
    // drawn under a temporary name, renamed once presented: whole or absent
    let target = AtomicPath::new(path);
    let temp = target.temp().to_path_buf();
    let root = BitMapBackend::new(&temp, size).into_drawing_area();
    root.fill(&WHITE).map_err(de)?;
    let (head, body) = root.split_vertically(FIG_TITLE_H);
    if !title.is_empty() {
        head.draw(&Text::new(
            title.to_string(),
            ((w / 2) as i32, (FIG_TITLE_H / 2) as i32),
            ("sans-serif", 24)
                .into_font()
                .color(&BLACK)
                .pos(text_center()),
        ))
        .map_err(de)?;
    }
    let (fields, bar) = body.split_horizontally(w - COLORBAR_W);
    // panel widths proportional to their natural widths
    let natural: Vec<f64> = panels
        .iter()
        .map(|p| {
            PANEL_PLOT_H * (p.bounds.width() / p.bounds.height()).clamp(0.1, 10.0)
                + (PANEL_YLAB + 2 * PANEL_MARGIN) as f64
        })
        .collect();
    let total: f64 = natural.iter().sum();
    let avail = (w - COLORBAR_W) as f64;
    let mut breaks = Vec::with_capacity(panels.len());
    let mut acc = 0.0;
    for nat in &natural[..natural.len() - 1] {
        acc += nat / total * avail;
        breaks.push(acc.round() as i32);
    }
    let areas = fields.split_by_breakpoints(breaks, Vec::<i32>::new());
    for (p, area) in panels.iter().zip(&areas) {
        draw_panel(area, p, range)?;
    }
    draw_colorbar(&bar, range, colorbar_label)?;
    root.present().map_err(de)?;
    drop(root);
    target.commit().map_err(de)
}

fn text_center() -> plotters::style::text_anchor::Pos {
    use plotters::style::text_anchor::{HPos, Pos, VPos};
    Pos::new(HPos::Center, VPos::Center)
}

fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    p: &Panel<'_>,
    range: (f64, f64),
) -> Result<()> {
    let (aw, ah) = area.dim_in_pixel();
    let (head, plot) = area.split_vertically(PANEL_TITLE_H);
    if !p.title.is_empty() {
        head.draw(&Text::new(
            p.title.clone(),
            ((aw / 2) as i32, (PANEL_TITLE_H / 2) as i32),
            ("sans-serif", 20)
                .into_font()
                .color(&BLACK)
                .pos(text_center()),
        ))
        .map_err(de)?;
    }
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
        .label_style(("sans-serif", 14))
        .x_label_formatter(&|v| fmt_tick(*v, xs))
        .y_label_formatter(&|v| fmt_tick(*v, ys))
        .draw()
        .map_err(de)?;

    let finite: Vec<usize> = (0..p.positions.len())
        .filter(|&i| p.positions[i][0].is_finite() && p.positions[i][1].is_finite())
        .collect();
    let marker = match p.marker {
        Some(m) if m.is_finite() && m > 0.0 => m,
        _ => auto_marker(p.positions, &finite, b),
    };
    // low values first so that bands are drawn on top where points overlap
    let mut order = finite;
    order.sort_by(|&i, &j| {
        let (a, b) = (p.values[i], p.values[j]);
        let a = if a.is_finite() { a } else { f64::NEG_INFINITY };
        let b = if b.is_finite() { b } else { f64::NEG_INFINITY };
        a.total_cmp(&b)
    });
    let half = 0.5 * marker;
    chart
        .draw_series(order.iter().map(|&i| {
            let [x, y] = p.positions[i];
            Rectangle::new(
                [(x - half, y - half), (x + half, y + half)],
                map_value(p.values[i], range).filled(),
            )
        }))
        .map_err(de)?;
    Ok(())
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

fn draw_colorbar(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
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
        .margin_right(36)
        .right_y_label_area_size(58)
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
            ((w as i32) - 16, (h / 2) as i32),
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
