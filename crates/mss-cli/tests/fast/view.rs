//! `mss view` as a process: the one line it prints, the token, replay of
//! a run folder, Ctrl-C, and the errors it exits with.

use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Command, Stdio};
use std::time::Duration;

const MSS: &str = env!("CARGO_BIN_EXE_mss");

fn http_status(url: &str) -> u16 {
    let rest = url.strip_prefix("http://").unwrap();
    let (host, path) = rest.split_once('/').unwrap();
    let mut s = std::net::TcpStream::connect(host).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "GET /{path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut reply = String::new();
    let _ = s.read_to_string(&mut reply);
    reply.split_whitespace().nth(1).unwrap().parse().unwrap()
}

/// Starts `mss view ARGS`, reads its address line, checks the token, then
/// sends SIGINT and expects a clean exit.
fn serve_and_stop(args: &[&str]) {
    let mut child = Command::new(MSS)
        .args(["view", "--no-open"])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line
        .trim()
        .strip_prefix("mss view: ")
        .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
        .to_owned();
    assert!(url.starts_with("http://127.0.0.1:"), "{url}");
    assert_eq!(http_status(&url), 200);
    assert_eq!(http_status(url.split('?').next().unwrap()), 403);
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let status = child.wait().unwrap();
    assert!(status.success(), "mss view after Ctrl-C: {status}");
}

#[test]
fn view_prints_its_address_serves_behind_the_token_and_stops_on_ctrl_c() {
    serve_and_stop(&[]);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let run = Command::new(MSS)
        .args(["-q", "--out", out, "run", "--duration", "0.05"])
        .status()
        .unwrap();
    assert!(run.success());
    serve_and_stop(&["--paused", out]);
}

#[test]
fn view_refuses_what_it_cannot_show() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.toml");
    for (args, expected) in [
        (
            vec![missing.to_str().unwrap()],
            "no such scene file or run folder",
        ),
        (vec![dir.path().to_str().unwrap()], "lattice.pvd"),
        (vec!["--host", "localhost"], "invalid value"),
    ] {
        let out = Command::new(MSS)
            .args(["view", "--no-open"])
            .args(&args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}
