//! Process-level tests of the `mss` binary: exit codes, the one-line error on
//! stderr, no panic, and no file left under a final output name, for a table
//! of bad inputs; plus the bundled default scene through `check` and `run`.
//!
//! They live here rather than in the workspace's `tests/` package because
//! `env!("CARGO_BIN_EXE_mss")` (the path of the built binary, which Cargo
//! builds before these tests) only exists in the package that defines the bin.

use std::path::{Path, PathBuf};
use std::process::Command;

const MSS: &str = env!("CARGO_BIN_EXE_mss");

/// A closed box surface, outward-wound (12 triangles).
fn box_obj(min: [f64; 3], max: [f64; 3]) -> String {
    let mut s = String::new();
    for k in 0..8 {
        let x = if k & 1 == 0 { min[0] } else { max[0] };
        let y = if k & 2 == 0 { min[1] } else { max[1] };
        let z = if k & 4 == 0 { min[2] } else { max[2] };
        s.push_str(&format!("v {x} {y} {z}\n"));
    }
    // Faces as quads (1-based), counter-clockwise from outside.
    for q in [
        [1, 3, 4, 2], // z-
        [5, 6, 8, 7], // z+
        [1, 2, 6, 5], // y-
        [3, 7, 8, 4], // y+
        [1, 5, 7, 3], // x-
        [2, 4, 8, 6], // x+
    ] {
        s.push_str(&format!(
            "f {} {} {}\nf {} {} {}\n",
            q[0], q[1], q[2], q[0], q[2], q[3]
        ));
    }
    s
}

/// A valid small scene using `mesh.obj` beside it, with `extra` appended
/// (later keys of the same table must not repeat earlier ones).
fn scene(material: &str, extra: &str) -> String {
    format!("[mesh]\npath = \"mesh.obj\"\n[voxelize]\ncells = 6\n[material]\n{material}\n{extra}")
}

const MATERIAL: &str = "young = 1.0e4\npoisson = 0.3\ndensity = 1000.0";

