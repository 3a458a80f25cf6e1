//! PNG output checks: written, decodable, requested size, not blank, text
//! drawn; colour-map end points.

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
    assert_eq!(colormap(0.5), COLORMAP[2]);
    assert_eq!(colormap(f64::NAN), NAN_COLOR);
    assert_eq!(map_value(0.02, (0.02, 0.3)), COLORMAP[0]);
    assert_eq!(map_value(0.3, (0.02, 0.3)), COLORMAP[COLORMAP.len() - 1]);
    assert_eq!(map_value(f64::INFINITY, (0.0, 1.0)), NAN_COLOR);
    assert_eq!(map_value(1.0, (1.0, 1.0)), colormap(0.5));
    // halfway between two control points is their mean
    let c = colormap(0.125);
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
    plot_field(&path, "εq at δ = 2.26 mm", &x, &e, b, None).unwrap();
    let img = load(&path);
    let panel = Panel {
        title: String::new(),
        positions: &x,
        values: &e,
        bounds: b,
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
    let col_w = (w - 130) / 4;
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
        plot_field(&path, "", &x, &[1.0], b, None),
        Err(PlotError::LengthMismatch(_))
    ));
    let bad = Bounds::new(1.0, 0.0, 0.0, 1.0);
    assert!(plot_field(&path, "", &x, &[1.0, 2.0], bad, None).is_err());
    assert!(plot_field(&path, "", &x, &[1.0, 2.0], b, Some((2.0, 1.0))).is_err());
    assert!(plot_field_panels(&path, "", &[], None, "").is_err());
    let p = Panel {
        title: "tiny".into(),
        positions: &x,
        values: &[1.0, 2.0],
        bounds: b,
        marker: None,
    };
    assert!(matches!(
        plot_field_panels_sized(&path, (100, 100), "", &[p], None, ""),
        Err(PlotError::Bounds(_))
    ));
    assert!(!path.exists());
    // degenerate but valid: constant values, NaN values, no points
    plot_field(&path, "", &x, &[1.0, 1.0], b, None).unwrap();
    plot_field(&path, "", &x, &[f64::NAN, 1.0], b, None).unwrap();
    plot_field(&path, "", &[], &[], b, None).unwrap();
    // the smallest accepted size renders without panicking
    let p = Panel {
        title: "tiny".into(),
        positions: &x,
        values: &[1.0, 2.0],
        bounds: b,
        marker: None,
    };
    plot_field_panels_sized(&path, (250, 180), "t", &[p], None, "e").unwrap();
    assert!(path.exists());
}
