//! Run outputs: `curve.csv` (one row per step, each row written whole and
//! flushed as the run goes), particle snapshots as VTK `.vtu` (ParaView) with
//! their `.pvd` collection, and `run.json`. Every file but `curve.csv` is
//! written under a temporary name and renamed ([`crate::atomic_file`]).

use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::atomic_file::{write_atomic, AtomicFile};
use crate::constitutive::{deviatoric_stress, mean_stress};
use crate::csv_columns::number;
use crate::error::RunError;
use crate::particles::Particles;

/// An output file that could not be written; [`OutputError::at`] adds the
/// step and time of the run.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {}: {source}", path.display())]
pub struct OutputError {
    /// The file (its final name).
    pub path: PathBuf,
    /// Why.
    #[source]
    pub source: std::io::Error,
}

impl OutputError {
    fn new(path: &Path, source: impl Into<std::io::Error>) -> Self {
        Self {
            path: path.to_path_buf(),
            source: source.into(),
        }
    }

    /// The run error of this failure while writing the outputs of `step` at `time`.
    pub fn at(self, step: usize, time: f64) -> RunError {
        RunError::Output {
            step,
            time,
            path: self.path.display().to_string(),
            message: self.source.to_string(),
        }
    }
}

pub use crate::simulation::{STEP_COLUMN, TIME_COLUMN};

/// Name of the snapshots' ParaView collection in the output directory.
pub const PVD_FILE: &str = "particles.pvd";

/// Where a run's outputs stood after a step: what a checkpoint stores so a
/// resumed run writes on exactly as the uninterrupted one would.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct OutputCursor {
    /// Step of the last `curve.csv` row (`None` before the first).
    pub last_row_step: Option<usize>,
    /// `[output] snapshot_times` not reached yet, latest first.
    pub pending_times: Vec<f64>,
    /// The fields at the snapshot times reached so far.
    pub fields: Vec<FieldSnapshot>,
    /// The snapshots written so far, (time, file name), as in the `.pvd`.
    pub snapshots: Vec<(f64, String)>,
    /// Length of `curve.csv` then, bytes.
    pub curve_bytes: u64,
    /// CRC-32 of those bytes.
    pub curve_checksum: u32,
}

/// The material points' positions and strains at one snapshot time (what the
/// campaigns plot as the paper's Fig. 10).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct FieldSnapshot {
    /// The snapshot time asked for in `[output] snapshot_times`, s.
    pub requested_time: f64,
    /// The time of the step written, s (the first step reaching it).
    pub time: f64,
    /// Positions x_p, m.
    pub positions: Vec<[f64; 2]>,
    /// Deviatoric Hencky strain εq per point (theory D8).
    pub eps_q: Vec<f64>,
    /// Current volume V_p, m³ per m.
    pub volumes: Vec<f64>,
}

impl FieldSnapshot {
    /// The fields of `sim` now, for the requested time `requested_time`.
    pub fn of(sim: &crate::simulation::Simulation, requested_time: f64) -> Self {
        let p = &sim.model.state.particles;
        Self {
            requested_time,
            time: sim.model.state.time,
            positions: p.position.clone(),
            eps_q: p.def_grad.iter().map(deviatoric_hencky_strain).collect(),
            volumes: p.volume.clone(),
        }
    }
}

/// `curve.csv`: columns `step_1, time_s`, the step's own columns
/// ([`crate::simulation::Simulation::step_column_names`]) and one per monitor
/// (named with its unit, [`crate::scene::MonitorSpec::column`]). Each row is
/// formatted first and written with one write, then flushed; if that write
/// fails (a full disk) the file is cut back to its last whole row and the
/// writer refuses further rows, so the file never ends in a partial row.
pub struct CurveWriter {
    file: File,
    path: PathBuf,
    /// Length of the file up to its last whole row, bytes.
    whole: u64,
    /// A failed row could not be cut back: write nothing more.
    broken: bool,
}

impl CurveWriter {
    /// Create the file and write the header: `step_1, time_s` and `columns`
    /// (on failure the file is removed).
    pub fn create(path: &Path, columns: &[String]) -> Result<Self, OutputError> {
        let file = File::create(path).map_err(|e| OutputError::new(path, e))?;
        let mut writer = Self {
            file,
            path: path.to_path_buf(),
            whole: 0,
            broken: false,
        };
        let mut header = vec![STEP_COLUMN.to_string(), TIME_COLUMN.to_string()];
        header.extend(columns.iter().cloned());
        if let Err(e) = writer.write_record(&header) {
            let _ = std::fs::remove_file(path);
            return Err(e);
        }
        Ok(writer)
    }

