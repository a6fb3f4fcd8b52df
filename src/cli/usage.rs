//! Command-line usage errors as one line on stderr.

use clap::error::ErrorKind;
use clap::Parser;

/// Parses the process arguments. `--help` and `--version` print and exit 0;
/// a usage error prints `geodex: <what is wrong>` on one line and exits 2.
pub(crate) fn parse_or_exit<P: Parser>() -> P {
    match P::try_parse() {
        Ok(p) => p,
        Err(e) => match e.kind() {
            ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => e.exit(),
            _ => {
                eprintln!("geodex: {}", one_line(&e.render().to_string()));
                std::process::exit(2)
            }
        },
    }
}

/// The first paragraph of a clap message, on one line, without `error: `.
fn one_line(message: &str) -> String {
    let first: Vec<&str> = message
        .lines()
        .map(str::trim)
        .skip_while(|l| l.is_empty())
        .take_while(|l| !l.is_empty())
        .collect();
    let joined = first.join(" ");
    joined
        .strip_prefix("error: ")
        .unwrap_or(&joined)
        .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clap_messages_become_one_line() {
        let m = "error: the following required arguments were not provided:\n  --out <U.npy>\n\nUsage: geodex distance --out <U.npy>\n\nFor more information, try '--help'.\n";
        assert_eq!(
            one_line(m),
            "the following required arguments were not provided: --out <U.npy>"
        );
    }
}
