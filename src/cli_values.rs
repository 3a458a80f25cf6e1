//! Parsers of command-line values whose refusals say what is wanted in plain
//! words ("a whole number ≥ 1"), not in Rust's ("invalid digit found in
//! string", "0 is not in 1..18446744073709551615"). clap calls them through
//! `value_parser`; the CLI prints clap's refusal as `error[CLI_ARGUMENT]`.

/// A whole number ≥ `least`, described as "a whole number ≥ `least`".
fn whole_number_at_least(text: &str, least: u64) -> Result<u64, String> {
    match text.trim().parse::<u64>() {
        Ok(n) if n >= least => Ok(n),
        _ => Err(format!("`{text}` is not a whole number ≥ {least}")),
    }
}

/// A whole number ≥ 0 (a step number).
pub fn whole_number(text: &str) -> Result<usize, String> {
    whole_number_at_least(text, 0).map(|n| n as usize)
}

/// A whole number ≥ 1 as `usize` (a count: jobs, repeats, steps).
pub fn count(text: &str) -> Result<usize, String> {
    whole_number_at_least(text, 1).map(|n| n as usize)
}

/// A whole number ≥ 1 as `u64` (an interval or a limit in steps).
pub fn positive_u64(text: &str) -> Result<u64, String> {
    whole_number_at_least(text, 1)
}

/// A whole number ≥ 2 (a refinement factor).
pub fn factor(text: &str) -> Result<usize, String> {
    whole_number_at_least(text, 2).map(|n| n as usize)
}

/// A finite number (a strain, a pressure).
pub fn number(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("`{text}` is not a finite number")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_name_the_value_in_plain_words() {
        assert_eq!(count("3"), Ok(3));
        assert_eq!(count("0"), Err("`0` is not a whole number ≥ 1".into()));
        assert_eq!(count("abc"), Err("`abc` is not a whole number ≥ 1".into()));
        assert_eq!(whole_number("0"), Ok(0));
        assert_eq!(factor("1"), Err("`1` is not a whole number ≥ 2".into()));
        assert_eq!(
            positive_u64("-4"),
            Err("`-4` is not a whole number ≥ 1".into())
        );
        assert_eq!(number("1e3"), Ok(1000.0));
        assert_eq!(number("nan"), Err("`nan` is not a finite number".into()));
    }
}