struct Case {
    name: &'static str,
    files: Vec<(&'static str, Vec<u8>)>,
    args: Vec<&'static str>,
    expect: Vec<&'static str>,
    code: i32,
}

fn case(
    name: &'static str,
    files: Vec<(&'static str, Vec<u8>)>,
    args: &[&'static str],
    expect: &[&'static str],
) -> Case {
    Case {
        name,
        files,
        args: args.to_vec(),
        expect: expect.to_vec(),
        code: 1,
    }
}

fn text(name: &'static str, s: impl Into<String>) -> (&'static str, Vec<u8>) {
    (name, s.into().into_bytes())
}

fn good_mesh() -> (&'static str, Vec<u8>) {
    text("mesh.obj", box_obj([0.0; 3], [0.1, 0.05, 0.05]))
}

/// Scene + good mesh, run with `mss run scene.toml --out out`.
fn scene_case(name: &'static str, scene_text: String, expect: &[&'static str]) -> Case {
    case(
        name,
        vec![text("scene.toml", scene_text), good_mesh()],
        &["run", "scene.toml", "--out", "out"],
        expect,
    )
}

/// Bad mesh bytes under `file`, run through a scene that names it.
fn mesh_case(
    name: &'static str,
    file: &'static str,
    bytes: Vec<u8>,
    expect: &[&'static str],
) -> Case {
    let scene = format!("[mesh]\npath = \"{file}\"\n[material]\n{MATERIAL}\n");
    case(
        name,
        vec![("scene.toml", scene.into_bytes()), (file, bytes)],
        &["run", "scene.toml", "--out", "out"],
        expect,
    )
}

fn truncated_stl() -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b.extend_from_slice(&10u32.to_le_bytes());
    b.extend_from_slice(&[0u8; 50 * 3]);
    b
}

fn cases() -> Vec<Case> {
    let fixed_floor = "[[fixed]]\nkind = \"face\"\nface = \"x-\"\n";
    vec![
        case(
            "missing scene file",
            vec![],
            &["run", "nope.toml", "--out", "out"],
            &["nope.toml"],
        ),
        scene_case(
            "unknown key",
            scene(MATERIAL, "colour = 3\n"),
            &[
                "scene.toml:",
                "unknown field `colour`",
                "expected one of",
                "`young`",
            ],
        ),
        scene_case(
            "unknown key in [solver]",
            scene(MATERIAL, "[solver]\ndurration = 1.0\n"),
            &["unknown field `durration`", "`duration`"],
        ),
        scene_case(
            "unknown table",
            scene(MATERIAL, "[physics]\ng = 9.81\n"),
            &["unknown field `physics`", "`loads`"],
        ),
        scene_case(
            "wrong value type",
            scene("young = \"soft\"\npoisson = 0.3\ndensity = 1000.0", ""),
            &["scene.toml:6:", "invalid type"],
        ),
        scene_case(
            "TOML syntax error",
            "[mesh\npath = 1\n".into(),
            &["scene.toml:1:"],
        ),
        scene_case(
            "missing material",
            "[mesh]\npath = \"mesh.obj\"\n".into(),
            &["missing field `material`"],
        ),
        scene_case(
            "nu = 0.5",
            scene(
                "young = 1.0e4\npoisson = 0.5\ndensity = 1000.0",
                fixed_floor,
            ),
            &["Poisson", "0.5"],
        ),
        scene_case(
            "negative E",
            scene(
                "young = -1.0e4\npoisson = 0.3\ndensity = 1000.0",
                fixed_floor,
            ),
            &["Young", "-10000"],
        ),
        scene_case(
            "zero density",
            scene("young = 1.0e4\npoisson = 0.3\ndensity = 0.0", fixed_floor),
            &["density"],
        ),
        scene_case(
            "unknown parameterization",
            scene(MATERIAL, "[model]\nparameterization = \"magic\"\n"),
            &["magic", "paper"],
        ),
        scene_case(
            "negative hourglass factor",
            scene(
                MATERIAL,
                "[model]\nparameterization = \"volumetric+hg\"\nhourglass = -1.0\n",
            ),
            &["[model] hourglass", "-1"],
        ),
        scene_case(
            "hourglass control twice",
            scene(MATERIAL, "[model]\nparameterization = \"paper+hg+hg\"\n"),
            &["paper+hg+hg", "paper, springs, volumetric", "+hg"],
        ),
        scene_case(
            "negative duration",
            scene(MATERIAL, "[solver]\nduration = -1.0\n"),
            &["[solver] duration"],
        ),
        scene_case(
            "zero cells",
            "[mesh]\npath = \"mesh.obj\"\n[voxelize]\ncells = 0\n[material]\nyoung = 1e4\n\
             poisson = 0.3\ndensity = 1000.0\n"
                .into(),
            &["[voxelize] cells"],
        ),
        scene_case(
            "bad rule name",
            "[mesh]\npath = \"mesh.obj\"\n[voxelize]\nrule = \"most\"\n[material]\nyoung = 1e4\n\
             poisson = 0.3\ndensity = 1000.0\n"
                .into(),
            &["most", "centre"],
        ),
        scene_case(
            "cell count over the limit",
            "[mesh]\npath = \"mesh.obj\"\n[voxelize]\ncells = 400\nmax_cells = 1000\n\
             [material]\nyoung = 1e4\npoisson = 0.3\ndensity = 1000.0\n"
                .into(),
            &["1000"],
        ),
        scene_case(
            "mesh smaller than one cell",
            "[mesh]\npath = \"mesh.obj\"\n[voxelize]\ncell_size = 1.0\n[material]\nyoung = 1e4\n\
             poisson = 0.3\ndensity = 1000.0\n"
                .into(),
            &["cell"],
        ),
        scene_case(
            "time step far above the stable limit",
            scene(
                MATERIAL,
                &format!("{fixed_floor}[solver]\nkind = \"explicit\"\ndt = 0.1\nduration = 1.0\n"),
            ),
            &["stability limit"],
        ),
        case(
            "check refuses the time step that run refuses",
            vec![
                text(
                    "scene.toml",
                    scene(
                        MATERIAL,
                        &format!("{fixed_floor}[solver]\nkind = \"explicit\"\ndt = 0.1\n"),
                    ),
                ),
                good_mesh(),
            ],
            &["check", "scene.toml"],
            &["stability limit", "1.000e-1 s"],
        ),
        case(
            "unknown solver kind",
            vec![
                text("scene.toml", scene(MATERIAL, "[solver]\nkind = \"rk4\"\n")),
                good_mesh(),
            ],
            &["check", "scene.toml"],
            &["[solver] kind", "rk4", "implicit", "static"],
        ),
        scene_case(
            "deeply nested inline tables",
            "[f]\nx={\n".repeat(2000),
            &["scene.toml:"],
        ),
        Case {
            code: 2,
            ..case(
                "threads beyond reason",
                vec![],
                &["--threads", "100000", "check"],
                &["--threads 100000", "cores"],
            )
        },
        mesh_case(
            "NUL bytes in an OBJ line",
            "nul.obj",
            b"v 0 0 0\nv 1 0 0\n\0\0v 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
                .to_vec(),
            &["nul.obj", "line 3", "NUL byte"],
        ),
        mesh_case(
            "coordinates of 1e300",
            "huge.obj",
            b"v 0 0 0\nv 1e300 0 0\nv 0 1e300 0\nv 0 0 1e300\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
                .to_vec(),
            &["huge.obj", "scale the mesh"],
        ),
        scene_case(
            "static solver, gravity, nothing fixed",
            scene(
                MATERIAL,
                "[loads]\ngravity = [0, 0, -9.81]\n[solver]\nkind = \"static\"\n",
            ),
            &["no node is fixed"],
        ),
        scene_case(
            "fixed box selects no node",
            scene(
                MATERIAL,
                "[[fixed]]\nkind = \"box\"\nmin = [5, 5, 5]\nmax = [6, 6, 6]\n",
            ),
            &["[[fixed]] #1", "selects no node"],
        ),
        scene_case(
            "missing mesh file",
            "[mesh]\npath = \"gone.obj\"\n[material]\nyoung = 1e4\npoisson = 0.3\n\
             density = 1000.0\n"
                .into(),
            &["gone.obj", "does not exist"],
        ),
        scene_case(
            "unknown built-in mesh",
            "[mesh]\npath = \"builtin:dragon\"\n[material]\nyoung = 1e4\npoisson = 0.3\n\
             density = 1000.0\n"
                .into(),
            &["builtin:dragon", "builtin:critter"],
        ),
        case(
            "unwritable output folder",
            vec![
                text("scene.toml", scene(MATERIAL, fixed_floor)),
                good_mesh(),
                text("blocker", "a file, not a folder"),
            ],
            &[
                "run",
                "scene.toml",
                "--out",
                "blocker/out",
                "--duration",
                "0.001",
            ],
            &["blocker"],
        ),
        case(
            "scene is not UTF-8",
            vec![("scene.toml", vec![0xff, 0xfe, 0x00, 0x80])],
            &["run", "scene.toml", "--out", "out"],
            &["UTF-8"],
        ),
        mesh_case(
            "empty mesh file",
            "empty.obj",
            Vec::new(),
            &["empty.obj", "empty"],
        ),
        mesh_case(
            "truncated binary STL",
            "cut.stl",
            truncated_stl(),
            &["cut.stl", "truncated"],
        ),
        mesh_case(
            "binary garbage named .obj",
            "garbage.obj",
            (0..4096u32)
                .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
                .collect(),
            &["garbage.obj"],
        ),
        mesh_case(
            "OBJ index out of range",
            "bad_index.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n".to_vec(),
            &["bad_index.obj"],
        ),
        mesh_case(
            "NaN coordinates",
            "nan.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 nan 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n".to_vec(),
            &["nan.obj"],
        ),
        mesh_case(
            "a single triangle",
            "tri.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".to_vec(),
            &["tri.obj", "zero extent"],
        ),
        mesh_case(
            "a flat square",
            "flat.obj",
            b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n".to_vec(),
            &["flat.obj", "zero extent"],
        ),
        mesh_case(
            "unknown mesh format",
            "mesh.off",
            b"OFF\n3 1 0\n".to_vec(),
            &["mesh.off", "unknown format"],
        ),
        mesh_case(
            "a PLY header that promises more faces than the file has",
            "short.ply",
            b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
              property float z\nelement face 9\nproperty list uchar int vertex_indices\n\
              end_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n"
                .to_vec(),
            &["short.ply", "line"],
        ),
        case(
            "voxelize: missing mesh",
            vec![],
            &["voxelize", "nothing.stl", "--out", "out"],
            &["nothing.stl"],
        ),
        case(
            "voxelize: zero cells",
            vec![good_mesh()],
            &["voxelize", "mesh.obj", "--cells", "0", "--out", "out"],
            &["at least 1"],
        ),
        case(
            "voxelize: negative cell size",
            vec![good_mesh()],
            &["voxelize", "mesh.obj", "--size=-0.1", "--out", "out"],
            &["-0.1"],
        ),
        case(
            "negative --duration",
            vec![
                text("scene.toml", scene(MATERIAL, fixed_floor)),
                good_mesh(),
            ],
            &["run", "scene.toml", "--duration=-1", "--out", "out"],
            &["--duration"],
        ),
        case(
            "init refuses to overwrite",
            vec![text("scene.toml", "keep me")],
            &["init", "scene.toml"],
            &["already exists", "--force"],
        ),
        Case {
            code: 2,
            ..case("unknown option", vec![], &["run", "--bogus"], &["--bogus"])
        },
        Case {
            code: 2,
            ..case(
                "zero threads",
                vec![],
                &["--threads", "0", "check"],
                &["--threads"],
            )
        },
    ]
}

fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(files_under(&p));
            } else {
                out.push(p);
            }
        }
    }
    out
}

