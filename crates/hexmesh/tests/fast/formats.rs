//! The PLY and VTK loaders against files written by other tools (plyfile,
//! meshio; `data/meshes/formats/make_fixtures.py`), and their errors.

use crate::common;

use std::path::PathBuf;

use hexmesh::load::{LoadError, MeshFormat, load_mesh, load_mesh_bytes};
use hexmesh::{Resolution, TriMesh, VoxelizeOptions, voxelize};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/meshes/formats")
        .join(name)
}

fn cells(mesh: &TriMesh, n: u32) -> std::collections::BTreeSet<[i64; 3]> {
    let opts = VoxelizeOptions {
        resolution: Resolution::CellsAlongLongestAxis(n),
        ..Default::default()
    };
    common::cell_keys(&voxelize(mesh, &opts).unwrap().lattice)
}

/// Triangles as corner coordinates, each rotated to start at its smallest
/// corner (which keeps the winding), sorted.
fn triangle_set(m: &TriMesh) -> Vec<[[u64; 3]; 3]> {
    let mut out: Vec<[[u64; 3]; 3]> = m
        .triangles
        .iter()
        .map(|t| {
            let c = t.map(|i| m.vertices[i as usize].map(f64::to_bits));
            let first = (0..3).min_by_key(|&k| c[k]).unwrap_or(0);
            std::array::from_fn(|k| c[(first + k) % 3])
        })
        .collect();
    out.sort_unstable();
    out
}

