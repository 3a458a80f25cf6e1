//! Scene errors that point at the mistake (issue 41, item 11): where in the
//! file (line, column and the line itself, from the spans the toml crate
//! reports), in plain words instead of Rust types ("a whole number ≥ 1",
//! not "expected usize"), with a "did you mean …" for a misspelt key or
//! value.
//!
//! serde and toml report a wrong scene as a message of a few fixed forms
//! (`unknown field `x`, expected one of …`, `invalid type: …, expected …`,
//! `missing field `x``); [`explain`] rewrites those forms and leaves any
//! other message as it is.

use std::fmt;
use std::ops::Range;

/// A position in a scene file, with its line for display.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// Line, from 1.
    pub line: usize,
    /// Column (characters), from 1.
    pub column: usize,
    /// The whole line as written.
    pub source_line: String,
    /// Characters to underline from `column` (at least 1).
    pub width: usize,
}

impl Location {
    /// The position of the byte range `span` of `text` (its start; the
    /// underline stops at the end of the line).
    pub fn of(text: &str, span: Range<usize>) -> Location {
        let start = floor_char_boundary(text, span.start.min(text.len()));
        let end = floor_char_boundary(text, span.end.clamp(start, text.len()));
        let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
        let line_end = text[start..].find('\n').map_or(text.len(), |i| start + i);
        let source_line = text[line_start..line_end].trim_end_matches('\r');
        let column = text[line_start..start].chars().count() + 1;
        let width = text[start..end.min(line_end)].chars().count().max(1);
        Location {
            line: text[..start].matches('\n').count() + 1,
            column,
            source_line: source_line.to_string(),
            width,
        }
    }
}

/// The largest char boundary of `text` at or below `index`.
fn floor_char_boundary(text: &str, index: usize) -> usize {
    (0..=index)
        .rev()
        .find(|&i| text.is_char_boundary(i))
        .unwrap_or(0)
}

impl fmt::Display for Location {
    /// The line with its number and a caret line under the mistake:
    /// `  11 | cel_size = 0.1` / `     | ^^^^^^^^`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let number = self.line.to_string();
        let gutter = " ".repeat(number.len());
        let indent: String = self
            .source_line
            .chars()
            .take(self.column - 1)
            .map(|c| if c == '\t' { '\t' } else { ' ' })
            .collect();
        write!(
            f,
            "{number} | {}\n{gutter} | {indent}{}",
            self.source_line,
            "^".repeat(self.width)
        )
    }
}

/// Where in `text` the deserialisation `error` lies (`raw` its message,
/// `keys` the key path [`explain`] gave it): toml's span of the same error
/// read from the text itself, narrowed to the key or value inside a model's
/// parameter table, whose errors carry the span of the whole table.
pub fn locate(
    text: &str,
    error: &toml::de::Error,
    raw: &str,
    keys: Option<&str>,
) -> Option<Location> {
    let segments: Vec<&str> = keys.map_or(Vec::new(), |k| k.split('.').collect());
    let spanned = toml::from_str::<super::Scene>(text)
        .err()
        .filter(|e| e.message() == error.message())
        .and_then(|e| e.span());
    // toml reads some values from the text that it refuses in a table (an
    // array too long for its type): then the value at the key path
    let mut span = spanned.or_else(|| entry_span(text, &segments, false))?;
    if let Some(path) = keys.filter(|k| k.starts_with("materials.")) {
        let mut segments: Vec<&str> = path.split('.').collect();
        let message = raw
            .strip_prefix(INNER_KEY)
            .and_then(|rest| rest.split_once("`: "))
            .map_or(raw, |(_, rest)| rest);
        let unknown = name_after(message, "unknown field `").map(|(name, _)| name);
        segments.extend(unknown);
        span = entry_span(text, &segments, unknown.is_some()).unwrap_or(span);
    }
    Some(Location::of(text, span))
}

/// The span of the key (`want_key`) or of the value at the table path
/// `segments` of the TOML `text` (`None` if it is not there).
fn entry_span(text: &str, segments: &[&str], want_key: bool) -> Option<Range<usize>> {
    let document = toml::de::DeTable::parse(text).ok()?;
    let (last, parents) = segments.split_last()?;
    let mut table = document.get_ref();
    for segment in parents {
        let (_, value) = table.iter().find(|(k, _)| k.get_ref() == segment)?;
        table = value.get_ref().as_table()?;
    }
    let (key, value) = table.iter().find(|(k, _)| k.get_ref() == last)?;
    Some(if want_key { key.span() } else { value.span() })
}

