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

/// `word` quoted for the shell and make when it needs it (spaces, quotes, `$`).
fn quote(word: &str) -> String {
    shell_word(word).replace('$', "$$")
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

/// The Makefile of `scene`, read from `scene_path`.
pub fn makefile(scene: &Scene, scene_path: &Path) -> String {
    let all = steps(scene);
    let dir = steps_dir(scene);
    let path = |p: &Path| quote(&p.display().to_string());
    let scene_file = quote(&scene_path.display().to_string());
    let mut m = String::new();
    let _ = writeln!(
        m,
        "# The steps of {scene_file}, written by `dbms plan --makefile`."
    );
    let _ = writeln!(
        m,
        "# Run with `make -f FILE`; DBMS=/path/to/dbms to pick the binary."
    );
    let _ = writeln!(m, "DBMS ?= dbms\nSCENE := {scene_file}\n");
    let _ = writeln!(m, ".DELETE_ON_ERROR:");
    let products: Vec<String> = product_stamps(&all, &dir).iter().map(|p| path(p)).collect();
    let _ = writeln!(m, "all: {}\n", products.join(" "));
    for s in &all {
        let mut deps = vec!["$(SCENE)".to_string()];
        deps.extend(dependencies(&all, s, &dir).iter().map(|p| path(p)));
        let _ = writeln!(m, "# {}: {}", s.name, s.does);
        let _ = writeln!(
            m,
            "{}: {}",
            path(&stamp_path(&dir, &s.name)),
            deps.join(" ")
        );
        for o in &s.outputs {
            if let Some(parent) = o.parent().filter(|p| !p.as_os_str().is_empty()) {
                let _ = writeln!(m, "\tmkdir -p {}", path(parent));
            }
        }
        for c in &s.commands {
            let args: Vec<String> = c.iter().map(|a| quote(a)).collect();
            let _ = writeln!(m, "\t$(DBMS) {}", args.join(" "));
        }
        let stamp: Vec<String> = stamp_options(scene, &s.name)
            .iter()
            .map(|a| quote(a))
            .collect();
        let _ = writeln!(m, "\t$(DBMS) plan --quiet $(SCENE) {}\n", stamp.join(" "));
    }
    m
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
}
