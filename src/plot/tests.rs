//! Figure checks: PNG written, decodable, requested size, not blank, text
//! drawn, SVG beside it with its labels; colour map end points and
//! lightness; legends beside the data; no background between the points of
//! a field; log ticks at decades.

use super::*;
use std::path::PathBuf;

/// Output directory: `$MPM_GEO_PLOT_DIR` if set (to look at the pictures),
/// else a temporary directory removed at the end of the test.
struct OutDir {
    path: PathBuf,
    _tmp: Option<tempfile::TempDir>,
}

fn out_dir() -> OutDir {
    match std::env::var_os("MPM_GEO_PLOT_DIR") {
        Some(d) => OutDir {
            path: PathBuf::from(d),
            _tmp: None,
        },
        None => {
            let t = tempfile::tempdir().unwrap();
            OutDir {
                path: t.path().to_path_buf(),
                _tmp: Some(t),
            }
        }
    }
}

fn load(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

fn count_where(img: &image::RgbImage, f: impl Fn(&image::Rgb<u8>) -> bool) -> usize {
    img.pixels().filter(|p| f(p)).count()
}

fn is_dark(p: &image::Rgb<u8>) -> bool {
    p.0.iter().all(|&c| c < 80)
}

fn near(p: &image::Rgb<u8>, c: RGBColor, tol: i32) -> bool {
    let d = |a: u8, b: u8| (a as i32 - b as i32).abs();
    d(p.0[0], c.0) <= tol && d(p.0[1], c.1) <= tol && d(p.0[2], c.2) <= tol
}

/// Dark (text) pixels in the rows `y0..y1`.
fn dark_in_rows(img: &image::RgbImage, y0: u32, y1: u32) -> usize {
    (y0..y1.min(img.height()))
        .flat_map(|y| (0..img.width()).map(move |x| (x, y)))
        .filter(|&(x, y)| is_dark(img.get_pixel(x, y)))
        .count()
}

#[test]
fn colormap_end_points_and_clamping() {
    assert_eq!(colormap(0.0), COLORMAP[0]);
    assert_eq!(colormap(1.0), COLORMAP[COLORMAP.len() - 1]);
    assert_eq!(colormap(-3.0), COLORMAP[0]);
    assert_eq!(colormap(7.0), COLORMAP[COLORMAP.len() - 1]);
    assert_eq!(colormap(0.5), COLORMAP[4]);
    assert_eq!(colormap(f64::NAN), NAN_COLOR);
    assert_eq!(map_value(0.02, (0.02, 0.3)), COLORMAP[0]);
    assert_eq!(map_value(0.3, (0.02, 0.3)), COLORMAP[COLORMAP.len() - 1]);
    assert_eq!(map_value(f64::INFINITY, (0.0, 1.0)), NAN_COLOR);
    assert_eq!(map_value(1.0, (1.0, 1.0)), colormap(0.5));
    // halfway between two control points is their mean
    let c = colormap(0.0625);
    let (a, b) = (COLORMAP[0], COLORMAP[1]);
    assert_eq!(c.2, ((a.2 as f64 + b.2 as f64) / 2.0).round() as u8);
    assert_eq!(series_color(0), series_color(PALETTE.len()));
}

fn fig3_series() -> Vec<Series> {
    // softening curves, one per mesh, local dashed and nonlocal solid
    let mut v = Vec::new();
    for (k, h) in ["3.3", "2.0", "1.4", "1.0"].iter().enumerate() {
        for dashed in [true, false] {
            let soft = if dashed { 6.0 + 2.0 * k as f64 } else { 5.0 };
            let points = (0..=226)
                .map(|i| {
                    let d = i as f64 * 0.01;
                    let f = if d < 1.3 {
                        12.63 * d * (1.0 - 0.2 * d / 1.3)
                    } else {
                        13.13 - soft * (d - 1.3)
                    };
                    (d, f.max(0.0))
                })
                .collect();
            v.push(Series {
                name: format!("{}, h = {h} mm", if dashed { "local" } else { "nonlocal" }),
                points,
                dashed,
                color: k,
                marker: Some(Marker::of_regularisation(!dashed)),
            });
        }
    }
    v
}

#[test]
fn curves_png_written_with_size_and_content() {
    let dir = out_dir();
    let path = dir.path.join("curves.png");
    let series = fig3_series();
    plot_curves(&path, "Biaxial test", "δ (mm)", "F (kN/m)", &series).unwrap();
    let img = load(&path);
    assert_eq!((img.width(), img.height()), CURVE_SIZE);
    let non_white = count_where(&img, |p| p.0 != [255, 255, 255]);
    assert!(non_white > 5000, "blank picture: {non_white}");
    // every mesh colour appears (lines and legend)
    for k in 0..4 {
        let n = count_where(&img, |p| near(p, series_color(k), 10));
        assert!(n > 200, "colour {k} drawn by {n} pixels");
    }
    // title text drawn in the top band
    assert!(dark_in_rows(&img, 0, 45) > 50);

    let small = dir.path.join("curves_small.png");
    plot_curves_sized(&small, (400, 300), "t", "x", "y", &series[..2]).unwrap();
    let img = load(&small);
    assert_eq!((img.width(), img.height()), (400, 300));
}

#[test]
fn curves_reject_empty_input() {
    let dir = out_dir();
    let path = dir.path.join("none.png");
    let _ = std::fs::remove_file(&path);
    assert!(plot_curves(&path, "t", "x", "y", &[]).is_err());
    let s = Series {
        name: "nan".into(),
        points: vec![(f64::NAN, 1.0)],
        dashed: false,
        color: 0,
        marker: None,
    };
    assert!(matches!(
        plot_curves(&path, "t", "x", "y", &[s]),
        Err(PlotError::Empty(_))
    ));
    assert!(!path.exists());
}

/// A biaxial-like quarter specimen: MPs at 2×2 Gauss positions, a Gaussian
/// band of width ~w from the top left towards the right edge.
fn specimen(h: f64, w: f64) -> (Vec<[f64; 2]>, Vec<f64>) {
    let g = 0.5 / 3f64.sqrt();
    let (nx, ny) = ((0.03 / h).round() as usize, (0.05 / h).round() as usize);
    let mut x = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            for (a, b) in [(-g, -g), (g, -g), (-g, g), (g, g)] {
                x.push([(i as f64 + 0.5 + a) * h, (j as f64 + 0.5 + b) * h]);
            }
        }
    }
    let th = 55f64.to_radians();
    let n = [-th.sin(), th.cos()];
    let s = w / 2.3548;
    let e = x
        .iter()
        .map(|p| {
            let d = (p[0] - 0.0) * n[0] + (p[1] - 0.035) * n[1];
            0.01 + 0.3 * (-d * d / (2.0 * s * s)).exp()
        })
        .collect();
    (x, e)
}

