//! Command-line mistakes get one line that says what to type instead.

use std::process::Command;

const MSS: &str = env!("CARGO_BIN_EXE_mss");

fn stderr_of(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(MSS).args(args).output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn mistakes_get_suggestions_and_the_right_help() {
    let (code, e) = stderr_of(&[]);
    assert_eq!(code, Some(2));
    assert!(
        e.contains("Usage: mss") && e.contains("no subcommand given"),
        "{e}"
    );
    assert!(!e.contains("error: Hexahedral"), "{e}");
    for (args, wanted) in [
        (
            &["runn"][..],
            &["a similar subcommand exists: 'run'", "`mss --help`"][..],
        ),
        (
            &["run", "--duraton", "1"],
            &["'--duration'", "`mss run --help`"],
        ),
        (&["check", "--bogus"], &["'--bogus'", "`mss check --help`"]),
        (&["voxelize"], &["<MESH>", "`mss voxelize --help`"]),
    ] {
        let (code, e) = stderr_of(args);
        assert_eq!(code, Some(2), "{args:?}");
        assert_eq!(e.trim().lines().count(), 1, "{args:?}: {e}");
        for w in wanted {
            assert!(e.contains(w), "{args:?}: {e}");
        }
        assert!(!e.contains("to pass"), "{e}");
    }
}
