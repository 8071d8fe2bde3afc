//! ARCHITECTURE.md against the workspace as cargo sees it: the table of
//! crate dependencies lists exactly the workspace crates each member
//! depends on (normal dependencies, not dev ones), and every normal
//! dependency of a member is named by that member's own source (a crate
//! depends only on what its source uses).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace root")
        .to_path_buf()
}

struct Member {
    manifest_dir: PathBuf,
    /// Normal dependencies: package name -> the name the source uses.
    dependencies: BTreeMap<String, String>,
}

fn members() -> BTreeMap<String, Member> {
    let out = std::process::Command::new(env!("CARGO"))
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(workspace_root())
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "cargo metadata failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).expect("metadata is JSON");
    let mut members = BTreeMap::new();
    for package in meta["packages"].as_array().expect("packages") {
        let name = package["name"].as_str().expect("name").to_owned();
        let manifest = PathBuf::from(package["manifest_path"].as_str().expect("manifest"));
        let mut dependencies = BTreeMap::new();
        for dep in package["dependencies"].as_array().expect("dependencies") {
            // Normal dependencies have a null kind; build ones would be "build".
            if !dep["kind"].is_null() {
                continue;
            }
            let dep_name = dep["name"].as_str().expect("dependency name").to_owned();
            let used_as = dep["rename"]
                .as_str()
                .map(str::to_owned)
                .unwrap_or_else(|| dep_name.replace('-', "_"));
            dependencies.insert(dep_name, used_as);
        }
        members.insert(
            name,
            Member {
                manifest_dir: manifest.parent().expect("manifest folder").to_path_buf(),
                dependencies,
            },
        );
    }
    members
}

/// The `| crate | workspace dependencies |` table of ARCHITECTURE.md.
fn documented_graph() -> BTreeMap<String, BTreeSet<String>> {
    let text = std::fs::read_to_string(workspace_root().join("ARCHITECTURE.md"))
        .expect("ARCHITECTURE.md is readable");
    let start = text
        .find("<!-- DEPENDENCY-TABLE-START -->")
        .expect("ARCHITECTURE.md marks its dependency table");
    let end = text
        .find("<!-- DEPENDENCY-TABLE-END -->")
        .expect("ARCHITECTURE.md ends its dependency table");
    let mut graph = BTreeMap::new();
    for line in text[start..end].lines().filter(|l| l.starts_with('|')) {
        let cells: Vec<&str> = line.trim_matches('|').split('|').map(str::trim).collect();
        let [krate, deps, ..] = cells[..] else {
            panic!("a table row has two columns: {line}")
        };
        if krate == "crate" || krate.starts_with('-') {
            continue;
        }
        let deps = deps
            .split(',')
            .map(|d| d.trim().trim_matches('`').to_owned())
            .filter(|d| !d.is_empty() && d != "none")
            .collect();
        graph.insert(krate.trim_matches('`').to_owned(), deps);
    }
    graph
}

#[test]
fn the_documented_crate_graph_is_cargos() {
    let members = members();
    let in_workspace: BTreeSet<&String> = members.keys().collect();
    let actual: BTreeMap<String, BTreeSet<String>> = members
        .iter()
        .map(|(name, m)| {
            let deps = m
                .dependencies
                .keys()
                .filter(|d| in_workspace.contains(d))
                .cloned()
                .collect();
            (name.clone(), deps)
        })
        .collect();
    assert_eq!(
        documented_graph(),
        actual,
        "ARCHITECTURE.md's dependency table (left) differs from the manifests (right)"
    );
}

fn source_text(dir: &Path, text: &mut String) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            source_text(&path, text);
        } else if path.extension().is_some_and(|e| e == "rs") {
            text.push_str(&std::fs::read_to_string(&path).unwrap_or_default());
        }
    }
}

#[test]
fn every_normal_dependency_is_used_by_the_crates_own_source() {
    let mut unused = Vec::new();
    for (name, member) in members() {
        let mut text = String::new();
        // The library and binaries; tests, benches and examples use
        // dev-dependencies. The e2e package's library is at its root.
        source_text(&member.manifest_dir.join("src"), &mut text);
        if name == "mss-e2e" {
            source_text(&member.manifest_dir, &mut text);
        }
        for (dep, used_as) in &member.dependencies {
            let named = [
                format!("{used_as}::"),
                format!("use {used_as}"),
                format!("extern crate {used_as}"),
            ]
            .iter()
            .any(|p| text.contains(p.as_str()));
            if !named {
                unused.push(format!("{name} -> {dep}"));
            }
        }
    }
    assert!(
        unused.is_empty(),
        "dependencies that the crate's own source never names: {unused:?}"
    );
}