#[test]
fn field_png_single_and_panels() {
    let dir = out_dir();
    let b = Bounds::new(0.0, 0.04, 0.0, 0.05);
    let (x, e) = specimen(0.001, 0.01);
    let path = dir.path.join("field.png");
    plot_field(&path, "εq at δ = 2.26 mm", &x, &e, None, b, None, "εq (1)").unwrap();
    let img = load(&path);
    let panel = Panel {
        title: String::new(),
        positions: &x,
        values: &e,
        bounds: b,
        volumes: None,
        marker: None,
    };
    assert_eq!(
        (img.width(), img.height()),
        field_figure_size(std::slice::from_ref(&panel))
    );
    // both ends of the colour map are present (field and colour bar)
    let lo = count_where(&img, |p| near(p, COLORMAP[0], 12));
    let hi = count_where(&img, |p| near(p, COLORMAP[COLORMAP.len() - 1], 12));
    assert!(lo > 1000 && hi > 100, "lo {lo}, hi {hi}");
    assert!(dark_in_rows(&img, 0, 40) > 50, "title not drawn");

    // four meshes side by side, shared range
    let meshes = [1.0 / 300.0, 1.0 / 500.0, 1.0 / 700.0, 1.0 / 1000.0];
    let data: Vec<_> = meshes.iter().map(|&h| specimen(h, 0.01)).collect();
    let labels = ["(a)", "(b)", "(c)", "(d)"];
    let panels: Vec<Panel> = data
        .iter()
        .zip(meshes)
        .zip(labels)
        .map(|(((x, e), h), l)| Panel {
            title: format!("{l} h = {:.1} mm", h * 1e3),
            positions: x,
            values: e,
            bounds: b,
            volumes: None,
            marker: Some(0.6 * h),
        })
        .collect();
    let path = dir.path.join("panels.png");
    plot_field_panels(&path, "Nonlocal, εq", &panels, Some((0.0, 0.31)), "εq").unwrap();
    let img = load(&path);
    let (w, h) = field_figure_size(&panels);
    assert_eq!((img.width(), img.height()), (w, h));
    assert!(w > 4 * 400);
    // every panel's column range holds coloured (non-grey, non-white) pixels
    let col_w = (w - COLORBAR_W) / 4;
    for k in 0..4 {
        let n = (k * col_w..(k + 1) * col_w)
            .flat_map(|x| (0..h).map(move |y| (x, y)))
            .filter(|&(x, y)| {
                let p = img.get_pixel(x, y).0;
                p.iter().max().unwrap() - p.iter().min().unwrap() > 60
            })
            .count();
        assert!(n > 20_000, "panel {k}: {n} coloured pixels");
    }
    let sized = dir.path.join("panels_sized.png");
    plot_field_panels_sized(&sized, (1000, 400), "", &panels[..2], None, "").unwrap();
    let img = load(&sized);
    assert_eq!((img.width(), img.height()), (1000, 400));
}

