//! ARCHITECTURE.md's rule of each crate is true: every crate's `[dependencies]` name only the
//! mdrlat crates its row of "What each crate may import" lists, and every crate has a row.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The table: crate → the mdrlat crates it may import.
fn allowed(architecture: &str, crates: &BTreeSet<String>) -> BTreeMap<String, BTreeSet<String>> {
    let section = architecture
        .split("## What each crate may import")
        .nth(1)
        .expect("ARCHITECTURE.md has the section 'What each crate may import'");
    let section = section.split("\n## ").next().unwrap_or(section);
    let mut rows = BTreeMap::new();
    for line in section.lines().filter(|l| l.starts_with("| `mdrlat-")) {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let name = cells[1].trim_matches('`').to_string();
        let may: BTreeSet<String> = if cells[2].starts_with("every mdrlat crate but") {
            let except: BTreeSet<&str> = cells[2]
                .trim_start_matches("every mdrlat crate but")
                .split(" and ")
                .map(str::trim)
                .collect();
            crates.iter().filter(|c| **c != name && !except.contains(c.as_str())).cloned().collect()
        } else {
            cells[2]
                .split(',')
                .map(str::trim)
                .filter(|c| c.starts_with("mdrlat-"))
                .map(String::from)
                .collect()
        };
        rows.insert(name, may);
    }
    rows
}

/// The mdrlat crates in a manifest's `[dependencies]` section.
fn imports(manifest: &str) -> BTreeSet<String> {
    let mut in_deps = false;
    let mut out = BTreeSet::new();
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            in_deps = line == "[dependencies]";
            continue;
        }
        if in_deps && line.starts_with("mdrlat-") {
            let name: String =
                line.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '-').collect();
            out.insert(name);
        }
    }
    out
}

#[test]
fn every_crate_imports_only_what_architecture_md_allows() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let architecture =
        std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut manifests = BTreeMap::new();
    for entry in std::fs::read_dir(root.join("crates")).expect("crates/") {
        let dir = entry.expect("entry").path();
        let Ok(manifest) = std::fs::read_to_string(dir.join("Cargo.toml")) else { continue };
        let name = dir.file_name().expect("name").to_string_lossy().into_owned();
        manifests.insert(name, manifest);
    }
    let crates: BTreeSet<String> = manifests.keys().cloned().collect();
    assert!(crates.len() >= 14, "found only {crates:?}");
    let rules = allowed(&architecture, &crates);
    let mut wrong = Vec::new();
    for (name, manifest) in &manifests {
        let Some(may) = rules.get(name) else {
            wrong.push(format!("{name} has no row in ARCHITECTURE.md's table"));
            continue;
        };
        for import in imports(manifest) {
            if !may.contains(&import) {
                wrong.push(format!("{name} imports {import}, which its row does not allow"));
            }
        }
    }
    for name in rules.keys() {
        if !crates.contains(name) {
            wrong.push(format!("ARCHITECTURE.md has a row for {name}, which does not exist"));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    // The checker itself: a manifest importing what its row forbids is caught.
    let fake = "[dependencies]\nmdrlat-nn.workspace = true\n[dev-dependencies]\nmdrlat-eval = 1\n";
    assert_eq!(imports(fake), BTreeSet::from(["mdrlat-nn".to_string()]));
    assert!(!rules["mdrlat-sim"].contains("mdrlat-nn"));
}