/// Paths that are not regular files are refused at once, not read forever.
#[test]
fn device_and_pipe_paths_are_refused_without_hanging() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::os::unix::fs::symlink("/dev/zero", d.join("zero.obj")).unwrap();
    let fifo = d.join("pipe.obj");
    let made = Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success());
    let mut meshes = vec!["zero.obj"];
    if made {
        meshes.push("pipe.obj");
    }
    for mesh in meshes {
        std::fs::write(
            d.join("scene.toml"),
            format!("[mesh]\npath = \"{mesh}\"\n[material]\n{MATERIAL}\n"),
        )
        .unwrap();
        let out = Command::new(MSS)
            .args(["check", "scene.toml"])
            .current_dir(d)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{mesh}: {stderr}");
        assert!(stderr.contains("not a regular file"), "{mesh}: {stderr}");
    }
    if made {
        let out = Command::new(MSS)
            .args(["check", "pipe.obj"])
            .current_dir(d)
            .output()
            .unwrap();
        assert!(String::from_utf8_lossy(&out.stderr).contains("not a regular file"));
    }
}

/// Holding every node is a scene without motion, not a crash.
#[test]
fn every_node_held_runs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("mesh.obj"), box_obj([0.0; 3], [0.1, 0.05, 0.05])).unwrap();
    std::fs::write(
        d.join("scene.toml"),
        scene(
            MATERIAL,
            "[[fixed]]\nkind = \"box\"\nmin = [-1, -1, -1]\nmax = [1, 1, 1]\n\
             [loads]\ngravity = [0, 0, -9.81]\n[solver]\nduration = 0.001\n",
        ),
    )
    .unwrap();
    for args in [
        vec!["check", "scene.toml"],
        vec!["-q", "run", "scene.toml", "--out", "out"],
    ] {
        let out = Command::new(MSS)
            .args(&args)
            .current_dir(d)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

#[test]
fn bad_inputs_fail_with_one_line_errors_and_leave_no_files() {
    let cases = cases();
    assert!(cases.len() >= 25, "{} cases", cases.len());
    let mut failures = Vec::new();
    for c in &cases {
        let dir = tempfile::tempdir().unwrap();
        for (name, bytes) in &c.files {
            std::fs::write(dir.path().join(name), bytes).unwrap();
        }
        let before = files_under(dir.path());
        let out = Command::new(MSS)
            .args(&c.args)
            .current_dir(dir.path())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        let mut problems = Vec::new();
        if out.status.code() != Some(c.code) {
            problems.push(format!(
                "exit code {:?}, expected {}",
                out.status.code(),
                c.code
            ));
        }
        if stderr.contains("panicked") {
            problems.push("panicked".into());
        }
        let lines: Vec<&str> = stderr.lines().collect();
        if lines.len() != 1 || !lines[0].starts_with("error: ") {
            problems.push("stderr is not one line `error: ...`".into());
        }
        for e in &c.expect {
            if !stderr.contains(e) {
                problems.push(format!("stderr lacks {e:?}"));
            }
        }
        let after = files_under(dir.path());
        let new: Vec<_> = after.iter().filter(|p| !before.contains(p)).collect();
        if !new.is_empty() {
            problems.push(format!("left files {new:?}"));
        }
        if !problems.is_empty() {
            failures.push(format!(
                "{}: {} -- stderr: {stderr}",
                c.name,
                problems.join("; ")
            ));
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

#[test]
fn verbose_error_shows_the_chain_of_causes() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(MSS)
        .args(["-v", "run", "missing.toml"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.starts_with("error: "), "{stderr}");
    assert!(stderr.contains("missing.toml"), "{stderr}");
}

#[test]
fn help_and_version_succeed() {
    for args in [
        &["--help"][..],
        &["--version"],
        &["run", "--help"],
        &["init", "--help"],
    ] {
        let out = Command::new(MSS).args(args).output().unwrap();
        assert!(out.status.success(), "{args:?}");
        assert!(!out.stdout.is_empty(), "{args:?}");
    }
}

#[test]
fn bundled_default_scene_checks_and_runs() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(MSS)
        .args(["check"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("stable time step"), "{stdout}");
    assert!(files_under(dir.path()).is_empty(), "check wrote files");

    let out = Command::new(MSS)
        .args(["run", "--out", "tmp", "--duration", "0.01"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for needle in [
        "cells",
        "nodes",
        "springs",
        "time step",
        "steps",
        "wall time",
        "peak memory",
        "max displacement",
        "tmp",
    ] {
        assert!(stdout.contains(needle), "summary lacks {needle}: {stdout}");
    }
    let tmp = dir.path().join("tmp");
    assert!(tmp.join("lattice.pvd").is_file());
    assert!(tmp.join("lattice_0000.vtu").is_file());
    // The defaults: the lattice and the embedded surface, one series each.
    assert!(tmp.join("surface.pvd").is_file());
    assert!(tmp.join("surface_0000.vtu").is_file());
    assert!(!tmp.join("skin_0000.obj").exists());
    assert!(
        stdout.contains("open lattice.pvd and surface.pvd in ParaView"),
        "{stdout}"
    );
    assert!(tmp.join("summary.json").is_file());
}

#[test]
fn init_writes_a_template_that_check_accepts() {
    let dir = tempfile::tempdir().unwrap();
    let st = Command::new(MSS)
        .args(["-q", "init", "my.toml"])
        .current_dir(dir.path())
        .status()
        .unwrap();
    assert!(st.success());
    let out = Command::new(MSS)
        .args(["check", "my.toml"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let st = Command::new(MSS)
        .args(["-q", "init", "my.toml", "--force"])
        .current_dir(dir.path())
        .status()
        .unwrap();
    assert!(st.success());
}

/// `mss check` counts the zero-energy modes the held nodes leave: two held
/// nodes leave rigid rotations (warned), a held face leaves none.
#[test]
fn check_warns_about_mechanisms() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("mesh.obj"),
        box_obj([0.0; 3], [1.0, 0.5, 0.5]),
    )
    .unwrap();
    let run_check = |fixed: &str| {
        let path = dir.path().join("s.toml");
        std::fs::write(&path, scene(MATERIAL, fixed)).unwrap();
        let out = Command::new(MSS).arg("check").arg(&path).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let few = run_check("[[fixed]]\nkind = \"indices\"\nnodes = [0, 1]\n");
    assert!(few.contains("zero-energy mode"), "{few}");
    let face = run_check("[[fixed]]\nkind = \"face\"\nface = \"x-\"\n");
    assert!(face.contains("mechanisms       none expected"), "{face}");
}

/// Runs `scene.toml` in `dir` into `out`, sends SIGINT once `marker` is
/// written there, and returns what `mss` printed on stderr (it must exit 1).
fn interrupt_run(dir: &Path, out: &str, marker: &str) -> String {
    let mut child = Command::new(MSS)
        .args(["-q", "run", "scene.toml", "--out", out])
        .current_dir(dir)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while !dir.join(out).join(marker).exists() {
        assert!(
            start.elapsed().as_secs() < 120,
            "the run did not write frames"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let status = child.wait().unwrap();
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    assert_eq!(status.code(), Some(1), "{stderr}");
    stderr
}

/// SIGINT stops a run after the step under way: the frames so far, the state
/// reached and a summary marked interrupted are written, no temporary file is
/// left, and the exit code is 1.
#[test]
fn sigint_finishes_the_frame_and_writes_an_interrupted_summary() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("scene.toml"),
        "[mesh]\npath = \"builtin:critter\"\n[voxelize]\ncells = 20\n[material]\n\
         young = 1.0e5\npoisson = 0.3\ndensity = 1000.0\n[[fixed]]\nkind = \"lowest_layer\"\n\
         [loads]\ngravity = [0, 0, -9.81]\n[solver]\nduration = 1000.0\ndamping = 5.0\n\
         [output]\nevery_steps = 200\n",
    )
    .unwrap();
    let out = d.join("out");
    let stderr = interrupt_run(d, "out", "lattice_0002.vtu");
    assert!(stderr.contains("interrupted"), "{stderr}");
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(summary.contains("\"interrupted\": true"), "{summary}");
    let pvd = std::fs::read_to_string(out.join("lattice.pvd")).unwrap();
    assert!(pvd.trim_end().ends_with("</VTKFile>"), "{pvd}");
    let leftovers: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// A run stopped by SIGINT and continued with `--resume` ends with exactly
/// the files of a run that was never stopped.
#[test]
fn a_run_stopped_by_sigint_resumes_to_the_uninterrupted_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("scene.toml"),
        "[mesh]\npath = \"builtin:critter\"\n[voxelize]\ncells = 12\n[material]\n\
         young = 1.0e5\npoisson = 0.3\ndensity = 1000.0\n[[fixed]]\nkind = \"lowest_layer\"\n\
         [loads]\ngravity = [0, 0, -9.81]\n[solver]\nduration = 20.0\ndamping = 5.0\n\
         [output]\nevery_time = 0.25\npc2 = true\n",
    )
    .unwrap();
    let whole = Command::new(MSS)
        .args(["-q", "run", "scene.toml", "--out", "whole"])
        .current_dir(d)
        .output()
        .unwrap();
    assert!(
        whole.status.success(),
        "{}",
        String::from_utf8_lossy(&whole.stderr)
    );
    let cut = d.join("cut");
    let stderr = interrupt_run(d, "cut", "lattice_0003.vtu");
    assert!(stderr.contains("--resume"), "{stderr}");
    assert!(cut.join("checkpoint.mss").exists());
    let resumed = Command::new(MSS)
        .args(["-q", "run", "scene.toml", "--resume", "cut"])
        .current_dir(d)
        .output()
        .unwrap();
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    let names = |p: &std::path::Path| {
        let mut v: Vec<String> = std::fs::read_dir(p)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        v.sort();
        v
    };
    assert_eq!(names(&cut), names(&d.join("whole")));
    for name in names(&cut) {
        if name == "summary.json" {
            continue;
        }
        assert!(
            std::fs::read(cut.join(&name)).unwrap()
                == std::fs::read(d.join("whole").join(&name)).unwrap(),
            "{name} differs"
        );
    }
    // Nothing is left to resume once the run completed.
    let again = Command::new(MSS)
        .args(["-q", "run", "scene.toml", "--resume", "cut"])
        .current_dir(d)
        .output()
        .unwrap();
    assert_eq!(again.status.code(), Some(1));
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(
        err.starts_with("error: ") && err.contains("cannot resume") && err.lines().count() == 1,
        "{err}"
    );
}

/// `mss voxelize MESH` writes into a folder of its own named after the mesh,
/// and says when the mesh is implausibly large for a soft body (a mesh in
/// millimetres read as metres), naming the flags that fix it.
#[test]
fn voxelize_writes_its_own_folder_and_hints_at_units() {
    let dir = tempfile::tempdir().unwrap();
    let bunny = concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/meshes/bunny.obj");
    let out = Command::new(MSS)
        .args(["voxelize", bunny, "--cells", "8"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(dir.path().join("bunny_lattice/stats.json").exists());
    assert!(!dir.path().join("out").exists());
    assert!(
        stderr.contains("large for a soft body") && stderr.contains("--units"),
        "{stderr}"
    );
    // In centimetres it is 9.7 cm: no hint.
    let out = Command::new(MSS)
        .args([
            "voxelize", bunny, "--cells", "8", "--units", "cm", "--up", "y",
        ])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(!stderr.contains("large for a soft body"), "{stderr}");
}

/// `mss voxelize IMAGE` resamples a label image: its own folder named
/// without the image's extensions, the `label` cell field, and the labels'
/// voxels and cells in stats.json; flags that only place meshes are refused.
#[test]
fn voxelize_takes_a_label_image() {
    let dir = tempfile::tempdir().unwrap();
    let organ = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../data/images/organ.nii.gz"
    );
    let out = Command::new(MSS)
        .args(["voxelize", organ, "--labels", "1,2", "--cells", "12"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let folder = dir.path().join("organ_lattice");
    let stats: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("stats.json")).unwrap()).unwrap();
    let labels: Vec<i64> = stats["image"]["cells_per_label"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p[0].as_i64().unwrap())
        .collect();
    assert_eq!(labels, vec![1, 2]);
    assert_eq!(stats["image"]["dims"], serde_json::json!([72, 56, 30]));
    let lattice = std::fs::read_to_string(folder.join("lattice.vtu")).unwrap();
    assert!(lattice.contains("Name=\"label\""));
    for (args, wanted) in [
        (&["--scale", "2"][..], "--scale"),
        (&["--rule", "any"], "--rule any"),
        (&["--labels", "9"], "no voxel carries the labels [9]"),
    ] {
        let out = Command::new(MSS)
            .args(["voxelize", organ, "--cells", "8"])
            .args(args)
            .current_dir(dir.path())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(wanted), "{args:?}: {stderr}");
    }
}
