//! `--design`, shared by every command that reads a cost: the cost `W` is
//! designed from the image given as the cost (the `design` section of the
//! request's `cost`, [`DesignSpec`]).
//!
//! The value is the JSON of the section, or its short form
//! `KIND[:KEY=VALUE,...]`, where a value is a number, a word, or numbers
//! separated by `;` (a list):
//!
//! ```text
//! --design edges
//! --design 'vesselness:scales=1;2,polarity=dark'
//! --design 'intensity:at=10;20,power=2'
//! --design '{"kind": "edges", "mode": "barrier"}'
//! ```

use serde_json::{Map, Value};

use super::flags::CliError;
use crate::ops::spec::design::DesignSpec;

/// `--design`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct DesignFlag {
    /// Design the cost W from the image given as the cost: `edges`,
    /// `intensity`, `vesselness`, with parameters as
    /// `KIND:KEY=VALUE,...` (lists with `;`, e.g.
    /// 'vesselness:scales=1;2,polarity=dark') or the JSON of a design
    /// section ('{"kind": "edges", "mode": "barrier"}').
    #[arg(long, value_name = "DESIGN")]
    pub design: Option<String>,
}

impl DesignFlag {
    /// The design section, if `--design` was given; `image` says whether
    /// the command has an image to design from (its cost file).
    ///
    /// # Errors
    ///
    /// A [`CliError`] naming `--design` for a value that parses as no
    /// design, or `image_flag` when there is no image.
    pub(crate) fn spec(
        &self,
        image: bool,
        image_flag: &str,
    ) -> Result<Option<DesignSpec>, CliError> {
        let Some(text) = &self.design else {
            return Ok(None);
        };
        if !image {
            return Err(CliError::flag(
                "--design",
                format!("needs the image to design from in {image_flag}"),
            ));
        }
        parse_design(text).map(Some)
    }
}

/// Parses the JSON or the short form of a design section.
///
/// # Errors
///
/// A [`CliError`] naming `--design`.
pub(crate) fn parse_design(text: &str) -> Result<DesignSpec, CliError> {
    let text = text.trim();
    let value = if text.starts_with('{') {
        serde_json::from_str(text)
            .map_err(|e| CliError::flag("--design", format!("not a design section: {e}")))?
    } else {
        short_form(text)?
    };
    serde_json::from_value(value).map_err(|e| {
        CliError::flag(
            "--design",
            format!("'{text}' is not a design: {e} (kinds: intensity, edges, vesselness)"),
        )
    })
}

/// `KIND[:KEY=VALUE,...]` as the JSON of a design section.
fn short_form(text: &str) -> Result<Value, CliError> {
    let (kind, params) = text.split_once(':').unwrap_or((text, ""));
    let mut section = Map::new();
    section.insert("kind".into(), Value::String(kind.trim().to_string()));
    for pair in params.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (key, value) = pair.split_once('=').ok_or_else(|| {
            CliError::flag(
                "--design",
                format!(
                    "'{pair}' is not KEY=VALUE (in '{text}', the short form KIND:KEY=VALUE,...)"
                ),
            )
        })?;
        section.insert(key.trim().to_string(), short_value(value.trim()));
    }
    Ok(Value::Object(section))
}

/// A number, a list of numbers (`1;2;3`), or a word.
fn short_value(v: &str) -> Value {
    let number = |s: &str| {
        s.trim()
            .parse::<f64>()
            .ok()
            .and_then(serde_json::Number::from_f64)
            .map(Value::Number)
    };
    if v.contains(';') {
        let items: Option<Vec<Value>> = v.split(';').map(number).collect();
        if let Some(items) = items {
            return Value::Array(items);
        }
    }
    number(v).unwrap_or_else(|| Value::String(v.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::spec::design::{EdgeModeSpec, PolaritySpec};

    #[test]
    fn the_short_form_and_the_json_give_the_same_section() {
        for (short, json) in [
            ("edges", r#"{"kind": "edges"}"#),
            (
                "edges:mode=barrier,sigma=2",
                r#"{"kind": "edges", "mode": "barrier", "sigma": 2}"#,
            ),
            (
                "vesselness:scales=1;2.5,polarity=dark",
                r#"{"kind": "vesselness", "scales": [1, 2.5], "polarity": "dark"}"#,
            ),
            (
                "intensity: at=10;20 , power=2",
                r#"{"kind": "intensity", "at": [10, 20], "power": 2}"#,
            ),
        ] {
            assert_eq!(
                parse_design(short).unwrap(),
                parse_design(json).unwrap(),
                "{short}"
            );
        }
        match parse_design("edges:mode=barrier").unwrap() {
            DesignSpec::Edges(e) => assert_eq!(e.mode, EdgeModeSpec::Barrier),
            other => panic!("{other:?}"),
        }
        match parse_design("vesselness:polarity=dark").unwrap() {
            DesignSpec::Vesselness(v) => assert_eq!(v.polarity, PolaritySpec::Dark),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn bad_designs_name_the_flag() {
        for bad in [
            "",
            "blur",
            "edges:sigma",
            "edges:colour=red",
            "{\"kind\": 3",
        ] {
            let e = parse_design(bad).unwrap_err();
            assert!(e.to_string().starts_with("--design: "), "{bad}: {e}");
        }
        let flag = DesignFlag {
            design: Some("edges".into()),
        };
        let e = flag.spec(false, "--cost").unwrap_err();
        assert_eq!(
            e.to_string(),
            "--design: needs the image to design from in --cost"
        );
        assert!(flag.spec(true, "--cost").unwrap().is_some());
        assert!(DesignFlag::default()
            .spec(false, "--cost")
            .unwrap()
            .is_none());
    }
}
