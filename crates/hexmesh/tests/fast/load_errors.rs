//! Every malformed input gives its typed error, and never a panic; valid
//! ASCII/binary STL variants load.

use std::path::Path;

use hexmesh::{LoadError, MeshFormat, load_mesh, load_mesh_bytes};

fn binary_stl(header: &[u8], tris: &[[[f32; 3]; 3]], declared: u32) -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b[..header.len()].copy_from_slice(header);
    b.extend_from_slice(&declared.to_le_bytes());
    for t in tris {
        b.extend_from_slice(&[0u8; 12]);
        for v in t {
            for c in v {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        b.extend_from_slice(&[0, 0]);
    }
    b
}

const TET: [[[f32; 3]; 3]; 4] = [
    [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
    [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
    [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]],
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
];

const ASCII_TET: &str = "solid
facet normal 0 0 -1
 outer loop
  vertex 0 0 0
  vertex 0 1 0
  vertex 1 0 0
 endloop
endfacet
facet normal 0 -1 0
 outer loop
  vertex 0 0 0
  vertex 1 0 0
  vertex 0 0 1
 endloop
endfacet
facet normal -1 0 0
 outer loop
  vertex 0 0 0
  vertex 0 0 1
  vertex 0 1 0
 endloop
endfacet
facet normal 1 1 1
 outer loop
  vertex 1 0 0
  vertex 0 1 0
  vertex 0 0 1
 endloop
endfacet
endsolid
";

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn malformed_files_give_typed_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut truncated = binary_stl(b"", &TET, 4);
    truncated.truncate(84 + 50 * 2 + 10);
    let mut garbage = Vec::new();
    let mut x: u32 = 12345;
    for _ in 0..4000 {
        x = x.wrapping_mul(1664525).wrapping_add(1013904223);
        garbage.push((x >> 24) as u8);
    }
    type Check = fn(&LoadError) -> bool;
    let cases: Vec<(&str, Vec<u8>, Check)> = vec![
        ("empty.obj", vec![], |e| {
            matches!(e, LoadError::Empty { .. })
        }),
        ("empty.stl", vec![], |e| {
            matches!(e, LoadError::Empty { .. })
        }),
        ("truncated.stl", truncated, |e| {
            matches!(e, LoadError::TruncatedStl { triangles: 4, .. })
        }),
        ("garbage.stl", garbage.clone(), |e| {
            matches!(e, LoadError::TruncatedStl { .. } | LoadError::Parse { .. })
        }),
        ("garbage.obj", garbage, |e| {
            matches!(e, LoadError::Parse { .. } | LoadError::NoTriangles { .. })
        }),
        (
            "words.obj",
            b"hello world\nthis is not a mesh\n".to_vec(),
            |e| matches!(e, LoadError::NoTriangles { .. }),
        ),
        (
            "badvertex.obj",
            b"v 0 0 0\nv 1 zero 0\nv 0 1 0\nf 1 2 3\n".to_vec(),
            |e| matches!(e, LoadError::Parse { line: Some(2), .. }),
        ),
        (
            "nan.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 nan 1\nv 0 0 1\nf 1 2 3\nf 1 2 4\n".to_vec(),
            |e| matches!(e, LoadError::NonFinite { vertex: 2, .. }),
        ),
        (
            "inf.stl",
            {
                let mut t = TET;
                t[1][2][0] = f32::INFINITY;
                binary_stl(b"", &t, 4)
            },
            |e| matches!(e, LoadError::NonFinite { .. }),
        ),
        (
            "range.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n".to_vec(),
            |e| {
                matches!(
                    e,
                    LoadError::Parse { line: Some(4), .. } | LoadError::IndexOutOfRange { .. }
                )
            },
        ),
        (
            "points.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 1\np 1 2\nl 1 2 3\n".to_vec(),
            |e| matches!(e, LoadError::NoTriangles { .. }),
        ),
        (
            "degenerate.obj",
            b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n".to_vec(),
            |e| matches!(e, LoadError::NoTriangles { dropped: 2, .. }),
        ),
        (
            "flat.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n".to_vec(),
            |e| matches!(e, LoadError::ZeroExtent { axis: "z", .. }),
        ),
        ("mesh.off", b"OFF\n".to_vec(), |e| {
            matches!(e, LoadError::UnknownFormat { .. })
        }),
        (
            "ascii_bad.stl",
            b"solid x\nfacet normal 0 0 1\n outer loop\n  vertex 0 0\n".to_vec(),
            |e| matches!(e, LoadError::Parse { .. }),
        ),
    ];
    for (name, bytes, check) in cases {
        let path = write(d, name, &bytes);
        let err = load_mesh(&path).expect_err(name);
        assert!(check(&err), "{name}: unexpected error {err:?}");
        let msg = err.to_string();
        assert!(
            msg.contains(name),
            "{name}: message does not name the file: {msg}"
        );
    }
    let missing = d.join("missing.obj");
    let err = load_mesh(&missing).unwrap_err();
    assert!(matches!(err, LoadError::Io { .. }) && err.to_string().contains("missing.obj"));
}

#[test]
fn stl_variants_load() {
    // Binary whose header starts with "solid": content decides.
    let b = binary_stl(b"solid but binary", &TET, 4);
    let m = load_mesh_bytes(&b, MeshFormat::Stl, "bin.stl").unwrap();
    assert_eq!(m.mesh.triangles.len(), 4);
    assert_eq!(m.mesh.vertices.len(), 4);
    assert_eq!(m.report.vertices_read, 12);
    assert_eq!(m.report.vertices_welded, 8);
    assert!((m.mesh.signed_volume() - 1.0 / 6.0).abs() < 1e-9);
    // ASCII whose first line is exactly "solid", with Unix and Windows line ends.
    for text in [ASCII_TET.to_string(), ASCII_TET.replace('\n', "\r\n")] {
        let a = load_mesh_bytes(text.as_bytes(), MeshFormat::Stl, "ascii.stl").unwrap();
        assert_eq!(a.mesh.triangles.len(), 4);
        assert_eq!(a.mesh.vertices, m.mesh.vertices);
        assert_eq!(a.mesh.triangles, m.mesh.triangles);
    }
    // OBJ with quads, groups and a line element.
    let obj = "o a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\ng q\nf 1 4 3 2\nl 1 5\no b\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n";
    let m = load_mesh_bytes(obj.as_bytes(), MeshFormat::Obj, "pyramid.obj").unwrap();
    assert_eq!(m.mesh.triangles.len(), 6);
    assert!((m.mesh.signed_volume() - 1.0 / 3.0).abs() < 1e-12);
}

#[test]
fn weld_tolerance_merges_near_duplicates() {
    let raw = hexmesh::TriMesh {
        vertices: vec![
            [0.0; 3],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1e-9, 0.0, 0.0],
            [0.0, 0.0, 1.0],
        ],
        triangles: vec![[0, 1, 2], [3, 2, 4]],
    };
    let exact = hexmesh::load::clean_mesh(raw.clone(), 0.0, "t").unwrap();
    assert_eq!(exact.report.vertices_welded, 0);
    let near = hexmesh::load::clean_mesh(raw, 1e-6, "t").unwrap();
    assert_eq!(near.report.vertices_welded, 1);
    assert_eq!(near.mesh.triangles[1], [0, 2, 3]);
}

/// Custom formats plug in through the registry.
#[test]
fn registered_loader_serves_its_extension() {
    struct Tri;
    impl hexmesh::MeshLoader for Tri {
        fn extensions(&self) -> &[&str] {
            &["tri3"]
        }
        fn load(&self, _bytes: &[u8], _name: &str) -> Result<hexmesh::TriMesh, LoadError> {
            Ok(hexmesh::generate::box_mesh([0.0; 3], [1.0; 3]))
        }
    }
    let mut loaders = hexmesh::load::Loaders::default();
    loaders.register(std::sync::Arc::new(Tri));
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "x.tri3", b"anything");
    assert_eq!(loaders.load(&p).unwrap().mesh.triangles.len(), 12);
    // The default set is not changed by registering into another value.
    assert!(
        load_mesh(&p)
            .unwrap_err()
            .to_string()
            .contains("obj, ply, stl, vtk, vtp, vtu")
    );
}
