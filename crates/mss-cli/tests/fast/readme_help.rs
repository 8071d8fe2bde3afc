//! The command reference in the workspace README (between `<!-- HELP-START -->`
//! and `<!-- HELP-END -->`) is generated from the binary's `--help` output.
//! This test fails when it is stale; regenerate it with
//!
//!     UPDATE_README=1 cargo test --release -p mss-cli --test fast readme_help

use std::path::Path;
use std::process::Command;

const MSS: &str = env!("CARGO_BIN_EXE_mss");
const START: &str = "<!-- HELP-START -->\n";
const END: &str = "<!-- HELP-END -->";

/// The generated section: `mss --help`, then `mss <command> --help` for
/// every command, each as a `text` block.
fn generated() -> String {
    let mut parts = Vec::new();
    for cmd in [
        &[][..],
        &["run"],
        &["voxelize"],
        &["check"],
        &["init"],
        &["experiment"],
        &["view"],
    ] {
        let out = Command::new(MSS)
            .args(cmd)
            .arg("--help")
            .output()
            .expect("run mss --help");
        assert!(out.status.success(), "mss {cmd:?} --help failed");
        let text = String::from_utf8(out.stdout).expect("UTF-8 help");
        let title = std::iter::once("mss")
            .chain(cmd.iter().copied())
            .chain(std::iter::once("--help"))
            .collect::<Vec<_>>()
            .join(" ");
        parts.push(format!(
            "### `{title}`\n\n```text\n{}\n```\n",
            text.trim_end()
        ));
    }
    parts.join("\n")
}

#[test]
fn readme_help_section_is_generated_from_the_binary() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md");
    let readme = std::fs::read_to_string(&path).expect("read README.md");
    let a = readme.find(START).expect("HELP-START marker") + START.len();
    let b = readme.find(END).expect("HELP-END marker");
    let want = generated();
    if readme[a..b] == want {
        return;
    }
    if std::env::var_os("UPDATE_README").is_some() {
        let updated = format!("{}{want}{}", &readme[..a], &readme[b..]);
        std::fs::write(&path, updated).expect("write README.md");
        return;
    }
    panic!(
        "README.md's help section is stale: run `UPDATE_README=1 cargo test --release -p mss-cli --test fast readme_help`"
    );
}
