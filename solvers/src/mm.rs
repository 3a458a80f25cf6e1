//! Linear systems in Matrix Market format (sprs's Matrix Market I/O): the tangent
//! `<stem>_K.mtx` (coordinate, general, every stored entry of the pattern, explicit zeros
//! too), the right-hand side `<stem>_rhs.mtx` and the solution `<stem>_x.mtx` (n × 1
//! coordinate), and a JSON description `<stem>.json` naming them. Values are written with
//! Rust's shortest round-trip formatting, so a system read back is bit-identical.

use std::path::{Path, PathBuf};

use sprs::{CsMatViewI, TriMatI};

use crate::{SolverError, SparseMatrix};

/// A system read back by [`read_system`].
#[derive(Debug, Clone)]
pub struct System {
    /// Name: the JSON file's stem.
    pub name: String,
    /// The matrix K.
    pub k: SparseMatrix,
    /// The right-hand side b.
    pub rhs: Vec<f64>,
    /// The solution written with it (`None` if there was none).
    pub x: Option<Vec<f64>>,
    /// The JSON description (scene, step, iteration, dof map, solver time, `symmetric`).
    pub meta: serde_json::Value,
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> SolverError {
    SolverError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Bytes the three `.mtx` files of an n × n system with `nnz` entries take, roughly (about
/// 40 bytes per matrix entry, 25 per vector entry).
pub fn estimated_bytes(n: usize, nnz: usize) -> usize {
    40 * nnz + 50 * n
}

fn write_matrix(path: &Path, k: &SparseMatrix) -> Result<(), SolverError> {
    let view = CsMatViewI::try_new_csc((k.n(), k.n()), k.col_ptr(), k.row_idx(), k.values())
        .map_err(|e| io_err(path, format!("{e:?}")))?;
    sprs::io::write_matrix_market(path, view).map_err(|e| io_err(path, e))
}

fn write_vector(path: &Path, v: &[f64]) -> Result<(), SolverError> {
    let n = v.len();
    let col_ptr = [0, n];
    let rows: Vec<usize> = (0..n).collect();
    let view = CsMatViewI::try_new_csc((n, 1), &col_ptr[..], &rows[..], v)
        .map_err(|e| io_err(path, format!("{e:?}")))?;
    sprs::io::write_matrix_market(path, view).map_err(|e| io_err(path, e))
}

fn read_triplets(path: &Path) -> Result<TriMatI<f64, usize>, SolverError> {
    sprs::io::read_matrix_market::<f64, usize, _>(path).map_err(|e| io_err(path, e))
}

fn read_vector(path: &Path) -> Result<Vec<f64>, SolverError> {
    let t = read_triplets(path)?;
    if t.cols() != 1 {
        return Err(io_err(
            path,
            format!("expected an n x 1 vector, found {} columns", t.cols()),
        ));
    }
    let mut v = vec![0.0; t.rows()];
    for (&val, (r, _)) in t.triplet_iter() {
        v[r] += val;
    }
    Ok(v)
}

/// Reads a square Matrix Market matrix (duplicates summed, explicit zeros kept in the pattern).
pub fn read_matrix(path: &Path) -> Result<SparseMatrix, SolverError> {
    let t = read_triplets(path)?;
    if t.rows() != t.cols() {
        return Err(io_err(
            path,
            format!("matrix is {} x {}, not square", t.rows(), t.cols()),
        ));
    }
    let triplets: Vec<(usize, usize, f64)> =
        t.triplet_iter().map(|(&v, (r, c))| (r, c, v)).collect();
    SparseMatrix::from_triplets(t.rows(), &triplets)
}

/// Writes `<dir>/<stem>_K.mtx`, `<stem>_rhs.mtx`, `<stem>_x.mtx` (if `x` is given) and
/// `<stem>.json`: `meta` with the keys `matrix`, `rhs`, `solution`, `n` and `nnz` added.
pub fn write_system(
    dir: &Path,
    stem: &str,
    k: &SparseMatrix,
    rhs: &[f64],
    x: Option<&[f64]>,
    meta: serde_json::Value,
) -> Result<PathBuf, SolverError> {
    std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
    let name = |suffix: &str| format!("{stem}_{suffix}.mtx");
    write_matrix(&dir.join(name("K")), k)?;
    write_vector(&dir.join(name("rhs")), rhs)?;
    if let Some(x) = x {
        write_vector(&dir.join(name("x")), x)?;
    }
    let mut meta = match meta {
        serde_json::Value::Object(m) => m,
        other => {
            let mut m = serde_json::Map::new();
            m.insert("meta".into(), other);
            m
        }
    };
    meta.insert("matrix".into(), name("K").into());
    meta.insert("rhs".into(), name("rhs").into());
    meta.insert(
        "solution".into(),
        x.map_or(serde_json::Value::Null, |_| name("x").into()),
    );
    meta.insert("n".into(), k.n().into());
    meta.insert("nnz".into(), k.nnz().into());
    let path = dir.join(format!("{stem}.json"));
    let text = serde_json::to_string_pretty(&serde_json::Value::Object(meta))
        .map_err(|e| io_err(&path, e))?;
    std::fs::write(&path, text).map_err(|e| io_err(&path, e))?;
    Ok(path)
}

/// Reads a system from its JSON description (written by [`write_system`]).
pub fn read_system(json: &Path) -> Result<System, SolverError> {
    let text = std::fs::read_to_string(json).map_err(|e| io_err(json, e))?;
    let meta: serde_json::Value = serde_json::from_str(&text).map_err(|e| io_err(json, e))?;
    let dir = json.parent().unwrap_or(Path::new("."));
    let file = |key: &str| -> Result<Option<PathBuf>, SolverError> {
        match meta.get(key) {
            Some(serde_json::Value::String(s)) => Ok(Some(dir.join(s))),
            Some(serde_json::Value::Null) | None => Ok(None),
            Some(_) => Err(io_err(json, format!("`{key}` is not a file name"))),
        }
    };
    let k_path = file("matrix")?.ok_or_else(|| io_err(json, "no `matrix` key"))?;
    let rhs_path = file("rhs")?.ok_or_else(|| io_err(json, "no `rhs` key"))?;
    let k = read_matrix(&k_path)?;
    let rhs = read_vector(&rhs_path)?;
    if rhs.len() != k.n() {
        return Err(io_err(
            &rhs_path,
            format!("length {} for a {} x {} matrix", rhs.len(), k.n(), k.n()),
        ));
    }
    let x = file("solution")?.map(|p| read_vector(&p)).transpose()?;
    let name = json
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    Ok(System {
        name,
        k,
        rhs,
        x,
        meta,
    })
}

/// The JSON descriptions of the systems in `dir` (files `*.json` with a `matrix` key), sorted
/// by name.
pub fn list_systems(dir: &Path) -> Result<Vec<PathBuf>, SolverError> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| io_err(dir, e))? {
        let path = entry.map_err(|e| io_err(dir, e))?.path();
        if path.extension().is_some_and(|e| e == "json") {
            let is_system = std::fs::read_to_string(&path)
                .ok()
                .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                .is_some_and(|v| v.get("matrix").is_some());
            if is_system {
                out.push(path);
            }
        }
    }
    out.sort();
    Ok(out)
}
