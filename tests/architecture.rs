//! The import direction `docs/architecture.md` draws, checked against the code.
//!
//! The layer diagram (the first fenced block of that page) is read as written: each line names,
//! in its module column, the modules of one row, and rows lower on the page are lower layers.
//! A library module may name (`crate::m`) only modules of its own row or rows below it, and the
//! items the crate root re-exports (`crate::Error`); the rows of a band (between two rules,
//! named by its label) may also have to skip a band below it ([`SKIPS`]: the view names no
//! stage). Test code (`#[cfg(test)]` modules, `tests.rs` and `*_tests.rs` files, and modules
//! declared under `#[cfg(feature = "testing")]`, which only tests and benches build) is
//! exempt: tests may build their scenes with any stage.
//! So are comments: a doc link may point up the layers (to say who uses a thing) without
//! making the module depend on it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Where the module column of the diagram starts and ends, in characters.
const MODULE_COLUMN: std::ops::Range<usize> = 14..39;

/// A library module's place in the diagram: its row (0 = top) and the label of its band (the
/// rows between two rules `─`, labelled on their first line left of the module column).
struct Place {
    row: usize,
    band: String,
}

/// Bands whose modules name no module of a band below them: (band, the band it skips, why).
const SKIPS: &[(&str, &str, &str)] = &[(
    "view",
    "stages",
    "the view reads the tile file the stages write, not the stages",
)];

/// Each library module's place in the diagram, read from `docs/architecture.md`.
fn places() -> BTreeMap<String, Place> {
    let doc = std::fs::read_to_string("docs/architecture.md").expect("docs/architecture.md");
    let block = doc
        .split("```")
        .nth(1)
        .expect("docs/architecture.md has a fenced layer diagram");
    let mut places = BTreeMap::new();
    let (mut band, mut band_starts) = (String::new(), true);
    for (row, line) in block.lines().enumerate() {
        if line.contains('─') {
            band_starts = true;
            continue;
        }
        let chars: Vec<char> = line.chars().collect();
        let label: String = chars.iter().take(MODULE_COLUMN.start).collect();
        if band_starts && !label.trim().is_empty() {
            (band, band_starts) = (label.trim().to_string(), false);
        }
        if chars.len() <= MODULE_COLUMN.start {
            continue;
        }
        let end = MODULE_COLUMN.end.min(chars.len());
        let column: String = chars[MODULE_COLUMN.start..end].iter().collect();
        for name in column.split_whitespace() {
            if name.chars().all(|c| c.is_ascii_lowercase() || c == '_') {
                let band = band.clone();
                places.insert(name.to_string(), Place { row, band });
            }
        }
    }
    places
}

/// Every `.rs` file under `dir`.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("readable source directory") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The top-level library module a file under `src/lib` belongs to (`None` for `lib.rs`).
fn module_of(path: &Path) -> Option<String> {
    let rel = path.strip_prefix("src/lib").expect("under src/lib");
    let first = rel.components().next()?.as_os_str().to_str()?.to_string();
    match first.strip_suffix(".rs") {
        Some("lib") => None,
        Some(stem) => Some(stem.to_string()),
        None => Some(first),
    }
}

/// The files of the modules `files` declare under `#[cfg(feature = "testing")]` (compiled for
/// tests and benches only): each module's file `m.rs` and its directory `m/`.
fn testing_only(files: &[PathBuf]) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for path in files {
        let text = std::fs::read_to_string(path).expect("readable source");
        let lines: Vec<&str> = text.lines().map(str::trim).collect();
        // The children of `lib.rs` or `mod.rs` live beside it, those of `m.rs` in `m/`.
        let dir = match path.file_name().and_then(|n| n.to_str()) {
            Some("lib.rs" | "mod.rs") => path.parent().expect("a parent").to_path_buf(),
            _ => path.with_extension(""),
        };
        for (i, line) in lines.iter().enumerate() {
            if *line != r#"#[cfg(feature = "testing")]"# {
                continue;
            }
            // The declaration may carry more attributes (`#[doc(hidden)]`) first.
            let name = lines[i + 1..]
                .iter()
                .find(|l| !l.starts_with("#["))
                .and_then(|l| l.trim_start_matches("pub ").strip_prefix("mod "))
                .and_then(|l| l.strip_suffix(';'));
            if let Some(name) = name {
                out.push(dir.join(format!("{name}.rs")));
                out.push(dir.join(name));
            }
        }
    }
    out
}