#[test]
fn every_format_of_the_bunny_is_the_same_surface_and_the_same_cells() {
    let obj = common::bunny();
    let reference = cells(&obj, 20);
    for name in [
        "bunny_ascii.ply",
        "bunny_le.ply",
        "bunny_be.ply",
        "bunny_legacy_ascii.vtk",
        "bunny_legacy_binary.vtk",
        "bunny.vtu",
    ] {
        let loaded = load_mesh(&fixture(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        let m = &loaded.mesh;
        assert_eq!(m.vertices.len(), obj.vertices.len(), "{name}");
        // The OBJ reader numbers vertices by first use, the others as stored:
        // compare triangles by their corners' coordinates (the writers store
        // doubles, so the points are the same numbers).
        assert_eq!(triangle_set(m), triangle_set(&obj), "{name}");
        assert_eq!(cells(m, 20), reference, "{name}: different cells");
    }
}

#[test]
fn a_tetrahedral_volume_mesh_gives_its_boundary() {
    let loaded = load_mesh(&fixture("box_tets.vtu")).unwrap();
    let m = &loaded.mesh;
    // 4 x 2 x 2 cubes: boundary 2 * (8 + 8 + 4) squares, 2 triangles each.
    assert_eq!(m.triangles.len(), 80);
    common::assert_closed_oriented(&m.triangles);
    assert!((m.signed_volume() - 0.2 * 0.1 * 0.1).abs() < 1e-15);
    let bx = hexmesh::generate::box_mesh([0.0; 3], [0.2, 0.1, 0.1]);
    assert_eq!(cells(m, 8), cells(&bx, 8));
}

const HEADER: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n\
                      property float y\nproperty float z\nelement face 4\n\
                      property list uchar int vertex_indices\nend_header\n";
const BODY: &str = "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n";

fn ply_err(text: &str) -> LoadError {
    load_mesh_bytes(text.as_bytes(), MeshFormat::Ply, "t.ply").unwrap_err()
}

#[test]
fn ply_binary_and_ascii_agree_and_lists_of_any_type_load() {
    let ascii = format!("{HEADER}{BODY}");
    let a = load_mesh_bytes(ascii.as_bytes(), MeshFormat::Ply, "a.ply").unwrap();
    assert!((a.mesh.signed_volume() - 1.0 / 6.0).abs() < 1e-7);
    for big in [false, true] {
        let mut b = HEADER
            .replace(
                "ascii",
                if big {
                    "binary_big_endian"
                } else {
                    "binary_little_endian"
                },
            )
            .replace("float", "double")
            .replace("uchar int", "ushort uint")
            .into_bytes();
        let f = |x: f64| {
            if big {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            }
        };
        for p in [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ] {
            for c in p {
                b.extend(f(c));
            }
        }
        for t in [[0u32, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]] {
            b.extend(if big {
                3u16.to_be_bytes()
            } else {
                3u16.to_le_bytes()
            });
            for i in t {
                b.extend(if big {
                    i.to_be_bytes()
                } else {
                    i.to_le_bytes()
                });
            }
        }
        let m = load_mesh_bytes(&b, MeshFormat::Ply, "b.ply").unwrap();
        assert_eq!(m.mesh, a.mesh, "big endian {big}");
        // Cut the payload short: an error, not a panic or a shorter mesh.
        let err = load_mesh_bytes(&b[..b.len() - 3], MeshFormat::Ply, "b.ply").unwrap_err();
        assert!(err.to_string().contains("b.ply"), "{err}");
    }
}

#[test]
fn bad_ply_files_are_typed_errors_naming_file_and_line() {
    // The header promises more faces than there are.
    let err = ply_err(&format!("{}{BODY}", HEADER.replace("face 4", "face 7")));
    assert!(
        matches!(err, LoadError::Parse { line: Some(_), .. }),
        "{err:?}"
    );
    assert!(err.to_string().contains("t.ply"), "{err}");
    // ... or fewer vertices than the faces use.
    let err = ply_err(&format!(
        "{}{}",
        HEADER.replace("vertex 4", "vertex 3"),
        BODY.replacen("0 0 1\n", "", 1)
    ));
    assert!(
        matches!(
            err,
            LoadError::IndexOutOfRange {
                index: 3,
                vertices: 3,
                ..
            }
        ),
        "{err:?}"
    );
    // An unknown property type, on its header line.
    let err = ply_err(&HEADER.replace("property float y", "property quaternion y"));
    match &err {
        LoadError::Parse { line: Some(5), .. } => {}
        other => panic!("{other:?}"),
    }
    // NaN coordinates: not a number in ASCII (a parse error on its line) ...
    let err = ply_err(&format!("{HEADER}{}", BODY.replacen("1 0 0", "nan 0 0", 1)));
    assert!(
        matches!(err, LoadError::Parse { line: Some(11), .. }),
        "{err:?}"
    );
    // ... and a non-finite value in binary.
    let mut b = HEADER.replace("ascii", "binary_little_endian").into_bytes();
    for c in [
        0.0f32,
        0.0,
        0.0,
        f32::NAN,
        0.0,
        0.0,
        0.0,
        1.0,
        0.0,
        0.0,
        0.0,
        1.0,
    ] {
        b.extend(c.to_le_bytes());
    }
    for t in [[0i32, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]] {
        b.push(3);
        for i in t {
            b.extend(i.to_le_bytes());
        }
    }
    let err = load_mesh_bytes(&b, MeshFormat::Ply, "t.ply").unwrap_err();
    assert!(
        matches!(err, LoadError::NonFinite { vertex: 1, .. }),
        "{err:?}"
    );
    // Text that is not a number, with its line (header of 9 lines, then vertex 2).
    let err = ply_err(&format!(
        "{HEADER}{}",
        BODY.replacen("1 0 0", "1 zero 0", 1)
    ));
    assert!(
        matches!(err, LoadError::Parse { line: Some(11), .. }),
        "{err:?}"
    );
    // Negative indices, no faces, no coordinates, not a PLY file at all.
    for (text, needle) in [
        (
            format!("{HEADER}{}", BODY.replacen("3 0 2 1", "3 0 -2 1", 1)),
            "negative",
        ),
        (
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
             property float z\nend_header\n0 0 0\n"
                .to_owned(),
            "no \"face\"",
        ),
        (HEADER.replace("property float z\n", ""), "no \"z\""),
        ("solid x\n".to_owned(), "starts with"),
        (
            HEADER.replace("format ascii", "format binary_middle_endian"),
            "t.ply",
        ),
    ] {
        let err = ply_err(&text).to_string();
        assert!(
            err.contains(needle) && err.contains("t.ply"),
            "{needle}: {err}"
        );
    }
    // A count far beyond the file's size is an error, not an allocation.
    let err = ply_err(&format!(
        "{}{BODY}",
        HEADER.replace("vertex 4", "vertex 4000000000000")
    ));
    assert!(err.to_string().contains("t.ply"), "{err}");
}

#[test]
fn bad_vtk_files_are_typed_errors() {
    let good = "# vtk DataFile Version 4.2\nt\nASCII\nDATASET POLYDATA\nPOINTS 4 double\n\
                0 0 0\n1 0 0\n0 1 0\n0 0 1\nPOLYGONS 4 16\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n";
    let m = load_mesh_bytes(good.as_bytes(), MeshFormat::Vtk, "t.vtk").unwrap();
    assert!((m.mesh.signed_volume() - 1.0 / 6.0).abs() < 1e-15);
    for (text, needle) in [
        (good.replace("3 1 2 3", "3 1 2 9"), "vertex 9"),
        (good.replace("POINTS 4", "POINTS 40"), "t.vtk"),
        (good.replace("POINTS 4", "POINTS 400000000000"), "t.vtk"),
        (good.replace("POLYGONS 4 16", "POLYGONS 9 16"), "t.vtk"),
        (good.replace("0 1 0\n", "0 nan 0\n"), "t.vtk"),
        (
            good.replace("DATASET POLYDATA", "DATASET STRUCTURED_POINTS"),
            "t.vtk",
        ),
        ("hello".to_owned(), "neither"),
        (
            "<?xml version=\"1.0\"?><VTKFile type=\"Unstruct".to_owned(),
            "t.vtk",
        ),
    ] {
        let err = load_mesh_bytes(text.as_bytes(), MeshFormat::Vtk, "t.vtk")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(needle) && err.contains("t.vtk"),
            "{needle}: {err}"
        );
    }
    // XML: malformed or truncated files, with the line.
    let vtu = std::fs::read_to_string(fixture("box_tets.vtu")).unwrap();
    let cut = &vtu[..vtu.len() / 2];
    let swapped = vtu.replacen("</Points>", "</Pionts>", 1);
    for (text, needle) in [
        (cut, "the file ends inside <"),
        (swapped.as_str(), "malformed XML"),
    ] {
        match load_mesh_bytes(text.as_bytes(), MeshFormat::Vtk, "t.vtu").unwrap_err() {
            LoadError::Parse {
                line: Some(l),
                message,
                ..
            } => assert!(l > 1 && message.contains(needle), "{l}: {message}"),
            other => panic!("{needle}: {other:?}"),
        }
    }
    // ASCII files: the line and the value at fault, also in version 5 files.
    let v5 = std::fs::read_to_string(fixture("bunny_legacy_ascii.vtk")).unwrap();
    let mut lines: Vec<&str> = v5.lines().collect();
    lines[3689] = "3 4 q";
    let v5_bad = lines.join("\n");
    for (text, line, needle) in [
        (
            good.replace("POINTS 4", "POINTS 40"),
            10,
            "\"POLYGONS\" is not a number",
        ),
        (
            good.replace("1 0 0\n", "1 x 0\n"),
            7,
            "\"x\" is not a number",
        ),
        (
            good.replace("POLYGONS 4 16", "POLYGONS 4 26"),
            14,
            "ends 10 cell entries short",
        ),
        (
            good.replace("POLYGONS", "POLYGONES"),
            10,
            "where a section keyword is due",
        ),
        (
            v5_bad,
            3690,
            "\"q\" is not a number (11022 connectivity entries",
        ),
    ] {
        match load_mesh_bytes(text.as_bytes(), MeshFormat::Vtk, "t.vtk").unwrap_err() {
            LoadError::Parse {
                line: Some(l),
                message,
                ..
            } => assert!(l == line && message.contains(needle), "{l}: {message}"),
            other => panic!("{needle}: {other:?}"),
        }
    }
}
