//! A scene's steps as a Snakefile, for Snakemake (`dbms plan --snakefile`): the same rules run
//! on one machine (`snakemake -j N`) and on a cluster (an executor plugin such as Slurm's or
//! Kubernetes'), where the shards of a sharded build (`[build] shards`) run on many machines.
//!
//! Invariant: as for the Makefile ([`super::makefile`]): each rule runs the step's command lines
//! and then records the step's stamp (`dbms plan SCENE --stamp STEP`), which is the rule's one
//! output; its inputs are the scene file, the step's inputs and the stamps of the steps it runs
//! after (the database steps depend on every input of any of them).

use super::file::Scene;
use super::makefile::{begin_options, dependencies, product_stamps, shell_word, stamp_options};
use super::plan::{stamp_path, steps, steps_dir};
use crate::error::{Error, Result};
use std::fmt::Write;
use std::path::Path;

/// `text` as a Python string literal whose Snakemake shell formatting gives back `text`
/// (braces doubled).
fn python_string(text: &str) -> String {
    let escaped = text
        .replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('{', "{{")
        .replace('}', "}}");
    format!("\"{escaped}\"")
}

/// A rule name for step `name`: a Python identifier (`shard.day.3` → `shard_day_3`).
fn rule_name(name: &str) -> String {
    name.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// `path` as a Python string literal naming a rule's input or output; an error for a brace
/// (Snakemake reads `{...}` there as a wildcard, and doubled braces do not escape it) or a
/// control character.
fn snake_path(path: &Path) -> Result<String> {
    let text = path.display().to_string();
    if let Some(c) = text.chars().find(|&c| "{}".contains(c) || c.is_control()) {
        return Err(Error::msg(format!(
            "{text:?} has {c:?} in it, which a Snakefile rule cannot name (a wildcard)"
        ))
        .fix("rename it, or build with dbms build SCENE instead of Snakemake"));
    }
    Ok(python_string(&text))
}

/// A list of paths as a Python list of string literals ([`snake_path`]).
fn python_list<'a>(paths: impl Iterator<Item = &'a Path>) -> Result<String> {
    let items = paths.map(snake_path).collect::<Result<Vec<String>>>()?;
    Ok(format!("[{}]", items.join(", ")))
}

/// The Snakefile of `scene`, read from `scene_path`; an error for a path a rule cannot name
/// (`snake_path`).
pub fn snakefile(scene: &Scene, scene_path: &Path) -> Result<String> {
    let all = steps(scene);
    let dir = steps_dir(scene);
    let scene_file = scene_path.display().to_string();
    let mut m = String::new();
    let _ = writeln!(
        m,
        "# The steps of {scene_file}, written by `dbms plan --snakefile`."
    );
    let _ = writeln!(
        m,
        "# Run from the directory dbms plan ran in: `snakemake -s FILE -j 2` (on a cluster, add an"
    );
    let _ = writeln!(
        m,
        "# executor, e.g. `--executor slurm`); `--config dbms=/path/to/dbms` picks the binary."
    );
    let _ = writeln!(m, "DBMS = config.get(\"dbms\", \"dbms\")\n");
    let goal = product_stamps(&all, &dir);
    let _ = writeln!(m, "rule all:");
    let _ = writeln!(
        m,
        "    input: {}\n",
        python_list(goal.iter().map(|p| p.as_path()))?
    );
    let scene_word = shell_word(&scene_file);
    for s in &all {
        let deps = dependencies(&all, s, &dir);
        let inputs = std::iter::once(scene_path).chain(deps.iter().map(|p| p.as_path()));
        let plan = |options: &[String]| {
            let options: Vec<String> = options.iter().map(|a| shell_word(a)).collect();
            format!(
                "\u{0}DBMS\u{1} plan --quiet {scene_word} {}",
                options.join(" ")
            )
        };
        let stamp = stamp_options(scene, &s.name);
        let mut shell: Vec<String> = Vec::new();
        for o in &s.outputs {
            if let Some(parent) = o.parent().filter(|p| !p.as_os_str().is_empty()) {
                shell.push(format!(
                    "mkdir -p {}",
                    shell_word(&parent.display().to_string())
                ));
            }
        }
        shell.push(plan(&begin_options(&stamp)));
        for c in &s.commands {
            let args: Vec<String> = c.iter().map(|a| shell_word(a)).collect();
            shell.push(format!("\u{0}DBMS\u{1} {}", args.join(" ")));
        }
        shell.push(plan(&stamp));
        // The binary comes from the Snakefile's DBMS (formatted by Snakemake), the rest as is.
        let shell = python_string(&shell.join(" && "))
            .replace('\u{0}', "{")
            .replace('\u{1}', "}");
        let _ = writeln!(m, "# {}: {}", s.name, s.does);
        let _ = writeln!(m, "rule {}:", rule_name(&s.name));
        let _ = writeln!(m, "    input: {}", python_list(inputs)?);
        let _ = writeln!(m, "    output: {}", snake_path(&stamp_path(&dir, &s.name))?);
        let _ = writeln!(m, "    shell: {shell}\n");
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn braces_and_quotes_survive_snakemake_formatting() {
        assert_eq!(
            python_string("a {b} \"c\" \\d"),
            "\"a {{b}} \\\"c\\\" \\\\d\""
        );
        assert_eq!(rule_name("shard.day.3"), "shard_day_3");
        assert_eq!(rule_name("object.tree"), "object_tree");
    }

    /// A brace in a rule's input or output would be a wildcard: refused in one line.
    #[test]
    fn braces_in_paths_are_refused() {
        assert_eq!(
            snake_path(Path::new("a b/c.done")).unwrap(),
            "\"a b/c.done\""
        );
        for bad in ["a{b}/s.done", "x}", "new\nline"] {
            let e = snake_path(Path::new(bad)).unwrap_err().to_string();
            assert!(e.contains("a Snakefile rule cannot name"), "{bad}: {e}");
            assert!(!e.contains('\n'), "one line: {e}");
        }
    }
}
