//! Errors in the command line's own words: each command's table from the
//! request's field paths (`sources[0].point`, `seeds`, `cost.dataset`) to
//! the flags that gave them (`--source 1`, `--seed`, `--cost`), applied in
//! one place ([`crate::cli::run`]) to every refused request.
//!
//! A table is a list of rules, tried in order; the first whose field is the
//! error's field or a prefix of it (up to a `.` or `[`) names the flag.
//! Unmatched fields fall back to `--` and the field's first name with `_` as
//! `-` (`max_distance` → `--max-distance`), the usual spelling of a flag.
//! The reason is rewritten too: every field the table knows, quoted
//! (`` `seed_image` ``) or indexed (`sources[2]`), becomes its flag, so that
//! no message points a command-line user at a JSON field.

use std::ops::Range;

use crate::ops::OpError;

/// How a field's index shows in the flag's name.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Name {
    /// The flag alone (`--phi`).
    Plain(String),
    /// The occurrence of a repeatable flag, 1-based (`--source 2`).
    Occurrence(String),
    /// The value of a list flag, 1-based (`--spacing value 2`).
    Value(String),
    /// The row of an array file, 0-based (`--targets (row 3)`).
    Row(String),
}

/// One rule of a [`FlagMap`].
#[derive(Debug, Clone)]
struct Rule {
    /// The field path (`sources`, `cost.design`).
    field: String,
    /// For indexed rules, the indices it covers (`field[k]`, `k` in range).
    range: Option<Range<usize>>,
    /// The flag.
    name: Name,
}

/// A command's table from request fields to its flags.
#[derive(Debug, Clone, Default)]
pub(crate) struct FlagMap {
    rules: Vec<Rule>,
}

/// A command-line error, naming the flag at fault: the one error of every
/// grid command (`DistanceError` and `SegmentCliError` are its older names).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CliError {
    /// A flag's value, or what it gave, is refused.
    #[error("{flag}: {reason}")]
    Flag {
        /// The flag, with its occurrence for repeatable ones (`--source 2`).
        flag: String,
        /// Why.
        reason: String,
    },
    /// The run was cancelled.
    #[error("cancelled")]
    Cancelled,
    /// Anything else (the pool could not start, the solve panicked).
    #[error("{0}")]
    Other(String),
}

impl From<super::output::OutputError> for CliError {
    fn from(e: super::output::OutputError) -> Self {
        CliError::Flag {
            flag: e.flag().to_string(),
            reason: e.reason(),
        }
    }
}

impl CliError {
    /// A refused flag.
    pub(crate) fn flag(flag: impl Into<String>, reason: impl Into<String>) -> Self {
        CliError::Flag {
            flag: flag.into(),
            reason: reason.into(),
        }
    }
}

/// What follows `pattern` at the start of `path`; `[]` in the pattern
/// stands for any index (`targets[].observed` matches `targets[3].observed`).
fn after<'a>(path: &'a str, pattern: &str) -> Option<&'a str> {
    let mut rest = path;
    let mut parts = pattern.split("[]").peekable();
    while let Some(part) = parts.next() {
        rest = rest.strip_prefix(part)?;
        if parts.peek().is_some() {
            let inner = rest.strip_prefix('[')?;
            let close = inner.find(']')?;
            inner[..close].parse::<usize>().ok()?;
            rest = &inner[close + 1..];
        }
    }
    Some(rest)
}

/// `field` or a path below it (`field.x`, `field[0]`).
fn under(path: &str, field: &str) -> bool {
    after(path, field).is_some_and(|rest| rest.is_empty() || rest.starts_with(['.', '[']))
}

/// The index of `field[k]...`.
fn index_of(path: &str, field: &str) -> Option<usize> {
    let rest = after(path, field)?.strip_prefix('[')?;
    rest[..rest.find(']')?].parse().ok()
}

impl FlagMap {
    /// An empty table: every field falls back to `--field-name`.
    pub(crate) fn new() -> Self {
        Self::default()
    }

    fn push(mut self, field: &str, range: Option<Range<usize>>, name: Name) -> Self {
        self.rules.push(Rule {
            field: field.into(),
            range,
            name,
        });
        self
    }

    /// `field` and everything below it → `flag`.
    pub(crate) fn field(self, field: &str, flag: &str) -> Self {
        self.push(field, None, Name::Plain(flag.into()))
    }

    /// `field[k]` → `flag k+1` (a repeatable flag), and `field` → `flag`.
    pub(crate) fn each(self, field: &str, flag: &str) -> Self {
        self.each_in(field, flag, 0..usize::MAX).field(field, flag)
    }