    /// Open an existing file to append rows after its first `keep` bytes
    /// (resuming a run: later rows are cut off). Errs when it is shorter.
    pub fn reopen(path: &Path, keep: u64) -> Result<Self, OutputError> {
        let error = |e: std::io::Error| OutputError::new(path, e);
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(error)?;
        let len = file.metadata().map_err(error)?.len();
        if len < keep {
            return Err(error(std::io::Error::other(format!(
                "{len} bytes, fewer than the {keep} to keep"
            ))));
        }
        file.set_len(keep).map_err(error)?;
        file.seek(SeekFrom::Start(keep)).map_err(error)?;
        Ok(Self {
            file,
            path: path.to_path_buf(),
            whole: keep,
            broken: false,
        })
    }

    /// Append one row (values written with full round-trip precision, a
    /// value that is not finite as an empty field) and flush.
    pub fn row(&mut self, step: usize, time: f64, values: &[f64]) -> Result<(), OutputError> {
        let mut record = vec![step.to_string(), number(time)];
        record.extend(values.iter().map(|&v| number(v)));
        self.write_record(&record)
    }

    fn write_record(&mut self, record: &[String]) -> Result<(), OutputError> {
        let path = self.path.clone();
        let error = |e: std::io::Error| OutputError::new(&path, e);
        if self.broken {
            return Err(error(std::io::Error::other(
                "an earlier row could not be written",
            )));
        }
        let mut line = csv::Writer::from_writer(Vec::new());
        line.write_record(record)
            .map_err(|e| error(std::io::Error::other(e)))?;
        let line = line
            .into_inner()
            .map_err(|e| error(std::io::Error::other(e.to_string())))?;
        let written = self.file.write_all(&line).and_then(|()| self.file.flush());
        if let Err(e) = written {
            // cut a partial row off again
            let cut = self
                .file
                .set_len(self.whole)
                .and_then(|()| self.file.seek(SeekFrom::Start(self.whole)));
            self.broken = cut.is_err();
            return Err(error(e));
        }
        self.whole += line.len() as u64;
        Ok(())
    }
}

/// Equivalent deviatoric Hencky strain εq = sqrt(⅔ e:e) of a deformation
/// gradient F (in-plane, row-major, F_zz = 1) (theory D8).
pub fn deviatoric_hencky_strain(f: &[f64; 4]) -> f64 {
    // b = F Fᵀ (2×2 symmetric), eigen-decomposition in closed form.
    let b11 = f[0] * f[0] + f[1] * f[1];
    let b12 = f[0] * f[2] + f[1] * f[3];
    let b22 = f[2] * f[2] + f[3] * f[3];
    let mean = 0.5 * (b11 + b22);
    let radius = (0.25 * (b11 - b22).powi(2) + b12 * b12).sqrt();
    let (l1, l2) = (mean + radius, (mean - radius).max(f64::MIN_POSITIVE));
    // principal Hencky strains ½ ln λ, with ε_zz = 0
    let e = [0.5 * l1.ln(), 0.5 * l2.ln(), 0.0];
    let tr = (e[0] + e[1] + e[2]) / 3.0;
    let dev2: f64 = e.iter().map(|v| (v - tr).powi(2)).sum();
    (2.0 / 3.0 * dev2).sqrt()
}

/// Write the material points as a VTK XML unstructured grid of vertices with
/// displacement, velocity, stress, strain, plastic strain, κ, κ̄, p, q and εq.
/// Written under a temporary name and renamed: the file is whole or absent.
pub fn write_vtu(path: &Path, particles: &Particles) -> Result<(), OutputError> {
    let error = |e| OutputError::new(path, e);
    let mut w = AtomicFile::create(path).map_err(error)?;
    write_vtu_body(&mut w, particles).map_err(error)?;
    w.commit().map_err(error)
}

/// The ParaView collection `path` (`particles.pvd`) of the snapshots written
/// so far, `(time, file name)` in order, so a series opens as an animation
/// with its times; rewritten whole (temporary name, rename).
pub fn write_pvd(path: &Path, snapshots: &[(f64, String)]) -> Result<(), OutputError> {
    let mut text = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n<Collection>\n",
    );
    for (time, file) in snapshots {
        text += &format!(
            "<DataSet timestep=\"{time:e}\" group=\"\" part=\"0\" file=\"{}\"/>\n",
            xml_escape(file)
        );
    }
    text += "</Collection>\n</VTKFile>\n";
    write_atomic(path, text).map_err(|e| OutputError::new(path, e))
}

