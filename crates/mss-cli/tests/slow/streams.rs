//! Printing never panics: a full standard output or error, a closed pipe;
//! and the output folder's free space is measured for relative folders.

use std::process::{Command, Stdio};

const MSS: &str = env!("CARGO_BIN_EXE_mss");

fn dev_full() -> Option<std::fs::File> {
    std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .ok()
}

#[test]
fn a_full_standard_output_is_an_error_message_not_a_panic() {
    let Some(full) = dev_full() else {
        eprintln!("skipped: no /dev/full here");
        return;
    };
    let out = Command::new(MSS)
        .args(["init", "--help"])
        .stdout(full)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("cannot print to standard output"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");

    let out = Command::new(MSS)
        .args(["check"])
        .stdout(dev_full().unwrap())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("No space left"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn a_full_standard_error_keeps_the_exit_code() {
    let Some(full) = dev_full() else {
        return;
    };
    let status = Command::new(MSS)
        .args(["check", "surely-missing-scene.toml"])
        .stderr(full)
        .stdout(Stdio::null())
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(1));
}

#[test]
fn a_closed_pipe_ends_quietly() {
    let mut child = Command::new(MSS)
        .args(["check"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The reader goes away before `check` has printed anything.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!stderr.contains("error"), "{stderr}");
    assert_eq!(out.status.code(), Some(141), "{stderr}");
}

#[test]
fn the_free_space_of_a_relative_output_folder_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(MSS)
        .args(["check", "--out", "out"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line = stdout
        .lines()
        .find(|l| l.starts_with("output estimate"))
        .unwrap();
    assert!(
        line.contains(" in out (") && line.contains("free)"),
        "{line}"
    );
    assert!(!dir.path().join("out").exists(), "check wrote the folder");
}

#[test]
fn ctrl_c_stops_mss_check_within_a_second() {
    // The template at 20 kPa, whose load check takes seconds (it buckles:
    // the static solve fails increment after increment).
    let dir = tempfile::tempdir().unwrap();
    let template = dir.path().join("soft.toml");
    std::fs::write(
        &template,
        mss_scene::scene::TEMPLATE_SCENE_TOML.replace("young = 1.0e5", "young = 2.0e4"),
    )
    .unwrap();
    let mut child = Command::new(MSS)
        .args(["-q", "check"])
        .arg(&template)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Past the preparation (well under a second), inside the static solve
    // of the load check (seconds on this scene).
    std::thread::sleep(std::time::Duration::from_secs(3));
    if child.try_wait().unwrap().is_some() {
        eprintln!("skipped: the check finished within 3 s on this machine");
        return;
    }
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let asked = std::time::Instant::now();
    let out = child.wait_with_output().unwrap();
    let waited = asked.elapsed();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        waited.as_secs_f64() < 1.5,
        "stopped {waited:?} after Ctrl-C"
    );
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("interrupted"), "{stderr}");
}
