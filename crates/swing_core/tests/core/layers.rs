//! The core's layers only look down: every `crate::…` path in `src/` names a module of the
//! same layer or a lower one (docs/architecture.md, "Layers"). Unit tests inside `src/`
//! count too; a test that needs a higher layer belongs in `tests/`.
//!
//! Order, bottom first: config/error/parallel ← linalg ← plant (and the sensor models, `sensors`) ←
//! sysid (and its fixtures in `testing`) ← control (and `mission`'s guidance) ← sim ← design.

use std::path::{Path, PathBuf};

/// Layer of a top-level module of `swing_core` (bottom = 0).
fn layer(module: &str) -> Option<usize> {
    Some(match module {
        "config" | "error" | "parallel" => 0,
        "linalg" => 1,
        "plant" | "sensors" => 2,
        "sysid" | "testing" => 3,
        "control" | "mission" => 4,
        "sim" => 5,
        "design" => 6,
        _ => return None,
    })
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("readable src dir") {
        let path = entry.expect("dir entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The top-level modules a source text names through `crate::X` or `use crate::{X, …}`,
/// with the line of each. Comments (doc links included) are skipped. `super::` cannot leave a
/// top-level module except from its own root file, which [`roots_do_not_climb`] checks.
fn referenced(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim_start();
        if line.starts_with("//") {
            continue;
        }
        let code = line.split("//").next().unwrap_or("");
        let mut rest = code;
        while let Some(at) = rest.find("crate::") {
            let before = rest[..at].chars().last();
            rest = &rest[at + "crate::".len()..];
            // `swing_core::crate::` cannot occur; an identifier ending in `crate` (e.g.
            // `subcrate::`) is not the keyword.
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                continue;
            }
            if let Some(group) = rest.strip_prefix('{') {
                let end = group.find('}').unwrap_or(group.len());
                for item in group[..end].split(',') {
                    let name: String = item
                        .trim()
                        .chars()
                        .take_while(|c| c.is_alphanumeric() || *c == '_')
                        .collect();
                    if !name.is_empty() {
                        out.push((i + 1, name));
                    }
                }
                continue;
            }
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() {
                out.push((i + 1, name));
            }
        }
    }
    out
}

#[test]
fn no_module_of_the_core_imports_from_a_layer_above_its_own() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    assert!(files.len() > 20, "found only {} source files", files.len());
    let mut upward = Vec::new();
    let mut unknown = Vec::new();
    for file in &files {
        let rel = file.strip_prefix(&src).expect("under src");
        let top = rel
            .components()
            .next()
            .and_then(|c| c.as_os_str().to_str())
            .expect("utf-8 path")
            .trim_end_matches(".rs")
            .to_string();
        if top == "lib" {
            continue;
        }
        let Some(own) = layer(&top) else {
            unknown.push(format!("{}: module `{top}` has no layer", rel.display()));
            continue;
        };
        let text = std::fs::read_to_string(file).expect("readable source");
        for (line, name) in referenced(&text) {
            match layer(&name) {
                Some(l) if l > own => upward.push(format!(
                    "{}:{line}: `{top}` (layer {own}) uses `crate::{name}` (layer {l})",
                    rel.display()
                )),
                Some(_) => {}
                // Re-exports at the crate root (`crate::ConfigError`) sit at the bottom.
                None if name.chars().next().is_some_and(char::is_uppercase) => {}
                None => unknown.push(format!(
                    "{}:{line}: `crate::{name}` is not a known layer",
                    rel.display()
                )),
            }
        }
    }
    assert!(
        unknown.is_empty(),
        "modules without a layer (add them to `layer`):\n{}",
        unknown.join("\n")
    );
    assert!(
        upward.is_empty(),
        "imports from a higher layer:\n{}",
        upward.join("\n")
    );
}

#[test]
fn the_scanner_sees_paths_groups_and_skips_comments() {
    let text = "use crate::sim::Simulator;\n\
                use crate::{config, design::twin};\n\
                // crate::design::twin in a comment\n\
                let x = crate::control::px4::Px4Cascade::new(); // crate::sim in a comment\n\
                let y = subcrate::design;\n";
    let names: Vec<String> = referenced(text).into_iter().map(|(_, n)| n).collect();
    assert_eq!(names, ["sim", "config", "design", "control"]);
}

#[test]
fn roots_do_not_climb() {
    // A top-level module's root file reaching the crate root through `super::` would dodge
    // the scan above.
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut roots: Vec<PathBuf> = std::fs::read_dir(&src)
        .expect("readable src dir")
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
        .collect();
    roots.extend(
        std::fs::read_dir(&src)
            .expect("readable src dir")
            .map(|e| e.expect("dir entry").path().join("mod.rs"))
            .filter(|p| p.exists()),
    );
    for root in roots {
        let text = std::fs::read_to_string(&root).expect("readable source");
        for (i, line) in text.lines().enumerate() {
            let code = line.trim_start();
            if code.starts_with("//") || code.starts_with("use super::*") {
                continue;
            }
            assert!(
                !code.contains("super::"),
                "{}:{}: a top-level module climbs to the crate root",
                root.display(),
                i + 1
            );
        }
    }
}