#[test]
fn field_rejects_bad_input() {
    let dir = out_dir();
    let path = dir.path.join("bad.png");
    let _ = std::fs::remove_file(&path);
    let b = Bounds::new(0.0, 1.0, 0.0, 1.0);
    let x = [[0.5, 0.5], [0.2, 0.2]];
    assert!(matches!(
        plot_field(&path, "", &x, &[1.0], None, b, None, ""),
        Err(PlotError::LengthMismatch(_))
    ));
    let bad = Bounds::new(1.0, 0.0, 0.0, 1.0);
    assert!(plot_field(&path, "", &x, &[1.0, 2.0], None, bad, None, "").is_err());
    assert!(plot_field(&path, "", &x, &[1.0, 2.0], None, b, Some((2.0, 1.0)), "").is_err());
    assert!(plot_field_panels(&path, "", &[], None, "").is_err());
    let p = Panel {
        title: "tiny".into(),
        positions: &x,
        values: &[1.0, 2.0],
        bounds: b,
        volumes: None,
        marker: None,
    };
    assert!(matches!(
        plot_field_panels_sized(&path, (100, 100), "", &[p], None, ""),
        Err(PlotError::Bounds(_))
    ));
    assert!(!path.exists());
    // degenerate but valid: constant values, NaN values, no points
    assert!(matches!(
        plot_field(&path, "", &x, &[1.0, 2.0], Some(&[1.0]), b, None, ""),
        Err(PlotError::LengthMismatch(_))
    ));
    plot_field(&path, "", &x, &[1.0, 1.0], None, b, None, "").unwrap();
    plot_field(&path, "", &x, &[f64::NAN, 1.0], None, b, None, "").unwrap();
    plot_field(&path, "", &[], &[], None, b, None, "").unwrap();
    // the smallest accepted size renders without panicking
    let p = Panel {
        title: "tiny".into(),
        positions: &x,
        values: &[1.0, 2.0],
        bounds: b,
        volumes: None,
        marker: None,
    };
    plot_field_panels_sized(&path, (320, 240), "t", &[p], None, "e").unwrap();
    assert!(path.exists());
}

/// CIE L* of an sRGB colour (white point of standard daylight).
fn lightness(c: RGBColor) -> f64 {
    let lin = |u: u8| {
        let u = u as f64 / 255.0;
        if u <= 0.04045 {
            u / 12.92
        } else {
            ((u + 0.055) / 1.055).powf(2.4)
        }
    };
    let y = 0.2126 * lin(c.0) + 0.7152 * lin(c.1) + 0.0722 * lin(c.2);
    if y > 216.0 / 24389.0 {
        116.0 * y.cbrt() - 16.0
    } else {
        y * 24389.0 / 27.0
    }
}

