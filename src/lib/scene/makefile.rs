//! A scene's steps as a Makefile, for teams that keep make in charge (`dbms plan --makefile`).
//!
//! Invariant: the Makefile runs the same command lines as the plan's steps, each rule's target
//! is the step's stamp (written by `dbms plan SCENE --stamp STEP` after the step's commands
//! succeeded), and a rule is out of date when the scene file, an input, or a stamp it runs after
//! is newer. The database steps (ingest, heights, place) depend on every input of any of them, so
//! make rebuilds the database from ingest whenever one of them has to run, as `dbms plan` does
//! (placing adds to the database).

use super::file::Scene;
use super::plan::{stamp_path, steps, steps_dir, Step};
use crate::error::{Error, Result};
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// `word` quoted for the shell when it needs it (spaces, quotes, `$`).
pub(super) fn shell_word(word: &str) -> String {
    let plain = word
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "-_./:,=+@%".contains(c));
    if plain && !word.is_empty() {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', "'\\''"))
    }
}

/// `word` quoted for the shell and make when it needs it (spaces, quotes, `$`): a word of a
/// recipe line.
fn quote(word: &str) -> String {
    shell_word(word).replace('$', "$$")
}

/// Characters make cannot take in a target or prerequisite, escaped or not: `:` `;` `|` `=`
/// end or change the rule, `%` makes a pattern rule, `*?[]~` are globs, `()` an archive member,
/// `\` an escape, and control characters end the line.
const NOT_IN_MAKE: &str = ":;|=%*?[]~()\\";

/// `path` as a target or prerequisite of a rule: spaces and `#` escaped with `\`, `$` doubled;
/// an error naming it for what make cannot express ([`NOT_IN_MAKE`]).
fn make_word(path: &Path) -> Result<String> {
    let text = path.display().to_string();
    if let Some(c) = text
        .chars()
        .find(|&c| NOT_IN_MAKE.contains(c) || c.is_control())
    {
        return Err(Error::msg(format!(
            "{text:?} has {c:?} in it, which a Makefile rule cannot name"
        ))
        .fix("rename it, or build with dbms build SCENE instead of make"));
    }
    Ok(text
        .replace('$', "$$")
        .replace(' ', "\\ ")
        .replace('#', "\\#"))
}

/// The files a step's rule depends on besides the scene file: its inputs and the stamps of the
/// steps it runs after. The database steps (ingest, heights, place) depend on every input of
/// any of them, and ingest on every object's stamp, so a rule engine starts the database over
/// from ingest whenever one of them has to run, as `dbms plan` does (placing adds to the
/// database).
pub(super) fn dependencies(all: &[Step], step: &Step, dir: &Path) -> Vec<PathBuf> {
    let mut deps: Vec<PathBuf> = match step.name == "ingest" {
        true => all
            .iter()
            .filter(|s| s.writes_database)
            .flat_map(|s| s.inputs.iter().cloned())
            .chain(
                all.iter()
                    .filter(|s| s.name.starts_with("object."))
                    .map(|s| stamp_path(dir, &s.name)),
            )
            .collect(),
        false => step.inputs.clone(),
    };
    deps.extend(step.after.iter().map(|a| stamp_path(dir, a)));
    deps
}

/// The stamps of the steps that deliver products: what a rule engine's default goal builds.
pub(super) fn product_stamps(all: &[Step], dir: &Path) -> Vec<PathBuf> {
    all.iter()
        .filter(|s| s.name.starts_with("product"))
        .map(|s| stamp_path(dir, &s.name))
        .collect()
}

/// The `dbms plan SCENE` options that record step `name` of `scene` as run (with `--shards`
/// when the scene is sharded, so the stamp's key is the plan's).
pub(super) fn stamp_options(scene: &Scene, name: &str) -> Vec<String> {
    let mut c = Vec::new();
    if scene.shards() > 1 {
        c.extend(["--shards".to_string(), scene.shards().to_string()]);
    }
    c.extend(["--stamp".to_string(), name.to_string()]);
    c
}