fn xml_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('"', "&quot;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn write_vtu_body(w: &mut impl Write, p: &Particles) -> std::io::Result<()> {
    let n = p.len();
    writeln!(w, r#"<?xml version="1.0"?>"#)?;
    writeln!(
        w,
        r#"<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">"#
    )?;
    writeln!(
        w,
        "<UnstructuredGrid>\n<Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">"
    )?;
    writeln!(
        w,
        r#"<Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">"#
    )?;
    for x in &p.position {
        writeln!(w, "{:e} {:e} 0", x[0], x[1])?;
    }
    writeln!(w, "</DataArray></Points>")?;
    writeln!(w, "<Cells>")?;
    write_int_array(w, "connectivity", 0..n)?;
    write_int_array(w, "offsets", 1..n + 1)?;
    writeln!(w, r#"<DataArray type="UInt8" Name="types" format="ascii">"#)?;
    for _ in 0..n {
        write!(w, "1 ")?;
    }
    writeln!(w, "\n</DataArray>\n</Cells>")?;
    writeln!(w, "<PointData>")?;
    let vectors: [(&str, Vec<[f64; 2]>); 2] = [
        ("displacement", (0..n).map(|i| p.displacement(i)).collect()),
        ("velocity", p.velocity.clone()),
    ];
    for (name, data) in vectors {
        writeln!(
            w,
            r#"<DataArray type="Float64" Name="{name}" NumberOfComponents="3" format="ascii">"#
        )?;
        for v in data {
            writeln!(w, "{:e} {:e} 0", v[0], v[1])?;
        }
        writeln!(w, "</DataArray>")?;
    }
    let tensors: [(&str, Vec<[f64; 4]>); 3] = [
        ("stress", p.stress.clone()),
        ("strain", p.strain.clone()),
        (
            "plastic_strain",
            p.state.iter().map(|s| s.plastic_strain).collect(),
        ),
    ];
    for (name, data) in tensors {
        writeln!(
            w,
            r#"<DataArray type="Float64" Name="{name}" NumberOfComponents="4" ComponentName0="xx" ComponentName1="yy" ComponentName2="zz" ComponentName3="xy" format="ascii">"#
        )?;
        for v in data {
            writeln!(w, "{:e} {:e} {:e} {:e}", v[0], v[1], v[2], v[3])?;
        }
        writeln!(w, "</DataArray>")?;
    }
    let scalars: [(&str, Vec<f64>); 7] = [
        (
            "plastic_strain_eq",
            p.state.iter().map(|s| s.plastic_strain_eq).collect(),
        ),
        (
            "plastic_strain_eq_nonlocal",
            p.state
                .iter()
                .map(|s| s.plastic_strain_eq_nonlocal)
                .collect(),
        ),
        ("p", p.stress.iter().map(mean_stress).collect()),
        ("q", p.stress.iter().map(deviatoric_stress).collect()),
        (
            "deviatoric_strain",
            p.def_grad.iter().map(deviatoric_hencky_strain).collect(),
        ),
        ("volume", p.volume.clone()),
        ("material", p.material.iter().map(|&m| m as f64).collect()),
    ];
    for (name, data) in scalars {
        writeln!(
            w,
            r#"<DataArray type="Float64" Name="{name}" format="ascii">"#
        )?;
        for v in data {
            write!(w, "{v:e} ")?;
        }
        writeln!(w, "\n</DataArray>")?;
    }
    writeln!(w, "</PointData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>")
}

fn write_int_array(
    w: &mut impl Write,
    name: &str,
    values: impl Iterator<Item = usize>,
) -> std::io::Result<()> {
    writeln!(
        w,
        r#"<DataArray type="Int64" Name="{name}" format="ascii">"#
    )?;
    for v in values {
        write!(w, "{v} ")?;
    }
    writeln!(w, "\n</DataArray>")
}

/// Write `value` as pretty JSON to `path`, whole (temporary name, rename).
pub fn write_json(path: &Path, value: &serde_json::Value) -> Result<(), OutputError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| OutputError::new(path, e))?;
    write_atomic(path, text).map_err(|e| OutputError::new(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Simple shear-free uniaxial stretch λ: εq = sqrt(⅔ Σ (e_i − ē)²) with e = (ln λ, 0, 0).
    #[test]
    fn hencky_deviatoric_strain_of_uniaxial_stretch() {
        let lambda: f64 = 1.3;
        let e = lambda.ln();
        let expected = (2.0 / 3.0 * ((2.0 * e / 3.0).powi(2) + 2.0 * (e / 3.0).powi(2))).sqrt();
        let got = deviatoric_hencky_strain(&[lambda, 0.0, 0.0, 1.0]);
        assert!((got - expected).abs() < 1e-14, "{got} vs {expected}");
        // a rigid rotation has no strain
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        assert!(deviatoric_hencky_strain(&[c, -s, s, c]).abs() < 1e-7);
    }
}