/// The message and the dotted key path (`scene.steps`; arrays have no
/// index) of an error of deserialising a `toml::Value`: toml prints the
/// path as a last line `in `a.b`` (and keeps it private otherwise).
pub fn message_and_keys(error: &toml::de::Error) -> (String, Option<String>) {
    let shown = error.to_string();
    let shown = shown.trim_end();
    if let Some((message, last)) = shown.rsplit_once('\n') {
        if let Some(keys) = last.strip_prefix("in `").and_then(|k| k.strip_suffix('`')) {
            return (message.trim_end().to_string(), Some(keys.to_string()));
        }
    }
    (error.message().trim_end().to_string(), None)
}

/// Where a message of a model's parameter table starts its own key path
/// (`in `E`: …`, written by [`crate::scene::MaterialSpec`]'s reader).
const INNER_KEY: &str = "in `";

/// `message` with an inner key path `inner` prefixed (see [`explain`]).
pub fn with_inner_key(message: &str, inner: Option<&str>) -> String {
    match inner {
        Some(key) => format!("{INNER_KEY}{key}`: {message}"),
        None => message.to_string(),
    }
}

/// A deserialisation message in plain words, given the dotted key path it
/// belongs to (the table for an unknown or missing key, the value for a
/// wrong type): the explained message and the full key path.
pub fn explain(message: &str, keys: Option<&str>) -> (String, Option<String>) {
    let (message, keys) = split_inner_key(message, keys);
    let (message, context) = match message.rfind(" (model `") {
        Some(i) if message.ends_with(')') => (&message[..i], &message[i..]),
        _ => (message, ""),
    };
    let path = keys.as_deref();
    let explained = unknown_key(message, path)
        .or_else(|| unknown_value(message, path))
        .or_else(|| missing_key(message, path))
        .or_else(|| wrong_type(message, path))
        .unwrap_or_else(|| match path {
            Some(p) => format!("`{p}`: {message}"),
            None => message.to_string(),
        });
    (format!("{explained}{context}"), keys)
}

/// An error of deserialising a `toml::Value` (a parameter table, say) in
/// plain words, naming its key: `message_and_keys` then `explain`.
pub fn plain_toml_error(error: &toml::de::Error) -> String {
    let (message, keys) = message_and_keys(error);
    explain(&message, keys.as_deref()).0
}

/// Split a leading `in `k`: ` (a model's own key path) off `message` and
/// append it to `keys`.
fn split_inner_key<'m>(message: &'m str, keys: Option<&str>) -> (&'m str, Option<String>) {
    let inner = message
        .strip_prefix(INNER_KEY)
        .and_then(|rest| rest.split_once("`: "));
    match (inner, keys) {
        (Some((key, rest)), Some(outer)) => (rest, Some(format!("{outer}.{key}"))),
        (Some((key, rest)), None) => (rest, Some(key.to_string())),
        (None, keys) => (message, keys.map(str::to_string)),
    }
}

/// `in `grid`` for a key path, nothing at the top level.
fn within(path: Option<&str>) -> String {
    match path {
        Some(p) if !p.is_empty() => format!(" in `{p}`"),
        _ => String::new(),
    }
}

/// The names between backticks of `text` (`a`, `b` or `c`).
fn quoted_names(text: &str) -> Vec<&str> {
    text.split('`').skip(1).step_by(2).collect()
}

/// The first backticked name after `prefix` at the start of `message`, and
/// the rest after it.
fn name_after<'m>(message: &'m str, prefix: &str) -> Option<(&'m str, &'m str)> {
    let rest = message.strip_prefix(prefix)?;
    let end = rest.find('`')?;
    Some((&rest[..end], &rest[end + 1..]))
}

/// `unknown field `x`, expected one of …` → `unknown key `x` in `t`; did you
/// mean `y`?` (or the list of the table's keys when none is close).
fn unknown_key(message: &str, path: Option<&str>) -> Option<String> {
    let (name, rest) = name_after(message, "unknown field `")?;
    let allowed = quoted_names(rest);
    let hint = match suggestion(name, &allowed) {
        Some(close) => format!("; did you mean `{close}`?"),
        None if allowed.is_empty() => " (this table takes no keys)".to_string(),
        None => format!(" (the keys here: {})", allowed_keys(&allowed)),
    };
    Some(format!("unknown key `{name}`{}{hint}", within(path)))
}

