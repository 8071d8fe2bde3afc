//! `mss experiment scene`: any scene against the Q1 FEM reference, through the
//! CLI library, on a tiny box; the outputs read back; unsupported loads
//! refused with a message naming them.

use mss_e2e::{box_obj, write};
use vtkio::model::{DataSet, Piece};

/// A 0.2 x 0.05 x 0.05 m bar, 8 cells along x (8 x 2 x 2), clamped at x = 0,
/// under gravity and a downward traction on its free end.
fn scene(extra: &str) -> String {
    format!(
        r#"
[mesh]
path = "box.obj"

[voxelize]
cells = 8

[material]
young = 1.0e5
poisson = 0.3
density = 1.0

[[fixed]]
kind = "face"
face = "x-"

[loads]
gravity = [0.0, 0.0, -9.81]

[[loads.tractions]]
min = [0.2, 0.0, 0.0]
max = [0.2, 0.05, 0.05]
traction = [0.0, 0.0, -1.0]
{extra}
[solver]
kind = "static"
"#
    )
}

#[test]
fn scene_experiment_writes_report_csv_and_vtu() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "box.obj", &box_obj([0.0; 3], [0.2, 0.05, 0.05]));
    let path = write(dir.path(), "scene.toml", &scene(""));
    let out = dir.path().join("out");
    mss_cli::run_with_args([
        "mss",
        "-q",
        "--out",
        out.to_str().unwrap(),
        "experiment",
        "scene",
        &path,
        "--refine",
        "2",
        "--all-models",
    ])
    .unwrap();
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    println!("{report}");
    assert!(report.contains("| model | lattice | h (m) | M % | SD % | MAX % |"));
    assert!(report.contains("small load (linear)"), "auto regime");
    let csv = std::fs::read_to_string(out.join("scene_errors.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 3, "{csv}");
    for (row, model) in rows.iter().zip(["paper", "springs", "volumetric"]) {
        let f: Vec<&str> = row.split(',').collect();
        assert_eq!(f[0], model);
        // The voxelizer's grid has a margin of one cell: 10x4x4 for 8x2x2 cells.
        assert_eq!(f[1], "10x4x4");
        let (m, max): (f64, f64) = (f[3].parse().unwrap(), f[5].parse().unwrap());
        assert!(m > 0.0 && m < 30.0 && max >= m && max < 80.0, "{row}");
    }
    for model in ["paper", "springs", "volumetric"] {
        let p = out.join(format!("scene_{model}.vtu"));
        let vtk = vtkio::Vtk::import(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
            panic!("not an unstructured grid");
        };
        let Piece::Inline(piece) = &pieces[0] else {
            panic!("piece not inline");
        };
        assert_eq!(piece.num_points(), 9 * 3 * 3);
        let names: Vec<String> = piece
            .data
            .point
            .iter()
            .map(|a| a.name().to_owned())
            .collect();
        for want in ["u_mss", "u_fem", "u_mss_minus_fem", "error_percent"] {
            assert!(names.iter().any(|n| n == want), "{want} in {names:?}");
        }
    }
}

#[test]
fn scene_experiment_refuses_a_drag_spring_by_name() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "box.obj", &box_obj([0.0; 3], [0.2, 0.05, 0.05]));
    let drag = "\n[[loads.drags]]\nselect = { kind = \"face\", face = \"x+\" }\ntarget = [0.3, 0.0, 0.0]\nstiffness = 1.0\n";
    let path = write(dir.path(), "scene.toml", &scene(drag));
    let out = dir.path().join("out");
    let err = mss_cli::run_with_args([
        "mss",
        "-q",
        "--out",
        out.to_str().unwrap(),
        "experiment",
        "scene",
        &path,
    ])
    .unwrap_err();
    let msg = format!("{err}");
    println!("{msg}");
    assert!(
        msg.contains("drag spring") && msg.contains("no FEM counterpart"),
        "{msg}"
    );
    assert!(!out.join("report.md").exists());
}
