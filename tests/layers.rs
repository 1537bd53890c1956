//! The module layers, checked from the source: every `crate::m` (library) and `damage_twin::m`
//! (binary) path in `src/**/*.rs` must name a module at a lower layer than the file's own, or its
//! own module. The order lives in `LAYERS` here and in docs/ARCHITECTURE.md's "Layers" line; the
//! test fails when the two disagree.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Bottom first; modules in one entry share a layer and may not use each other.
const LAYERS: &[&[&str]] = &[
    &["simd", "metrics"],
    &["scene"],
    &["synth"],
    &["splats"],
    &["raster"],
    &["gpu"],
    &["train"],
    &["damage"],
    &["segment"],
    &["blocks"],
    &["timeline"],
    &["report"],
    &["studies"],
    &["app", "cli"],
];

/// Edges allowed across the rule, each with its reason: the CLI opens the desktop app, in one
/// file, behind the `app` feature (docs/ARCHITECTURE.md).
const EXCEPTIONS: &[(&str, &str)] = &[("src/cli/launch.rs", "app")];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|layer| layer.contains(&module))
}

/// The layers as docs/ARCHITECTURE.md writes them.
fn layers_line() -> String {
    let names: Vec<String> = LAYERS.iter().map(|layer| layer.join(", ")).collect();
    format!("Layers (each looks only down): {}", names.join(" → "))
}

/// The top module a source file belongs to (`src/train/trainer/mod.rs` → `train`); `None` for
/// the crate roots.
fn module_of(relative: &Path) -> Option<String> {
    let mut parts = relative
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned());
    let first = parts.next()?;
    if first != "src" {
        return None;
    }
    let second = parts.next()?;
    match second.strip_suffix(".rs") {
        Some("lib" | "main") => None,
        Some(stem) => Some(stem.to_string()),
        None => Some(second),
    }
}

/// The modules a file's text names through `crate::` or `damage_twin::`, with `use crate::{a::x,
/// b}` groups opened (across lines). Comments are skipped, so a doc line naming a path is not an
/// edge.
fn named_modules(text: &str) -> BTreeSet<String> {
    let code: String = text
        .lines()
        .map(|line| line.find("//").map_or(line, |at| &line[..at]))
        .collect::<Vec<_>>()
        .join("\n");
    let mut found = BTreeSet::new();
    for root in ["crate::", "damage_twin::"] {
        let mut rest = code.as_str();
        while let Some(at) = rest.find(root) {
            // `damage_twin::` inside another identifier (`my_damage_twin::`) is not ours.
            let before = rest[..at].chars().next_back();
            rest = &rest[at + root.len()..];
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                continue;
            }
            if let Some(group) = rest.strip_prefix('{') {
                found.extend(group_heads(group));
            } else {
                found.insert(identifier(rest).to_string());
            }
        }
    }
    found.retain(|name| !name.is_empty() && name != "self" && name != "super");
    found
}

/// First segments of the paths in a `{a::x, b, c::{…}}` group, up to its closing brace.
fn group_heads(group: &str) -> Vec<String> {
    let mut heads = Vec::new();
    let mut depth = 0usize;
    let mut at_item_start = true;
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => break,
            '}' => depth -= 1,
            ',' if depth == 0 => at_item_start = true,
            c if at_item_start && depth == 0 && !c.is_whitespace() => {
                heads.push(identifier(&group[i..]).to_string());
                at_item_start = false;
            }
            _ => {}
        }
    }
    heads
}

fn identifier(text: &str) -> &str {
    let end = text
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(text.len());
    &text[..end]
}

/// Every edge that looks up the layers, as `file → module` lines.
fn violations(files: &[(PathBuf, String)]) -> Vec<String> {
    let mut bad = Vec::new();
    for (path, text) in files {
        let Some(own) = module_of(path) else { continue };
        let Some(own_layer) = layer_of(&own) else {
            bad.push(format!("{}: module `{own}` is in no layer", path.display()));
            continue;
        };
        for named in named_modules(text) {
            if named == own {
                continue;
            }
            let Some(named_layer) = layer_of(&named) else {
                continue;
            };
            let allowed = named_layer < own_layer
                || EXCEPTIONS
                    .iter()
                    .any(|&(file, to)| Path::new(file) == path.as_path() && to == named);
            if !allowed {
                bad.push(format!("{} → {named}", path.display()));
            }
        }
    }
    bad
}

fn rust_files(dir: &Path, root: &Path, out: &mut Vec<(PathBuf, String)>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|entry| entry.expect("a directory entry reads").path())
        .collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            rust_files(&path, root, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let relative = path
                .strip_prefix(root)
                .expect("under the root")
                .to_path_buf();
            out.push((relative, text));
        }
    }
}

#[test]
fn every_module_looks_only_down_the_layers() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), root, &mut files);
    assert!(files.len() > 100, "found only {} source files", files.len());
    let bad = violations(&files);
    assert!(bad.is_empty(), "edges up the layers:\n{}", bad.join("\n"));
}

#[test]
fn architecture_page_states_the_same_layers() {
    let page = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/ARCHITECTURE.md");
    let text = std::fs::read_to_string(&page).expect("docs/ARCHITECTURE.md reads");
    let line = layers_line();
    assert!(
        text.contains(&line),
        "docs/ARCHITECTURE.md should contain the line\n{line}"
    );
}

#[test]
fn an_upward_import_is_caught() {
    let files = vec![
        (
            PathBuf::from("src/scene/open.rs"),
            "use crate::{files::open_regular, splats::Splats};\n// crate::train in a comment\n"
                .to_string(),
        ),
        (
            PathBuf::from("src/train/run.rs"),
            "use crate::raster::Render;\nlet x = crate::timeline::Twin::open(p);\n".to_string(),
        ),
        (
            PathBuf::from("src/cli/launch.rs"),
            "use damage_twin::app::run;\n".to_string(),
        ),
        (
            PathBuf::from("src/cli/train.rs"),
            "use damage_twin::app::run;\n".to_string(),
        ),
        (
            PathBuf::from("src/damage/mod.rs"),
            "use crate::{\n    scene::Camera,\n    timeline::Twin,\n};\n".to_string(),
        ),
    ];
    assert_eq!(
        violations(&files),
        vec![
            "src/scene/open.rs → splats".to_string(),
            "src/train/run.rs → timeline".to_string(),
            "src/cli/train.rs → app".to_string(),
            "src/damage/mod.rs → timeline".to_string(),
        ]
    );
}