/// `unknown variant `x`, expected …` → `unknown value `x` for `k`; did you
/// mean `y`?` (or the allowed values when none is close).
fn unknown_value(message: &str, path: Option<&str>) -> Option<String> {
    let (name, rest) = name_after(message, "unknown variant `")?;
    let allowed = quoted_names(rest);
    let subject = match path {
        Some(p) => format!("unknown value `{name}` for `{p}`"),
        None => format!("unknown value `{name}`"),
    };
    Some(match suggestion(name, &allowed) {
        Some(close) => format!(
            "{subject}; did you mean `{close}`? (one of {})",
            list(&allowed)
        ),
        None if allowed.len() > 2 => format!("{subject}: expected one of {}", list(&allowed)),
        None => format!("{subject}: expected {}", list(&allowed)),
    })
}

/// `missing field `x`` → `missing key `x` in `t``.
fn missing_key(message: &str, path: Option<&str>) -> Option<String> {
    let (name, _) = name_after(message, "missing field `")?;
    Some(format!("missing key `{name}`{}", within(path)))
}

/// `invalid type: integer `1`, expected a string`, `invalid value: …`,
/// `invalid length 3, expected …` → `` `k` must be <plain>, not <found>``.
fn wrong_type(message: &str, path: Option<&str>) -> Option<String> {
    let (found, expected) = if let Some(rest) = message
        .strip_prefix("invalid type: ")
        .or_else(|| message.strip_prefix("invalid value: "))
    {
        let (found, expected) = rest.rsplit_once(", expected ")?;
        (found_in_words(found), expected)
    } else {
        let rest = message.strip_prefix("invalid length ")?;
        let (count, expected) = rest.split_once(", expected ")?;
        let noun = if count == "1" { "value" } else { "values" };
        (format!("{count} {noun}"), expected)
    };
    let expected = expected_in_words(expected, path);
    Some(match path {
        Some(p) => format!("`{p}` must be {expected}, not {found}"),
        None => format!("expected {expected}, found {found}"),
    })
}

/// serde's description of a value found (`floating point `2.5``,
/// `string "a"`, `sequence`) in plain words.
fn found_in_words(found: &str) -> String {
    let quoted = || found.split('`').nth(1).unwrap_or(found).to_string();
    if ["floating point", "integer", "boolean"]
        .iter()
        .any(|kind| found.starts_with(kind))
    {
        quoted()
    } else if let Some(text) = found.strip_prefix("string ") {
        format!("the string {text}")
    } else if found.starts_with("sequence") {
        "an array".to_string()
    } else if found.starts_with("map") {
        "a table".to_string()
    } else {
        found.to_string()
    }
}

/// Whole-number keys whose allowed range is narrower than "≥ 0" (the dotted
/// paths toml reports: arrays without an index).
const WHOLE_NUMBER_RANGES: &[(&str, &str)] = &[
    ("scene.steps", "a whole number ≥ 1"),
    ("grid.points_per_cell", "a whole number from 1 to 4"),
    ("solver.max_iterations", "a whole number ≥ 1"),
    ("solver.max_halvings", "a whole number from 0 to 10"),
    ("solver.pcg_max_iterations", "a whole number ≥ 1"),
    ("limits.max_steps", "a whole number ≥ 1"),
    ("output.snapshots", "a step number (a whole number ≥ 0)"),
    ("output.systems", "a step number (a whole number ≥ 0)"),
    (
        "bc.pressure.edges",
        "an edge number (a whole number ≥ 0, edge k joins vertex k to k + 1)",
    ),
];

/// serde's name of the type expected (`usize`, `f64`, `a sequence`,
/// `struct GridSpec`) in plain words; whole numbers with the key's range.
fn expected_in_words(expected: &str, path: Option<&str>) -> String {
    let whole = |generic: &str| {
        path.and_then(|p| WHOLE_NUMBER_RANGES.iter().find(|(k, _)| *k == p))
            .map_or(generic.to_string(), |(_, words)| words.to_string())
    };
    match expected.trim() {
        "usize" | "u64" | "u32" | "u16" | "u8" => whole("a whole number ≥ 0"),
        "isize" | "i64" | "i32" | "i16" | "i8" => "a whole number".to_string(),
        "f64" | "f32" => "a number".to_string(),
        "a boolean" | "bool" => "true or false".to_string(),
        "a string" | "a borrowed string" | "a character" | "char" => {
            "a string in quotes".to_string()
        }
        "a sequence" => "an array `[…]`".to_string(),
        "a map" => "a table".to_string(),
        other if other.starts_with("struct ") => "a table".to_string(),
        "fewer elements in array" => "an array with fewer values".to_string(),
        other if other.starts_with("an array of length ") => {
            format!(
                "an array of {} values",
                &other["an array of length ".len()..]
            )
        }
        other if other.starts_with("enum ") || other.ends_with("identifier") => {
            "a name in quotes".to_string()
        }
        other => other.to_string(),
    }
}

