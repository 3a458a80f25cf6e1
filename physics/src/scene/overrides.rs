//! `--set key.path=value` overrides, applied to the TOML table of a scene
//! before it is parsed.

use super::SceneError;

/// Apply one `a.b.c=value` override to a TOML table. Path segments that are
/// numbers index arrays (`body.0.box`). The value is parsed as TOML (numbers,
/// booleans, arrays, strings in quotes) and taken as a bare string otherwise.
/// An empty value (`a.b.c=`) removes the key, so that its default applies
/// (e.g. `solver.newmark_gamma=` before `solver.rho_infinity=0.8`).
pub fn apply_override(table: &mut toml::Table, assignment: &str) -> Result<(), SceneError> {
    let err = |message: String| SceneError::Override {
        assignment: assignment.to_string(),
        message,
    };
    let (path, raw) = assignment
        .split_once('=')
        .ok_or_else(|| err("expected KEY=VALUE".into()))?;
    let keys: Vec<&str> = path.trim().split('.').collect();
    if keys.iter().any(|k| k.is_empty()) {
        return Err(err("empty key segment".into()));
    }
    let raw = raw.trim();
    if raw.is_empty() {
        return remove_key(table, &keys).map_err(err);
    }
    let value: toml::Value = format!("v = {raw}")
        .parse::<toml::Table>()
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(raw.to_string()));
    if keys.len() == 1 {
        table.insert(keys[0].to_string(), value);
        return Ok(());
    }
    // Missing intermediate tables are created (optional sections such as
    // `[solver]`); a misspelt key is then refused by `deny_unknown_fields`.
    let mut current: &mut toml::Value = table
        .entry(keys[0])
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    for (depth, key) in keys.iter().enumerate().skip(1) {
        let last = depth == keys.len() - 1;
        current = match current {
            toml::Value::Table(t) => {
                if last {
                    t.insert((*key).to_string(), value);
                    return Ok(());
                }
                t.entry(*key)
                    .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            }
            toml::Value::Array(a) => {
                let index: usize = key
                    .parse()
                    .map_err(|_| err(format!("`{key}` must be an array index")))?;
                let len = a.len();
                let slot = a
                    .get_mut(index)
                    .ok_or_else(|| err(format!("index {index} out of range (length {len})")))?;
                if last {
                    *slot = value;
                    return Ok(());
                }
                slot
            }
            _ => {
                return Err(err(format!(
                    "`{}` is not a table or array",
                    keys[..depth].join(".")
                )))
            }
        };
    }
    Ok(())
}

/// Remove the key at the path `keys` (tables and array indices on the way);
/// a key that is not there is already removed.
fn remove_key(table: &mut toml::Table, keys: &[&str]) -> Result<(), String> {
    match keys {
        [last] => {
            table.remove(*last);
            Ok(())
        }
        [first, rest @ ..] => match table.get_mut(*first) {
            Some(value) => remove_in(value, rest, first),
            None => Ok(()),
        },
        [] => Err("empty key".into()),
    }
}

/// [`remove_key`] below `value`, the value at the path `above`.
fn remove_in(value: &mut toml::Value, keys: &[&str], above: &str) -> Result<(), String> {
    match value {
        toml::Value::Table(table) => remove_key(table, keys),
        toml::Value::Array(items) if keys.len() > 1 => {
            let index: usize = keys[0]
                .parse()
                .map_err(|_| format!("`{}` must be an array index", keys[0]))?;
            let len = items.len();
            let item = items
                .get_mut(index)
                .ok_or_else(|| format!("index {index} out of range (length {len})"))?;
            remove_in(item, &keys[1..], keys[0])
        }
        toml::Value::Array(_) => Err("an array element cannot be removed, only a key".into()),
        _ => Err(format!("`{above}` is not a table or array")),
    }
}