#[test]
fn colormap_lightness_rises_steadily() {
    // 64 steps: each moves the channels by several units, so rounding to
    // u8 cannot reverse a step
    let n = 64;
    let l: Vec<f64> = (0..=n)
        .map(|k| lightness(colormap(k as f64 / n as f64)))
        .collect();
    for (k, w) in l.windows(2).enumerate() {
        assert!(w[1] > w[0], "L* falls at {k}/{n}: {} -> {}", w[0], w[1]);
    }
    // dark to light over most of the lightness scale, no plateau
    assert!(l[0] < 20.0 && l[n] > 85.0, "L* from {} to {}", l[0], l[n]);
    let steps: Vec<f64> = l.windows(2).map(|w| w[1] - w[0]).collect();
    let mean = (l[n] - l[0]) / n as f64;
    assert!(
        steps.iter().all(|&s| s < 2.5 * mean),
        "uneven lightness steps"
    );
    // the rainbow it replaces is not monotone: the test can fail
    let rainbow = [
        RGBColor(0, 0, 180),
        RGBColor(0, 200, 255),
        RGBColor(40, 200, 40),
    ];
    assert!(lightness(rainbow[2]) < lightness(rainbow[1]));
}

/// Whether the file at `path` looks like a whole SVG document holding every
/// one of `texts`.
fn assert_svg(path: &Path, texts: &[&str]) {
    let svg = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(svg.contains("<svg") && svg.trim_end().ends_with("</svg>"));
    assert_eq!(
        svg.matches("<text").count(),
        svg.matches("</text>").count(),
        "unbalanced text elements"
    );
    for t in texts {
        assert!(svg.contains(t), "`{t}` missing from {}", path.display());
    }
}

#[test]
fn every_figure_has_its_svg_beside_it() {
    let dir = out_dir();
    let path = dir.path.join("svg_curves.png");
    plot_curves(&path, "Biaxial test", "δ (mm)", "F (kN/m)", &fig3_series()).unwrap();
    assert_eq!(svg_path(&path), dir.path.join("svg_curves.svg"));
    assert_svg(
        &svg_path(&path),
        &["Biaxial test", "δ (mm)", "F (kN/m)", "local, h = 3.3 mm"],
    );
    let b = Bounds::new(0.0, 0.04, 0.0, 0.05);
    let (x, e) = specimen(0.002, 0.01);
    let path = dir.path.join("svg_field.png");
    plot_field(&path, "εq", &x, &e, None, b, None, "εq (1)").unwrap();
    assert!(path.exists());
    assert_svg(&svg_path(&path), &[FIELD_X_LABEL, FIELD_Y_LABEL, "εq (1)"]);
}

#[test]
fn the_legend_sits_beside_the_curves() {
    let dir = out_dir();
    let path = dir.path.join("legend.png");
    // curves through the whole data area, the upper right corner included
    let series: Vec<Series> = (0..4)
        .map(|k| Series {
            name: format!("nonlocal implicit h={k}.000 m"),
            points: (0..=100)
                .map(|i| (i as f64, 10.0 - k as f64 + 0.01 * i as f64))
                .collect(),
            dashed: k % 2 == 0,
            color: k,
            marker: Some(Marker::of_index(k)),
        })
        .collect();
    plot_curves(&path, "t", "x (m)", "y (m)", &series).unwrap();
    let img = load(&path);
    // the legend column, right of its line samples: names only, no curve
    let entries: Vec<LegendEntry> = series.iter().map(LegendEntry::of).collect();
    let lw = ensure_fonts()
        .map(|()| {
            let mut buf = vec![0u8; (CURVE_SIZE.0 * CURVE_SIZE.1 * 3) as usize];
            let area = BitMapBackend::with_buffer(&mut buf, CURVE_SIZE).into_drawing_area();
            legend_width(&area, &entries)
        })
        .unwrap();
    assert!(lw > 150 && lw < CURVE_SIZE.0 / 2, "legend width {lw}");
    let names_x = CURVE_SIZE.0 - lw + LEGEND_SAMPLE as u32 + 12;
    let in_names = |f: &dyn Fn(&image::Rgb<u8>) -> bool| {
        (names_x..img.width())
            .flat_map(|x| (0..img.height()).map(move |y| (x, y)))
            .filter(|&(x, y)| f(img.get_pixel(x, y)))
            .count()
    };
    for k in 0..4 {
        let n = in_names(&|p| near(p, series_color(k), 30));
        assert_eq!(n, 0, "curve {k} drawn under the legend names");
    }
    assert!(in_names(&|p| is_dark(p)) > 300, "legend names not drawn");
    // and the curves are drawn, left of the legend
    for k in 0..4 {
        assert!(count_where(&img, |p| near(p, series_color(k), 10)) > 300);
    }
}

