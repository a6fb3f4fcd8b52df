//! The rules of `ARCHITECTURE.md` ("Invariants") as a test: it reads the
//! sources under `src/` and fails, naming file, line and rule, when
//!
//! 1. `numerics` uses an upper layer of the crate (`crate::http`, `jobs`,
//!    `datasets`, `ops`, `io`, `pool`, `app`, `cli`, `config`, `telemetry`)
//!    or the crates `tokio`, `axum`, `sqlx`, `serde`, `serde_json`, `utoipa`;
//! 2. `io` uses `crate::http`, `jobs`, `datasets`, `ops`, `pool`, `app`,
//!    `cli`, or `tokio`, `axum`, `sqlx`;
//! 3. `jobs`, `ops`, `datasets` or `io` use `crate::http` or `axum`;
//! 4. `unsafe` appears outside `src/numerics/prefetch.rs`, or a file other
//!    than `src/lib.rs` (which denies it) and that one names the
//!    `unsafe_code` lint;
//! 5. a public function of `numerics` that runs a long loop does not take a
//!    `Control` (cancel flag + progress): see [`takes_control`] for which
//!    functions are checked.
//!
//! # How it reads a file
//! Comments, string literals and char literals are blanked first (line
//! numbers kept), the rest is split into identifiers, `::` and single
//! punctuation characters. A use of a module of the crate is a path that
//! starts with `crate::`, `super::` or `self::` (resolved against the file's
//! module and the inline `mod` blocks around it), including every item of a
//! `crate::{a, b::c}` group. A use of an external crate is its name followed
//! by `::` at the start of a path (also after a leading `::` or in a `use`
//! group), `use name;`, `extern crate name`, or an attribute `#[name(…)]`
//! (`#[serde(…)]`). Derives count through their path or their `use`.
//!
//! # What it does not see
//! Paths built by macros from strings, `#[path]` attributes, and items that
//! reach an upper layer through a re-export in a module in between (it
//! checks what a file names, not what a name resolves to). `src/main.rs` is
//! the binary crate; only rule 4 applies to it.

use std::fmt;
use std::path::{Path, PathBuf};

/// Modules of the crate above `numerics`.
const ABOVE_NUMERICS: &[&str] = &[
    "http",
    "jobs",
    "collections",
    "datasets",
    "ops",
    "io",
    "pool",
    "app",
    "cli",
    "config",
    "telemetry",
];
/// Crates `numerics` must not use: no async, HTTP, storage, JSON or schema.
const NOT_IN_NUMERICS: &[&str] = &["tokio", "axum", "sqlx", "serde", "serde_json", "utoipa"];
/// Modules of the crate above `io`.
const ABOVE_IO: &[&str] = &[
    "http",
    "jobs",
    "collections",
    "datasets",
    "ops",
    "pool",
    "app",
    "cli",
];
/// Crates `io` must not use.
const NOT_IN_IO: &[&str] = &["tokio", "axum", "sqlx"];
/// The layers below HTTP (rule 3).
const BELOW_HTTP: &[&str] = &["jobs", "collections", "ops", "datasets", "io"];
/// Every external crate a rule names (the scanner records only these).
const WATCHED_CRATES: &[&str] = &["tokio", "axum", "sqlx", "serde", "serde_json", "utoipa"];

/// The one file that may hold `unsafe`.
const UNSAFE_FILE: &str = "src/numerics/prefetch.rs";
/// The one file besides [`UNSAFE_FILE`] that may name the `unsafe_code` lint.
const LINT_ROOT: &str = "src/lib.rs";