/// `a`, `b`, `c` for messages.
fn allowed_keys(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
    quoted.join(", ")
}

/// `a`, `b` or `c` for messages.
fn list(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
    match quoted.split_last() {
        None => String::new(),
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
    }
}

/// The candidate closest to `word`, when it is close enough to be a typo:
/// at most a third of its length (at least 1) of single-letter edits or
/// swaps, ignoring case, and fewer edits than the word has letters.
pub fn suggestion<'c>(word: &str, candidates: &[&'c str]) -> Option<&'c str> {
    let word_lower = word.to_lowercase();
    let (best, distance) = candidates
        .iter()
        .map(|c| (*c, edit_distance(&word_lower, &c.to_lowercase())))
        .min_by_key(|(_, d)| *d)?;
    let length = word.chars().count().max(best.chars().count());
    let allowed = (length / 3).max(1);
    (distance <= allowed && distance < word.chars().count()).then_some(best)
}

/// Optimal string alignment distance: insertions, deletions, substitutions
/// and swaps of two neighbouring letters, each counting 1.
fn edit_distance(a: &str, b: &str) -> usize {
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().collect(), b.chars().collect());
    let mut d = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for (i, row) in d.iter_mut().enumerate() {
        row[0] = i;
    }
    for j in 0..=b.len() {
        d[0][j] = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut best = (d[i - 1][j] + 1)
                .min(d[i][j - 1] + 1)
                .min(d[i - 1][j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                best = best.min(d[i - 2][j - 2] + 1);
            }
            d[i][j] = best;
        }
    }
    d[a.len()][b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn typos_get_the_closest_key_and_unrelated_words_none() {
        let keys = ["origin", "size", "cell_size", "points_per_cell"];
        assert_eq!(suggestion("cel_size", &keys), Some("cell_size"));
        assert_eq!(suggestion("CELL_SIZE", &keys), Some("cell_size"));
        assert_eq!(suggestion("orgin", &keys), Some("origin"));
        assert_eq!(suggestion("gird", &["grid", "scene"]), Some("grid"));
        assert_eq!(suggestion("temperature", &keys), None);
        assert_eq!(suggestion("z", &["x", "y"]), None);
    }

    #[test]
    fn rust_types_become_plain_words() {
        let (m, _) = explain(
            "invalid type: floating point `2.5`, expected usize",
            Some("scene.steps"),
        );
        assert_eq!(m, "`scene.steps` must be a whole number ≥ 1, not 2.5");
        let (m, _) = explain(
            "invalid value: integer `-1`, expected usize",
            Some("output.curve_every"),
        );
        assert_eq!(m, "`output.curve_every` must be a whole number ≥ 0, not -1");
        let (m, _) = explain(
            "invalid type: string \"a\", expected f64",
            Some("grid.cell_size"),
        );
        assert_eq!(m, "`grid.cell_size` must be a number, not the string \"a\"");
        let (m, keys) = explain(
            "in `nu`: invalid type: boolean `true`, expected f64 (model `linear_elastic`)",
            Some("materials.soil"),
        );
        assert_eq!(
            m,
            "`materials.soil.nu` must be a number, not true (model `linear_elastic`)"
        );
        assert_eq!(keys.as_deref(), Some("materials.soil.nu"));
    }

    #[test]
    fn unknown_names_are_explained_with_a_suggestion() {
        let (m, _) = explain(
            "unknown variant `quasistatic`, expected one of `quasi_static`, `implicit_dynamic`, `explicit`",
            Some("scene.analysis"),
        );
        assert!(
            m.starts_with(
                "unknown value `quasistatic` for `scene.analysis`; did you mean `quasi_static`?"
            ),
            "{m}"
        );
        let (m, _) = explain(
            "unknown field `temperature`, expected `E` or `nu`",
            Some("materials.soil"),
        );
        assert_eq!(
            m,
            "unknown key `temperature` in `materials.soil` (the keys here: `E`, `nu`)"
        );
        let (m, _) = explain("missing field `cell_size`", Some("grid"));
        assert_eq!(m, "missing key `cell_size` in `grid`");
    }

    #[test]
    fn locations_count_lines_and_characters() {
        let text = "[grid]\nsize = [1.0, 2.0]\ncél_size = 0.1\n";
        let at = text.find("0.1").unwrap();
        let location = Location::of(text, at..at + 3);
        assert_eq!((location.line, location.column, location.width), (3, 12, 3));
        assert_eq!(
            location.to_string(),
            "3 | cél_size = 0.1\n  |            ^^^"
        );
    }
}