#[test]
fn local_and_nonlocal_differ_beyond_colour() {
    assert_ne!(
        Marker::of_regularisation(true),
        Marker::of_regularisation(false)
    );
    let distinct: std::collections::HashSet<_> = (0..4)
        .map(|i| format!("{:?}", Marker::of_index(i)))
        .collect();
    assert_eq!(distinct.len(), 4);
    assert_eq!(marker_indices(5, 0.5), [0, 1, 2, 3, 4]);
    let idx = marker_indices(227, 0.0);
    assert_eq!(idx.len(), MARKERS_PER_CURVE);
    assert_eq!((idx[0], idx[idx.len() - 1]), (0, 226));
    // staggered: another series' markers fall between these
    let other = marker_indices(227, marker_phase(1));
    assert!(other.iter().all(|i| !idx.contains(i)), "{other:?}");
    assert!(other.iter().all(|&i| i < 227));
    // a grey copy of the same two curves still tells them apart: drawn in
    // one colour, the dashed curve with triangles differs from the solid
    // one with circles
    let dir = out_dir();
    let one = |dashed: bool, marker| Series {
        name: String::new(),
        points: (0..=100).map(|i| (i as f64, 1.0)).collect(),
        dashed,
        color: 7,
        marker: Some(marker),
    };
    let a = dir.path.join("style_a.png");
    let b = dir.path.join("style_b.png");
    plot_curves(&a, "", "x (m)", "y (m)", &[one(true, Marker::Triangle)]).unwrap();
    plot_curves(&b, "", "x (m)", "y (m)", &[one(false, Marker::Circle)]).unwrap();
    let (a, b) = (load(&a), load(&b));
    let grey = |img: &image::RgbImage| count_where(img, |p| near(p, series_color(7), 10));
    let (na, nb) = (grey(&a), grey(&b));
    assert!(na > 200 && nb > 200);
    assert!(
        (na as f64 - nb as f64).abs() > 0.1 * nb as f64,
        "dashed+triangles {na} px vs solid+circles {nb} px"
    );
}

#[test]
fn log_axes_are_labelled_at_decades() {
    assert_eq!(decade_bounds(0.003, 0.2), (1e-3, 1.0));
    assert_eq!(decade_bounds(2.0, 3.0), (1.0, 10.0));
    let (lo, hi) = decade_bounds(1e-3, 1e-3);
    assert!(hi > lo);
    let t = decade_ticks(1e-3, 1.0, 10);
    assert_eq!(t.len(), 4);
    for (v, k) in t.iter().zip(-3..) {
        assert!((v.log10() - k as f64).abs() < 1e-12, "{v}");
    }
    // many decades: every 3rd labelled, at most 5
    let t = decade_ticks(1e-12, 1.0, 5);
    assert!(t.len() <= 5 && t.len() >= 4, "{t:?}");
    assert!((t[1] / t[0] - 1e3).abs() < 1e-6);
    assert_eq!(decade_label(1e-3), "10⁻³");
    assert_eq!(decade_label(1e4), "10⁴");
    assert_eq!(decade_label(1e-12), "10⁻¹²");
    assert_eq!(decade_label(1.0), "1");
    assert_eq!(decade_label(10.0), "10");
    assert_eq!(decade_label(0.1), "0.1");
    assert!(minor_ticks(1e-2, 1.0).contains(&0.05));
    assert_eq!(minor_ticks(1e-2, 1.0).len(), 16);

    let dir = out_dir();
    let path = dir.path.join("work_precision.png");
    let series: Vec<Series> = (0..3)
        .map(|k| Series {
            name: format!("method {k}"),
            points: (0..5)
                .map(|i| {
                    let t = 0.01 * 3f64.powi(i);
                    (
                        t,
                        0.2 / (k as f64 + 1.0) * t.powf(-1.0 - k as f64 * 0.5) * 1e-3,
                    )
                })
                .collect(),
            dashed: false,
            color: k,
            marker: None,
        })
        .collect();
    plot_work_precision(&path, "study", &series, &[(0.01, 1e-2), (0.81, 1e-5)]).unwrap();
    let img = load(&path);
    assert_eq!((img.width(), img.height()), CURVE_SIZE);
    assert_svg(
        &svg_path(&path),
        &[
            "wall time (s)",
            "error (relative, 1)",
            "10⁻",
            "Pareto front",
            "method 2",
        ],
    );
    // only decades are labelled: no "0.02"-style label in the SVG text
    let svg = std::fs::read_to_string(svg_path(&path)).unwrap();
    assert!(
        !svg.contains(">0.02<") && !svg.contains(">2e"),
        "non-decade tick label"
    );
}