/// Public functions of `numerics` that must take a `Control`: names that
/// match one of these prefixes or suffixes, anywhere in `numerics`…
const CONTROL_PREFIXES: &[&str] = &[
    "solve",
    "design",
    "skeleton",
    "thin",
    "gaussian",
    "structure_tensor",
    "contours",
];
/// … or end with one of these …
const CONTROL_SUFFIXES: &[&str] = &["_transform"];
/// … and these entry points, by file (the transforms, filters, designs and
/// solvers whose names do not follow the patterns). A function with a long
/// loop that is on neither list is not checked: add it here. Known single
/// passes without a `Control` yet, so not listed: `planning::widest_radius`
/// (sort and union-find, inside `plan` after its polled EDT),
/// `segmentation::voronoi` (one pass over the solved maps),
/// `skeleton::graph_2d` (one pass over the skeleton), `mesh::Topology::new`
/// and the `TensorField` constructors (one validation pass).
const CONTROL_ENTRY_POINTS: &[(&str, &str)] = &[
    ("src/numerics/edt.rs", "edt"),
    ("src/numerics/inverse/tomography.rs", "tomography"),
    ("src/numerics/inverse/metric_fit.rs", "fit_metric"),
    ("src/numerics/edt.rs", "edt_squared"),
    ("src/numerics/edt.rs", "signed_edt"),
    ("src/numerics/edt.rs", "multilabel_edt"),
    ("src/numerics/filters.rs", "gradient"),
    ("src/numerics/filters.rs", "hessian"),
    ("src/numerics/contours.rs", "trace"),
    ("src/numerics/metric_design.rs", "intensity"),
    ("src/numerics/metric_design.rs", "edge_strength"),
    ("src/numerics/metric_design.rs", "edges"),
    ("src/numerics/metric_design.rs", "vesselness"),
    (
        "src/numerics/anisotropic/structure_tensor.rs",
        "edge_metric",
    ),
    (
        "src/numerics/anisotropic/height_map.rs",
        "height_map_metric",
    ),
    ("src/numerics/skeleton/medial_axis.rs", "medial_axis"),
    ("src/numerics/segmentation.rs", "offset_euclidean"),
    ("src/numerics/planning.rs", "plan"),
    ("src/numerics/grouping.rs", "group"),
    ("src/numerics/grouping.rs", "oriented_metric"),
    ("src/numerics/mesh/solve.rs", "mesh_distance"),
    ("src/numerics/mesh/sampling.rs", "farthest_point_sampling"),
];

/// One broken rule.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Violation {
    file: String,
    line: usize,
    rule: String,
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: {}", self.file, self.line, self.rule)
    }
}

#[test]
fn layers_use_only_what_is_below_them() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    assert!(
        files.len() > 50,
        "found only {} files under src/",
        files.len()
    );
    let mut violations = Vec::new();
    for path in &files {
        let rel = path
            .strip_prefix(root)
            .unwrap_or(path)
            .to_string_lossy()
            .replace('\\', "/");
        let src = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{rel}: {e}"));
        violations.extend(check_file(&rel, &src));
    }
    let report: Vec<String> = violations.iter().map(ToString::to_string).collect();
    assert!(
        violations.is_empty(),
        "{} layering violation(s) (see ARCHITECTURE.md, Invariants):\n{}",
        violations.len(),
        report.join("\n")
    );
}

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.map(|e| e.path()).unwrap_or_else(|e| panic!("{e}")))
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

const RULE_1: &str = "numerics must not use";
const RULE_2: &str = "io must not use";
const RULE_3: &str = "below http, a layer must not use";
const RULE_4: &str = "unsafe outside src/numerics/prefetch.rs";
const RULE_5: &str = "a long computation of numerics must take a Control";