/// The Makefile of `scene`, read from `scene_path`; an error for a path make cannot name
/// (`NOT_IN_MAKE`).
pub fn makefile(scene: &Scene, scene_path: &Path) -> Result<String> {
    let all = steps(scene);
    let dir = steps_dir(scene);
    let path = |p: &Path| quote(&p.display().to_string());
    let scene_file = quote(&scene_path.display().to_string());
    let mut m = String::new();
    let _ = writeln!(
        m,
        "# The steps of {}, written by `dbms plan --makefile`.",
        make_word(scene_path)?
    );
    let _ = writeln!(
        m,
        "# Run with `make -f FILE`; DBMS=/path/to/dbms to pick the binary."
    );
    // In an assignment `#` starts a comment unless escaped.
    let scene_value = scene_file.replace('#', "\\#");
    let _ = writeln!(m, "DBMS ?= dbms\nSCENE := {scene_value}\n");
    let _ = writeln!(m, ".DELETE_ON_ERROR:");
    let products = product_stamps(&all, &dir)
        .iter()
        .map(|p| make_word(p))
        .collect::<Result<Vec<String>>>()?;
    let _ = writeln!(m, "all: {}\n", products.join(" "));
    for s in &all {
        let mut deps = vec![make_word(scene_path)?];
        for p in dependencies(&all, s, &dir) {
            deps.push(make_word(&p)?);
        }
        let stamp = stamp_options(scene, &s.name);
        let plan = |options: &[String]| {
            let options: Vec<String> = options.iter().map(|a| quote(a)).collect();
            format!("\t$(DBMS) plan --quiet $(SCENE) {}", options.join(" "))
        };
        let _ = writeln!(m, "# {}: {}", s.name, s.does);
        let target = make_word(&stamp_path(&dir, &s.name))?;
        let _ = writeln!(m, "{target}: {}", deps.join(" "));
        for o in &s.outputs {
            if let Some(parent) = o.parent().filter(|p| !p.as_os_str().is_empty()) {
                let _ = writeln!(m, "\tmkdir -p {}", path(parent));
            }
        }
        let _ = writeln!(m, "{}", plan(&begin_options(&stamp)));
        for c in &s.commands {
            let args: Vec<String> = c.iter().map(|a| quote(a)).collect();
            let _ = writeln!(m, "\t$(DBMS) {}", args.join(" "));
        }
        let _ = writeln!(m, "{}\n", plan(&stamp));
    }
    Ok(m)
}

/// The `dbms plan SCENE` options that record step `name` as begun, from its `--stamp` options
/// ([`stamp_options`]): its inputs are hashed before its commands run, and the stamp its
/// `--stamp` writes after them is that one.
pub(super) fn begin_options(stamp: &[String]) -> Vec<String> {
    stamp
        .iter()
        .map(|o| match o.as_str() {
            "--stamp" => "--begin".to_string(),
            _ => o.clone(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_are_quoted_only_when_they_need_it() {
        assert_eq!(quote("out/db"), "out/db");
        assert_eq!(quote("500066,5300130"), "500066,5300130");
        assert_eq!(quote("my dir/a b"), "'my dir/a b'");
        assert_eq!(quote("it's"), "'it'\\''s'");
        assert_eq!(quote("$HOME"), "'$$HOME'");
        assert_eq!(quote(""), "''");
    }

    /// Spaces, `#` and `$` are escaped in targets and prerequisites (make runs the rule:
    /// tests/cli_scene.rs); what make cannot name is refused in one line.
    #[test]
    fn paths_make_cannot_name_are_refused_and_the_rest_escaped() {
        let word = |p: &str| make_word(Path::new(p));
        assert_eq!(word("my dir/a#1$.done").unwrap(), "my\\ dir/a\\#1$$.done");
        for bad in [
            "a:b/s.done",
            "50%/s.done",
            "a*b",
            "x(y)",
            "back\\slash",
            "new\nline",
        ] {
            let e = word(bad).unwrap_err().to_string();
            assert!(e.contains("a Makefile rule cannot name"), "{bad}: {e}");
            assert!(!e.contains('\n'), "one line: {e}");
        }
    }
}