/// The code of a file that is not test code or comments: its lines up to its first
/// `#[cfg(test)]`, each without what follows `//`; nothing for a test file.
fn non_test_code(path: &Path) -> String {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if name == "tests.rs" || name.ends_with("_tests.rs") {
        return String::new();
    }
    let text = std::fs::read_to_string(path).expect("readable source");
    let code = text.split("#[cfg(test)]").next().unwrap_or("");
    code.lines()
        .map(|line| line.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The top-level modules `text` names as `crate::m` or inside `crate::{a, b::c, ...}`.
fn named_modules(text: &str) -> Vec<String> {
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    let mut out = Vec::new();
    for (k, _) in text.match_indices("crate::") {
        let rest = &text[k + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            // Top-level names of the group: those at brace depth 0 after `{` or `,`.
            let mut depth = 0;
            let mut at_start = true;
            for (i, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => at_start = true,
                    c if c.is_whitespace() => {}
                    _ if at_start && depth == 0 => {
                        out.push(ident(&group[i..]));
                        at_start = false;
                    }
                    _ => {}
                }
            }
        } else {
            out.push(ident(rest));
        }
    }
    out
}

#[test]
fn no_library_module_names_a_module_above_its_row() {
    let places = places();
    let mut files = Vec::new();
    sources(Path::new("src/lib"), &mut files);
    files.sort();
    let testing_only = testing_only(&files);
    let mut against = Vec::new();
    for path in &files {
        if testing_only.iter().any(|m| path.starts_with(m)) {
            continue;
        }
        let Some(module) = module_of(path) else {
            continue;
        };
        let Some(place) = places.get(&module) else {
            against.push(format!(
                "{}: module `{module}` is not in the diagram",
                path.display()
            ));
            continue;
        };
        for named in named_modules(&non_test_code(path)) {
            let skip = |p: &Place| {
                SKIPS
                    .iter()
                    .find(|(band, skipped, _)| *band == place.band && *skipped == p.band)
            };
            match places.get(&named) {
                _ if named.starts_with(|c: char| c.is_ascii_uppercase()) => {} // crate root
                Some(p) if p.row < place.row => against.push(format!(
                    "{}: `{module}` names `crate::{named}`, a layer above it",
                    path.display()
                )),
                Some(p) => {
                    if let Some((_, skipped, why)) = skip(p) {
                        against.push(format!(
                            "{}: `{module}` names `crate::{named}`, of the {skipped} band: {why}",
                            path.display()
                        ));
                    }
                }
                None => against.push(format!(
                    "{}: `crate::{named}` is not a module in the diagram",
                    path.display()
                )),
            }
        }
    }
    against.dedup();
    assert!(
        against.is_empty(),
        "imports against docs/architecture.md:\n{}",
        against.join("\n")
    );
}

#[test]
fn the_diagram_places_every_library_module() {
    let places = places();
    let rows: BTreeMap<&str, usize> = places.iter().map(|(m, p)| (m.as_str(), p.row)).collect();
    for module in [
        "error", "walk", "io", "sun", "standing", "pyramid", "render", "testing",
    ] {
        assert!(rows.contains_key(module), "{module} missing from {rows:?}");
    }
    // Lower on the page is lower in the layers.
    assert!(rows["error"] > rows["io"] && rows["io"] > rows["sun"]);
    assert!(rows["sun"] > rows["standing"] && rows["standing"] > rows["pyramid"]);
    assert!(rows["pyramid"] > rows["render"] && rows["render"] > rows["testing"]);
    // The rule that the view skips the stages reads bands the diagram has.
    assert_eq!(places["render"].band, "view");
    for (band, skipped, _) in SKIPS {
        assert!(places.values().any(|p| p.band == *band), "no band {band}");
        assert!(
            places.values().any(|p| p.band == *skipped),
            "no band {skipped}"
        );
    }
}

#[test]
fn the_test_helpers_are_behind_the_testing_feature() {
    let mut files = Vec::new();
    sources(Path::new("src/lib"), &mut files);
    let gated = testing_only(&files);
    for module in ["src/lib/testing", "src/lib/render/mesh.rs"] {
        assert!(
            gated.contains(&PathBuf::from(module)),
            "{module} is compiled into every build: declare it under #[cfg(feature = \"testing\")] ({gated:?})"
        );
    }
}

#[test]
fn named_modules_reads_paths_and_groups() {
    let text = "use crate::a::B;\nuse crate::{c, d::{e, f}, g::H};\n/// [`crate::i::J`]\n";
    assert_eq!(named_modules(text), ["a", "c", "d", "g", "i"]);
}