/// The violations of the file `rel` (path from the crate root, `/`
/// separated) whose text is `src`.
fn check_file(rel: &str, src: &str) -> Vec<Violation> {
    let tokens = tokenize(&blank_comments_and_literals(src));
    let Some(module) = module_path(rel) else {
        return Vec::new();
    };
    let layer = module.first().map(String::as_str).unwrap_or("");
    let mut out = Vec::new();
    let mut fail = |line: usize, rule: String| {
        out.push(Violation {
            file: rel.to_string(),
            line,
            rule,
        })
    };
    // The binary crate is not a layer: only rule 4 applies to it.
    let is_bin = rel == "src/main.rs";
    for r in references(&tokens, &module).into_iter().filter(|_| !is_bin) {
        let (kind, name) = match &r.target {
            Target::Module(m) => ("crate::", m.as_str()),
            Target::Crate(c) => ("", c.as_str()),
        };
        let forbidden = |modules: &[&str], crates: &[&str]| match &r.target {
            Target::Module(m) => modules.contains(&m.as_str()),
            Target::Crate(c) => crates.contains(&c.as_str()),
        };
        if layer == "numerics" && forbidden(ABOVE_NUMERICS, NOT_IN_NUMERICS) {
            fail(
                r.line,
                format!("{RULE_1} {kind}{name} (it is the pure core)"),
            );
        }
        if layer == "io" && forbidden(ABOVE_IO, NOT_IN_IO) {
            fail(
                r.line,
                format!("{RULE_2} {kind}{name} (codecs sit under everything but numerics)"),
            );
        }
        if BELOW_HTTP.contains(&layer) && forbidden(&["http"], &["axum"]) {
            fail(r.line, format!("{RULE_3} {kind}{name}"));
        }
    }
    for t in &tokens {
        match &t.tok {
            Tok::Ident(w) if w == "unsafe" && rel != UNSAFE_FILE => {
                fail(t.line, format!("{RULE_4}: `unsafe`"));
            }
            Tok::Ident(w) if w == "unsafe_code" && rel != UNSAFE_FILE && rel != LINT_ROOT => {
                fail(
                    t.line,
                    format!("{RULE_4}: only {LINT_ROOT} sets the unsafe_code lint"),
                );
            }
            _ => {}
        }
    }
    if layer == "numerics" {
        for f in public_functions(&tokens) {
            if takes_control(rel, &f.name) && !f.signature.iter().any(|w| w == "Control") {
                fail(f.line, format!("{RULE_5}: `pub fn {}` takes none", f.name));
            }
        }
    }
    out
}

/// Whether the public function `name` of the file `rel` of `numerics` must
/// take a `Control` (see [`CONTROL_PREFIXES`], [`CONTROL_SUFFIXES`],
/// [`CONTROL_ENTRY_POINTS`]).
fn takes_control(rel: &str, name: &str) -> bool {
    CONTROL_PREFIXES.iter().any(|p| name.starts_with(p))
        || CONTROL_SUFFIXES.iter().any(|s| name.ends_with(s))
        || CONTROL_ENTRY_POINTS.contains(&(rel, name))
}

/// The module path of a source file (`src/numerics/skeleton/graph.rs` →
/// `numerics::skeleton::graph`; `mod.rs` and `lib.rs` name their folder);
/// `None` outside `src/`.
fn module_path(rel: &str) -> Option<Vec<String>> {
    let inner = rel.strip_prefix("src/")?.strip_suffix(".rs")?;
    let mut parts: Vec<String> = inner.split('/').map(str::to_string).collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    Some(parts)
}