    /// `field[k]` for `k` in `range` → `flag k-start+1`: the occurrences of
    /// a flag that gave those entries of the list.
    pub(crate) fn each_in(self, field: &str, flag: &str, range: Range<usize>) -> Self {
        self.push(field, Some(range), Name::Occurrence(flag.into()))
    }

    /// `field[k]` for `k` in `range` → `flag` alone (one file that gave
    /// those entries, e.g. `--phi`).
    pub(crate) fn all_in(self, field: &str, flag: &str, range: Range<usize>) -> Self {
        self.push(field, Some(range), Name::Plain(flag.into()))
    }

    /// `field[k]` → `flag value k+1` (a comma-separated list), and `field` → `flag`.
    pub(crate) fn values(self, field: &str, flag: &str) -> Self {
        self.push(field, Some(0..usize::MAX), Name::Value(flag.into()))
            .field(field, flag)
    }

    /// `field[k]` for `k >= start` → `flag (row k-start)`: the rows of an array file.
    pub(crate) fn rows_from(self, field: &str, flag: &str, start: usize) -> Self {
        self.push(field, Some(start..usize::MAX), Name::Row(flag.into()))
    }

    /// The rules of a `cost` section and what goes with it: `--design`,
    /// `--speed`, `--shape` (its values), the metric flag `cost_flag`
    /// (`--cost`, or whichever flag gave the cost), `--tensor`,
    /// `--spacing` (its values) and `--obstacles`.
    pub(crate) fn metric(self, cost_flag: &str) -> Self {
        let map = self
            .field("cost.design", "--design")
            .field("cost.interpretation", "--speed");
        let map = if cost_flag == "--shape" {
            map.values("cost.shape", "--shape")
        } else {
            map
        };
        map.field("cost", cost_flag)
            .field("metric", "--tensor")
            .values("spacing", "--spacing")
            .field("obstacles", "--obstacles")
    }

    /// The flag that gave `path`; `None` when no rule matches.
    fn lookup(&self, path: &str) -> Option<String> {
        self.rules.iter().find_map(|rule| {
            let k = match &rule.range {
                Some(range) => Some(index_of(path, &rule.field).filter(|k| range.contains(k))?),
                None if under(path, &rule.field) => None,
                None => return None,
            };
            let start = rule.range.as_ref().map_or(0, |r| r.start);
            let k = k.map_or(0, |k| k - start);
            Some(match &rule.name {
                Name::Plain(f) => f.clone(),
                Name::Occurrence(f) => format!("{f} {}", k + 1),
                Name::Value(f) => format!("{f} value {}", k + 1),
                Name::Row(f) => format!("{f} (row {k})"),
            })
        })
    }

    /// The flag that gave the field `path` (see the module docs).
    pub(crate) fn flag_of(&self, path: &str) -> String {
        if path.is_empty() {
            return "geodex".into();
        }
        self.lookup(path).unwrap_or_else(|| {
            let root = path.split(['.', '[']).next().unwrap_or(path);
            format!("--{}", root.replace('_', "-"))
        })
    }

    /// `reason` with the fields it names replaced by their flags: quoted
    /// paths (`` `seed_image` ``) the table knows, and indexed ones
    /// (`sources[2]`) of its indexed rules.
    pub(crate) fn reword(&self, reason: &str) -> String {
        let mut out = String::with_capacity(reason.len());
        let mut rest = reason;
        // Quoted paths.
        while let Some(open) = rest.find('`') {
            let Some(len) = rest[open + 1..].find('`') else {
                break;
            };
            let inner = &rest[open + 1..open + 1 + len];
            out.push_str(&rest[..open]);
            match self.lookup(inner) {
                Some(flag) => out.push_str(&format!("`{flag}`")),
                None => out.push_str(&rest[open..open + len + 2]),
            }
            rest = &rest[open + len + 2..];
        }
        out.push_str(rest);
        // Bare indexed paths (`sources[2]`, `sources[2].point`).
        for rule in self.rules.iter().filter(|r| r.range.is_some()) {
            let needle = format!("{}[", rule.field);
            let mut from = 0;
            while let Some(at) = out[from..].find(&needle).map(|i| i + from) {
                let preceded = out[..at]
                    .chars()
                    .next_back()
                    .is_some_and(|c| c.is_alphanumeric() || c == '_' || c == '.' || c == '-');
                let end = out[at..]
                    .find(|c: char| !(c.is_alphanumeric() || "_.[]".contains(c)))
                    .map_or(out.len(), |i| at + i);
                let path = out[at..end].trim_end_matches('.').to_string();
                match (preceded, self.lookup(&path)) {
                    (false, Some(flag)) => {
                        out.replace_range(at..at + path.len(), &flag);
                        from = at + flag.len();
                    }
                    _ => from = at + needle.len(),
                }
            }
        }
        out
    }