/// Fraction of background (white) pixels inside the box of the pixels of
/// colour `c` in the field columns of `img` (2 px inset).
fn background_in_block(img: &image::RgbImage, c: RGBColor) -> f64 {
    let w = img.width() - COLORBAR_W;
    let (mut x0, mut x1, mut y0, mut y1) = (u32::MAX, 0, u32::MAX, 0);
    for y in 0..img.height() {
        for x in 0..w {
            if near(img.get_pixel(x, y), c, 3) {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
    }
    assert!(x1 > x0 + 50 && y1 > y0 + 50, "block not found");
    let (x0, x1, y0, y1) = (x0 + 2, x1 - 2, y0 + 2, y1 - 2);
    let inside = ((x1 - x0 + 1) * (y1 - y0 + 1)) as f64;
    let white = (y0..=y1)
        .flat_map(|y| (x0..=x1).map(move |x| (x, y)))
        .filter(|&(x, y)| near(img.get_pixel(x, y), WHITE, 40))
        .count();
    white as f64 / inside
}

/// A block of 2×2 points per cell of side `h` at the Gauss positions,
/// `n × n` cells, with the volume h²/4 of each point.
fn gauss_block(h: f64, n: usize) -> (Vec<[f64; 2]>, Vec<f64>) {
    let g = 0.5 / 3f64.sqrt();
    let mut x = Vec::new();
    for j in 0..n {
        for i in 0..n {
            for (a, b) in [(-g, -g), (g, -g), (-g, g), (g, g)] {
                x.push([
                    0.1 + (i as f64 + 0.5 + a) * h,
                    0.1 + (j as f64 + 0.5 + b) * h,
                ]);
            }
        }
    }
    let v = vec![h * h / 4.0; x.len()];
    (x, v)
}

#[test]
fn a_dense_block_of_points_has_no_background_inside() {
    let dir = out_dir();
    let b = Bounds::new(0.0, 1.0, 0.0, 1.0);
    let c = colormap(0.5);
    let block = |name: &str, x: &[[f64; 2]], v: Option<&[f64]>, marker| {
        let values = vec![1.0; x.len()];
        let panel = Panel {
            title: String::new(),
            positions: x,
            values: &values,
            bounds: b,
            volumes: v,
            marker,
        };
        let path = dir.path.join(name);
        plot_field_panels(&path, "", &[panel], Some((0.0, 2.0)), "v (1)").unwrap();
        background_in_block(&load(&path), c)
    };
    // uniform lattice, spacing d, V = d²
    let (d, n) = (0.8 / 60.0, 60);
    let x: Vec<[f64; 2]> = (0..n * n)
        .map(|k| [0.1 + (k % n) as f64 * d, 0.1 + (k / n) as f64 * d])
        .collect();
    let v = vec![d * d; x.len()];
    let f = block("block_uniform.png", &x, Some(&v), None);
    assert!(f < 1e-4, "uniform block: {f} of its pixels are background");
    // the Gauss layout (spacing 0.42h and 0.58h, √V = 0.5h)
    let (x, v) = gauss_block(0.8 / 30.0, 30);
    let f = block("block_gauss.png", &x, Some(&v), None);
    assert!(f < 1e-4, "Gauss block: {f} of its pixels are background");
    // squares of side √V alone would leave slivers: the measure sees them
    let f = block("block_slivers.png", &x, None, Some(0.45 * 0.8 / 30.0));
    assert!(f > 0.05, "slivers not seen: {f}");
    // a stretched region: its points spaced 1.4 d in x with V = 1.4 d²
    // (spacing 1.18 √V along x, within EXTENT_FACTOR)
    let x: Vec<[f64; 2]> = (0..42 * 60)
        .map(|k| [0.1 + (k % 42) as f64 * 1.4 * d, 0.1 + (k / 42) as f64 * d])
        .collect();
    let v = vec![1.4 * d * d; x.len()];
    let f = block("block_stretched.png", &x, Some(&v), None);
    assert!(
        f < 1e-4,
        "stretched block: {f} of its pixels are background"
    );
    // stretched 2:1 at constant volume (a shear band's points): spacing 2d
    // along x, d/2 along y, √V = d
    let x: Vec<[f64; 2]> = (0..30 * 120)
        .map(|k| {
            [
                0.1 + (k % 30) as f64 * 2.0 * d,
                0.1 + (k / 30) as f64 * 0.5 * d,
            ]
        })
        .collect();
    let v = vec![d * d; x.len()];
    let f = block("block_band.png", &x, Some(&v), None);
    assert!(
        f < 1e-4,
        "2:1 stretched block: {f} of its pixels are background"
    );
}

#[test]
fn stretched_points_grow_and_lost_points_do_not() {
    let d = 0.01;
    // a row stretched 2:1 between unstretched rows
    let mut x = Vec::new();
    for j in 0..5 {
        let (dx, n) = if j == 2 { (2.0 * d, 20) } else { (d, 40) };
        for i in 0..n {
            x.push([i as f64 * dx, j as f64 * d]);
        }
    }
    x.push([5.0, 5.0]); // lost far away
    let base = vec![d; x.len()];
    let sides = extents(&x, &base);
    let tol = 1e-9;
    let own = EXTENT_FACTOR * d;
    // an inner point of an unstretched row: its own size
    let (wx, wy) = sides[40 + 10];
    assert!(
        (wx - own).abs() < tol && (wy - own).abs() < tol,
        "{wx} {wy}"
    );
    // an inner point of the stretched row: as wide as its spacing (with the
    // margin), no higher than its own size
    let (wx, wy) = sides[80 + 5];
    assert!(
        wx >= 2.0 * d && wx <= 2.0 * CELL_MARGIN * d + tol && (wy - own).abs() < tol,
        "{wx} {wy}"
    );
    // a point of the top row: not drawn taller (outward) than its own size
    let (_, wy) = sides[140 + 20];
    assert!((wy - own).abs() < tol, "{wy}");
    // the lost point keeps its own size
    let (wx, wy) = sides[180];
    assert!(
        (wx - own).abs() < tol && (wy - own).abs() < tol,
        "{wx} {wy}"
    );
    assert!(sides
        .iter()
        .all(|&(wx, wy)| wx <= EXTENT_CAP * d + tol && wy <= EXTENT_CAP * d + tol));
}

/// A slender body (a bar 20 times taller than wide, as the campaign of
/// `elastic/bar_explicit.toml` draws) still gets a field figure: its panel
/// is widened to the narrowest one drawn, instead of refusing the figure.
#[test]
fn a_slender_body_gets_a_field_figure() {
    let dir = out_dir();
    let b = Bounds::new(0.0, 0.05, 0.0, 1.0);
    let x: Vec<[f64; 2]> = (0..40)
        .map(|i| [0.025, 0.0125 + 0.025 * i as f64])
        .collect();
    let e: Vec<f64> = (0..40).map(|i| i as f64).collect();
    let path = dir.path.join("bar.png");
    plot_field(&path, "bar", &x, &e, None, b, None, "εq (1)").unwrap();
    let img = load(&path);
    assert!(img.width() >= MIN_PANEL_W + COLORBAR_W, "{}", img.width());
}