/// Replaces comments (line, block, nested, doc), string literals (plain,
/// byte, raw) and char literals by spaces, keeping the line breaks.
fn blank_comments_and_literals(src: &str) -> String {
    let c: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let ident = |ch: char| ch.is_alphanumeric() || ch == '_';
    let blank = |out: &mut String, ch: char| out.push(if ch == '\n' { '\n' } else { ' ' });
    let mut i = 0;
    while i < c.len() {
        let next = c.get(i + 1).copied();
        if c[i] == '/' && next == Some('/') {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if c[i] == '/' && next == Some('*') {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    blank(&mut out, c[i]);
                    i += 1;
                }
            }
        } else if c[i] == 'r'
            && (i == 0 || !ident(c[i - 1]) || (c[i - 1] == 'b' && (i < 2 || !ident(c[i - 2]))))
            && {
                let mut j = i + 1;
                while c.get(j) == Some(&'#') {
                    j += 1;
                }
                c.get(j) == Some(&'"')
            }
        {
            // A raw string r#"…"#: ends at a quote followed by as many #.
            let mut hashes = 0;
            i += 1;
            while c[i] == '#' {
                hashes += 1;
                i += 1;
            }
            out.push_str(&" ".repeat(hashes + 2));
            i += 1;
            while i < c.len() {
                if c[i] == '"' && (1..=hashes).all(|k| c.get(i + k) == Some(&'#')) {
                    out.push_str(&" ".repeat(hashes + 1));
                    i += hashes + 1;
                    break;
                }
                blank(&mut out, c[i]);
                i += 1;
            }
        } else if c[i] == '"' {
            out.push(' ');
            i += 1;
            while i < c.len() && c[i] != '"' {
                if c[i] == '\\' {
                    blank(&mut out, c[i]);
                    i += 1;
                }
                if i < c.len() {
                    blank(&mut out, c[i]);
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c[i] == '\'' && next == Some('\\') {
            // An escaped char literal: '\n', '\'', '\u{…}'.
            out.push_str("  ");
            i += 2;
            while i < c.len() && c[i] != '\'' {
                out.push(' ');
                i += 1;
            }
            out.push(' ');
            i += 1;
        } else if c[i] == '\'' && c.get(i + 2) == Some(&'\'') {
            out.push_str("   ");
            i += 3;
        } else {
            // Code, or the quote of a lifetime or label.
            out.push(c[i]);
            i += 1;
        }
    }
    out
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Ident(String),
    /// `::`.
    PathSep,
    Punct(char),
}

#[derive(Debug, Clone)]
struct Token {
    tok: Tok,
    line: usize,
}

impl Token {
    fn ident(&self) -> Option<&str> {
        match &self.tok {
            Tok::Ident(s) => Some(s),
            _ => None,
        }
    }
    fn is(&self, ch: char) -> bool {
        self.tok == Tok::Punct(ch)
    }
    fn is_word(&self, w: &str) -> bool {
        self.ident() == Some(w)
    }
}

/// Identifiers (numbers too), `::`, and every other character but
/// whitespace as punctuation.
fn tokenize(clean: &str) -> Vec<Token> {
    let c: Vec<char> = clean.chars().collect();
    let mut out = Vec::new();
    let mut line = 1;
    let mut i = 0;
    while i < c.len() {
        let ch = c[i];
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if ch.is_alphanumeric() || ch == '_' {
            let start = i;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            let mut word: String = c[start..i].iter().collect();
            // A raw identifier r#name is the identifier name.
            if word == "r"
                && c.get(i) == Some(&'#')
                && c.get(i + 1).is_some_and(|n| n.is_alphabetic() || *n == '_')
            {
                let s = i + 1;
                i = s;
                while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                    i += 1;
                }
                word = c[s..i].iter().collect();
            }
            out.push(Token {
                tok: Tok::Ident(word),
                line,
            });
        } else if ch == ':' && c.get(i + 1) == Some(&':') {
            out.push(Token {
                tok: Tok::PathSep,
                line,
            });
            i += 2;
        } else {
            out.push(Token {
                tok: Tok::Punct(ch),
                line,
            });
            i += 1;
        }
    }
    out
}

/// What a path names at its root.
#[derive(Debug, Clone, PartialEq)]
enum Target {
    /// A top-level module of this crate (`http`, `numerics`, …).
    Module(String),
    /// An external crate among [`WATCHED_CRATES`].
    Crate(String),
}

#[derive(Debug, Clone, PartialEq)]
struct Reference {
    line: usize,
    target: Target,
}

/// Every use of a top-level module of the crate or of a watched crate in
/// `tokens`, for a file of module path `module`.
fn references(tokens: &[Token], module: &[String]) -> Vec<Reference> {
    let mut out = Vec::new();
    // Inline `mod name {` blocks: (name, brace depth inside them).
    let mut inline: Vec<(String, usize)> = Vec::new();
    let mut depth = 0usize;
    let at = |i: usize| tokens.get(i);
    for i in 0..tokens.len() {
        let t = &tokens[i];
        if t.is('{') {
            depth += 1;
            if i >= 2 && tokens[i - 2].is_word("mod") {
                if let Some(name) = tokens[i - 1].ident() {
                    inline.push((name.to_string(), depth));
                }
            }
            continue;
        }
        if t.is('}') {
            depth = depth.saturating_sub(1);
            while inline.last().is_some_and(|(_, d)| *d > depth) {
                inline.pop();
            }
            continue;
        }
        let Some(word) = t.ident() else {
            continue;
        };
        let after_sep = i > 0 && tokens[i - 1].tok == Tok::PathSep;
        let leading_sep = after_sep && (i < 2 || tokens[i - 2].ident().is_none());
        let before_sep = at(i + 1).is_some_and(|n| n.tok == Tok::PathSep);
        if matches!(word, "crate" | "super" | "self") && before_sep && !after_sep {
            // Resolve the crate/super/self prefix to a module path.
            let mut path: Vec<String> = if word == "crate" {
                Vec::new()
            } else {
                module
                    .iter()
                    .cloned()
                    .chain(inline.iter().map(|(n, _)| n.clone()))
                    .collect()
            };
            let mut j = i;
            loop {
                match tokens[j].ident() {
                    Some("crate") => path.clear(),
                    Some("super") => {
                        path.pop();
                    }
                    _ => {}
                }
                let next_is_prefix = at(j + 2)
                    .and_then(Token::ident)
                    .is_some_and(|w| matches!(w, "super" | "self"));
                if at(j + 1).is_some_and(|n| n.tok == Tok::PathSep) && next_is_prefix {
                    j += 2;
                } else {
                    break;
                }
            }
            if let Some(root) = path.first() {
                out.push(Reference {
                    line: t.line,
                    target: Target::Module(root.clone()),
                });
            } else {
                for name in path_roots(tokens, j + 2) {
                    out.push(Reference {
                        line: t.line,
                        target: Target::Module(name),
                    });
                }
            }
            continue;
        }
        if !WATCHED_CRATES.contains(&word) {
            continue;
        }
        // The tokens just before this one, nearest first.
        let before = |k: usize| i.checked_sub(k).map(|b| &tokens[b]);
        let word_before = |k: usize, w: &str| before(k).is_some_and(|t| t.is_word(w));
        let punct_before = |k: usize, ch: char| before(k).is_some_and(|t| t.is(ch));
        let used = (before_sep && (!after_sep || leading_sep)) // name::…, ::name::…
            || word_before(1, "use") // use name;
            || (word_before(1, "crate") && word_before(2, "extern")) // extern crate name
            || (punct_before(1, '[') && punct_before(2, '#')) // #[name(…)]
            || (punct_before(1, '[') && punct_before(2, '!') && punct_before(3, '#'));
        if used {
            out.push(Reference {
                line: t.line,
                target: Target::Crate(word.to_string()),
            });
        }
    }
    out
}

/// The first segments of the path that starts at token `i`: one name, or
/// every item of a `{a, b::c, self}` group (without `self`).
fn path_roots(tokens: &[Token], i: usize) -> Vec<String> {
    let Some(t) = tokens.get(i) else {
        return Vec::new();
    };
    if let Some(w) = t.ident() {
        return vec![w.to_string()];
    }
    if !t.is('{') {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut depth = 0;
    let mut expect_item = true;
    for t in &tokens[i..] {
        if t.is('{') {
            depth += 1;
            expect_item = depth == 1;
            continue;
        }
        if t.is('}') {
            depth -= 1;
            if depth == 0 {
                break;
            }
            continue;
        }
        if depth == 1 && t.is(',') {
            expect_item = true;
            continue;
        }
        if depth == 1 && expect_item {
            if let Some(w) = t.ident() {
                if w != "self" {
                    out.push(w.to_string());
                }
            }
            expect_item = false;
        }
    }
    out
}

/// A `pub fn` and the words of its signature (up to its body or `;`).
struct PublicFn {
    name: String,
    line: usize,
    signature: Vec<String>,
}

/// The `pub fn`s (also `pub const`/`async`/`unsafe fn`; not `pub(crate)`).
fn public_functions(tokens: &[Token]) -> Vec<PublicFn> {
    let mut out = Vec::new();
    for i in 0..tokens.len() {
        if !tokens[i].is_word("pub") {
            continue;
        }
        let mut j = i + 1;
        while tokens
            .get(j)
            .is_some_and(|t| t.is_word("const") || t.is_word("async") || t.is_word("unsafe"))
        {
            j += 1;
        }
        if !tokens.get(j).is_some_and(|t| t.is_word("fn")) {
            continue;
        }
        let Some(name) = tokens.get(j + 1).and_then(Token::ident) else {
            continue;
        };
        // Up to the body or the `;` of a declaration, outside brackets
        // (`[usize; 2]` has a `;`).
        let mut depth = 0i32;
        let signature = tokens[j + 2..]
            .iter()
            .take_while(|t| {
                if t.is('(') || t.is('[') {
                    depth += 1;
                } else if t.is(')') || t.is(']') {
                    depth -= 1;
                }
                depth > 0 || !(t.is('{') || t.is(';'))
            })
            .filter_map(|t| t.ident().map(str::to_string))
            .collect();
        out.push(PublicFn {
            name: name.to_string(),
            line: tokens[i].line,
            signature,
        });
    }
    out
}

/// The checker against sources written to break (or keep) each rule: a
/// rule that cannot fail proves nothing.
mod checker {
    use super::*;

    fn rules(rel: &str, src: &str) -> Vec<String> {
        check_file(rel, src)
            .into_iter()
            .map(|v| format!("{}:{}", v.line, v.rule))
            .collect()
    }

    fn fails(rel: &str, src: &str, rule: &str) {
        let found = rules(rel, src);
        assert!(
            found.iter().any(|r| r.contains(rule)),
            "{rel}: expected `{rule}` for\n{src}\ngot {found:?}"
        );
    }

    fn passes(rel: &str, src: &str) {
        assert_eq!(rules(rel, src), Vec::<String>::new(), "{rel}:\n{src}");
    }

    #[test]
    fn rule_1_numerics_uses_no_upper_layer_and_no_server_crate() {
        let f = "src/numerics/edt.rs";
        for m in ABOVE_NUMERICS {
            fails(f, &format!("use crate::{m}::X;"), RULE_1);
            fails(f, &format!("fn f() {{ crate::{m}::g(); }}"), RULE_1);
            fails(f, &format!("use crate::{{grid, {m}::X}};"), RULE_1);
            fails(
                "src/numerics/mod.rs",
                &format!("use super::{m}::X;"),
                RULE_1,
            );
            fails(
                "src/numerics/skeleton/graph.rs",
                &format!("use super::super::super::{m}::X;"),
                RULE_1,
            );
        }
        for c in NOT_IN_NUMERICS {
            fails(f, &format!("use {c}::X;"), RULE_1);
            fails(f, &format!("use {c};"), RULE_1);
            fails(f, &format!("fn f() {{ ::{c}::g(); }}"), RULE_1);
            fails(f, &format!("#[derive({c}::Serialize)] struct S;"), RULE_1);
        }
        fails(f, "#[serde(rename = \"a\")] struct S;", RULE_1);
        fails(f, "extern crate serde;", RULE_1);
        // Line numbers point at the use.
        assert_eq!(
            rules(f, "//! doc\n\nuse crate::http::X;")[0],
            format!("3:{RULE_1} crate::http (it is the pure core)")
        );
        // Its own modules, comments and strings are fine.
        passes(
            f,
            "use super::grid::Grid;\nuse crate::numerics::Control;\n// crate::http::X\n\
             /// [`crate::ops`]\nconst S: &str = \"serde::X tokio::spawn\";\n\
             fn f<'a>(x: &'a str) -> char { let _ = r#\"crate::io::x\"#; 'x' }",
        );
        // A module of the crate named like a crate is not the crate.
        passes(f, "use self::serde_like::X; fn f() { x.serde_json(); }");
        // Inline modules shift `super`.
        passes(
            "src/numerics/mod.rs",
            "mod tests { use super::grid::Grid; }",
        );
        fails(
            "src/numerics/mod.rs",
            "mod tests { use super::super::ops::X; }",
            RULE_1,
        );
    }

    #[test]
    fn rule_2_io_uses_no_upper_layer_and_no_server_crate() {
        for m in ABOVE_IO {
            fails("src/io/npy.rs", &format!("use crate::{m}::X;"), RULE_2);
        }
        for c in NOT_IN_IO {
            fails("src/io/mesh/ply.rs", &format!("use {c}::X;"), RULE_2);
        }
        passes(
            "src/io/npy.rs",
            "use crate::numerics::Grid; use serde::Serialize; use super::ArrayData;",
        );
    }

    #[test]
    fn rule_3_no_http_below_http() {
        for f in [
            "src/jobs/db.rs",
            "src/ops/grid_edt.rs",
            "src/datasets.rs",
            "src/datasets/mesh.rs",
            "src/io/mod.rs",
        ] {
            fails(f, "use crate::http::error::ApiError;", RULE_3);
            fails(f, "fn f() { axum::Json::<u8>::from_bytes(b); }", RULE_3);
            fails(f, "use axum::http::StatusCode;", RULE_3);
        }
        passes(
            "src/http/mod.rs",
            "use axum::Router; use crate::http::error::X;",
        );
        passes("src/app.rs", "use crate::http::router;");
    }

    #[test]
    fn rule_4_unsafe_only_in_prefetch() {
        fails("src/numerics/heap.rs", "fn f() { unsafe { g() } }", RULE_4);
        fails("src/ops/mod.rs", "unsafe fn f() {}", RULE_4);
        fails("src/main.rs", "unsafe impl Send for X {}", RULE_4);
        fails(
            "src/numerics/heap.rs",
            "#[allow(unsafe_code)] fn f() {}",
            RULE_4,
        );
        passes(
            UNSAFE_FILE,
            "#[allow(unsafe_code)] fn f() { unsafe { g() } }",
        );
        passes(LINT_ROOT, "#![deny(unsafe_code)]");
        passes(
            "src/numerics/heap.rs",
            "// unsafe\nconst S: &str = \"unsafe\";",
        );
    }

    #[test]
    fn rule_5_long_computations_take_a_control() {
        let f = "src/numerics/filters.rs";
        fails(
            f,
            "pub fn gaussian_smooth(grid: &Grid, v: &[f64]) -> Vec<f64> { x }",
            RULE_5,
        );
        fails(f, "pub fn gradient(grid: &Grid) -> Vec<f64> { x }", RULE_5);
        fails(
            "src/numerics/x.rs",
            "impl S { pub fn solve(&self) -> T; }",
            RULE_5,
        );
        fails(
            "src/numerics/x.rs",
            "pub fn distance_transform(g: &Grid) {}",
            RULE_5,
        );
        passes(
            f,
            "pub fn gaussian_smooth(\n    grid: &Grid,\n    control: &Control<'_>,\n) -> R {}",
        );
        // Other names, private functions and other layers are not checked.
        passes(f, "pub fn normalize_unit(v: &[f64]) -> Vec<f64> {}");
        passes(f, "fn gaussian_kernel(s: f64) -> Vec<f64> {}");
        passes(f, "pub(crate) fn solve_inner(s: f64) {}");
        // Brackets in the signature do not end it.
        passes(
            "src/numerics/contours.rs",
            "pub fn trace(s: [usize; 2], c: &Control<'_>) -> R { x }",
        );
        fails(
            "src/numerics/contours.rs",
            "pub fn trace(s: [usize; 2]) -> R { Control::new() }",
            RULE_5,
        );
        passes("src/ops/grid_edt.rs", "pub fn solve(x: u8) {}");
    }
}