    /// An operation's error in the command's terms.
    pub(crate) fn error(&self, e: OpError) -> CliError {
        match e {
            OpError::Cancelled => CliError::Cancelled,
            OpError::UnknownDataset { field, id } => {
                CliError::flag(self.flag_of(&field), format!("dataset '{id}' not found"))
            }
            OpError::Invalid { field, reason } | OpError::TooLarge { field, reason } => {
                CliError::flag(self.flag_of(&field), self.reword(&reason))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn distance_map(points: usize) -> FlagMap {
        FlagMap::new()
            .each_in("sources", "--source", 0..points)
            .all_in("sources", "--phi", points..usize::MAX)
            .field("sources", "--source")
            .each("stop.targets", "--target")
            .field("stop.max_distance", "--max-distance")
            .metric("--cost")
    }

    #[test]
    fn fields_map_to_the_flags_that_gave_them() {
        let m = distance_map(2);
        assert_eq!(m.flag_of("sources[0]"), "--source 1");
        assert_eq!(m.flag_of("sources[1].point[0]"), "--source 2");
        assert_eq!(m.flag_of("sources[2].level_set"), "--phi");
        assert_eq!(m.flag_of("sources"), "--source");
        assert_eq!(m.flag_of("stop.targets[2]"), "--target 3");
        assert_eq!(m.flag_of("cost.dataset"), "--cost");
        assert_eq!(m.flag_of("cost.design.scales[0]"), "--design");
        assert_eq!(m.flag_of("cost.interpretation"), "--speed");
        assert_eq!(m.flag_of("spacing[1]"), "--spacing value 2");
        assert_eq!(m.flag_of("spacing"), "--spacing");
        assert_eq!(m.flag_of("metric.dataset"), "--tensor");
        assert_eq!(m.flag_of("stop.max_distance"), "--max-distance");
        assert_eq!(
            m.flag_of("min_boundary_fraction"),
            "--min-boundary-fraction"
        );
        assert_eq!(m.flag_of("costs"), "--costs");
        assert_eq!(m.flag_of(""), "geodex");
        let shape = FlagMap::new().metric("--shape");
        assert_eq!(shape.flag_of("cost.shape[1]"), "--shape value 2");
        assert_eq!(shape.flag_of("cost.constant"), "--shape");
        let rows = FlagMap::new()
            .field("targets[].observed", "--observed")
            .each_in("targets", "--target", 0..2)
            .rows_from("targets", "--targets", 2);
        assert_eq!(rows.flag_of("targets[1].point"), "--target 2");
        assert_eq!(rows.flag_of("targets[5].point"), "--targets (row 3)");
        assert_eq!(rows.flag_of("targets[5].observed"), "--observed");
        assert_eq!(rows.flag_of("targets[x].observed"), "--targets");
    }

    #[test]
    fn reasons_name_flags_instead_of_fields() {
        let m = FlagMap::new()
            .each("seeds", "--seed")
            .field("seed_image", "--seed-image");
        assert_eq!(
            m.reword("give labelled `seeds`, a `seed_image`, or both"),
            "give labelled `--seed`, a `--seed-image`, or both"
        );
        assert_eq!(
            m.reword("give exactly one of `point` or a non-empty `cells`"),
            "give exactly one of `point` or a non-empty `cells`"
        );
        let d = distance_map(3);
        assert_eq!(
            d.reword("a `level_set` source (sources[1]) must be the only source"),
            "a `level_set` source (--source 2) must be the only source"
        );
        assert_eq!(
            d.reword("sources[0].point and sources[2] coincide; see my_sources[1]."),
            "--source 1 and --source 3 coincide; see my_sources[1]."
        );
        assert_eq!(d.reword("unbalanced ` quote"), "unbalanced ` quote");
        assert_eq!(
            d.reword("a design needs the image in `cost.dataset`"),
            "a design needs the image in `--cost`"
        );
    }

    #[test]
    fn errors_carry_the_flag_and_the_reworded_reason() {
        let m = FlagMap::new()
            .each("seeds", "--seed")
            .field("seed_image", "--seed-image");
        let e = m.error(OpError::invalid(
            "seeds",
            "give labelled `seeds`, a `seed_image`, or both",
        ));
        assert_eq!(
            e.to_string(),
            "--seed: give labelled `--seed`, a `--seed-image`, or both"
        );
        assert_eq!(m.error(OpError::Cancelled), CliError::Cancelled);
    }
}
