//! Write-then-read round trips: `.vtu` (every encoding) and legacy `.vtk`
//! (ASCII and binary) read back with vtkio, `.pvd` parsed back, OBJ read with
//! tobj (and parsed exactly), binary STL read with stl_io.

use mss_io::IoError;
use mss_io::exporters::Exporters;
use mss_io::skin::{SkinFrames, vertex_normals, write_obj, write_stl};
use mss_io::vtk::{
    ComputedValues, Field, LatticeFrame, LegacyFormat, VtuEncoding, write_legacy_vtk,
    write_lines_vtu, write_vtu,
};
use std::collections::HashMap;
use std::path::Path;
use vtkio::model::{Attribute, CellType, DataSet, Piece};

/// What a reader recovered from a file.
struct ReadBack {
    points: Vec<f64>,
    /// Legacy layout: `n i_1 .. i_n` per cell.
    cells: Vec<u32>,
    types: Vec<CellType>,
    point_data: HashMap<String, Vec<f64>>,
    cell_data: HashMap<String, Vec<f64>>,
}

fn attributes(attrs: Vec<Attribute>) -> HashMap<String, Vec<f64>> {
    attrs
        .into_iter()
        .map(|a| match a {
            Attribute::DataArray(d) => (d.name, d.data.cast_into::<f64>().expect("numeric")),
            Attribute::Field { name, .. } => panic!("unexpected field attribute {name}"),
        })
        .collect()
}

fn read_back(path: &Path) -> ReadBack {
    let vtk = vtkio::Vtk::import(path).unwrap_or_else(|e| panic!("{}: {e:?}", path.display()));
    let DataSet::UnstructuredGrid { mut pieces, .. } = vtk.data else {
        panic!("not an unstructured grid");
    };
    assert_eq!(pieces.len(), 1);
    let Piece::Inline(piece) = pieces.remove(0) else {
        panic!("piece not inline");
    };
    let piece = *piece;
    ReadBack {
        points: piece.points.cast_into::<f64>().expect("points"),
        cells: piece.cells.cell_verts.into_legacy().1,
        types: piece.cells.types,
        point_data: attributes(piece.data.point),
        cell_data: attributes(piece.data.cell),
    }
}

/// A small lattice with fields whose values exercise number formatting:
/// irrational-looking values, a subnormal, huge and negative numbers.
struct Sample {
    points: Vec<[f64; 3]>,
    cells: Vec<[u32; 8]>,
    displacement: Vec<[f64; 3]>,
    velocity: Vec<[f64; 3]>,
    fixed: Vec<bool>,
    strain: Vec<f64>,
    ids: Vec<u32>,
    labels: Vec<i32>,
}

fn sample() -> Sample {
    let lattice = hexmesh::Lattice::block([3, 2, 2], 0.1, [0.25, -1.0, 3.0]).unwrap();
    let n = lattice.num_nodes();
    let displacement: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let x = i as f64;
            [
                (0.7 * x).sin() * 1e-3,
                -(x * 1.3).cos() / 3.0,
                x.sqrt() * 1e-7,
            ]
        })
        .collect();
    let mut velocity: Vec<[f64; 3]> = displacement
        .iter()
        .map(|u| [u[1], 2.0 * u[0], -u[2] * 1e12])
        .collect();
    velocity[0] = [5e-324, -1.5e300, 0.1 + 0.2];
    let points = lattice
        .nodes()
        .iter()
        .zip(&displacement)
        .map(|(p, u)| [p[0] + u[0], p[1] + u[1], p[2] + u[2]])
        .collect();
    let m = lattice.num_cells();
    Sample {
        points,
        cells: lattice.cells().to_vec(),
        displacement,
        velocity,
        fixed: (0..n).map(|i| i % 3 == 0).collect(),
        strain: (0..m)
            .map(|c| (c as f64 + 0.5).ln() * 1e-4 - 1e-5)
            .collect(),
        ids: (0..m as u32).map(|c| c * 1000 + 7).collect(),
        labels: (0..m as i32).map(|c| (c - 5) * 100_003).collect(),
    }
}

fn frame(s: &Sample) -> LatticeFrame<'_> {
    LatticeFrame::new(&s.points, &s.cells)
        .with_point_field(Field::vectors("displacement", &s.displacement))
        .with_point_field(Field::vectors("velocity", &s.velocity))
        .with_point_field(Field::flags("fixed", &s.fixed))
        .with_cell_field(Field::scalars("strain", &s.strain))
        .with_cell_field(Field::ids("cell_id", &s.ids))
        .with_cell_field(Field::labels("label", &s.labels))
}

/// Compares bit for bit: the ASCII writers print the shortest digits that
/// parse back to the same `f64`, so even text files round-trip exactly.
fn check(s: &Sample, r: &ReadBack) {
    assert_eq!(r.points.len(), 3 * s.points.len());
    assert_eq!(r.points, s.points.as_flattened());
    assert_eq!(r.types.len(), s.cells.len());
    assert!(r.types.iter().all(|&t| t == CellType::Hexahedron));
    let expected_cells: Vec<u32> = s
        .cells
        .iter()
        .flat_map(|c| std::iter::once(8).chain(c.iter().copied()))
        .collect();
    assert_eq!(r.cells, expected_cells);
    assert_eq!(r.point_data.len(), 3);
    assert_eq!(r.point_data["displacement"], s.displacement.as_flattened());
    assert_eq!(r.point_data["velocity"], s.velocity.as_flattened());
    let fixed: Vec<f64> = s.fixed.iter().map(|&b| f64::from(u8::from(b))).collect();
    assert_eq!(r.point_data["fixed"], fixed);
    assert_eq!(r.cell_data.len(), 3);
    assert_eq!(r.cell_data["strain"], s.strain);
    let ids: Vec<f64> = s.ids.iter().map(|&i| f64::from(i)).collect();
    assert_eq!(r.cell_data["cell_id"], ids);
    let labels: Vec<f64> = s.labels.iter().map(|&l| f64::from(l)).collect();
    assert_eq!(r.cell_data["label"], labels);
}

#[test]
fn vtu_round_trips_exactly_in_every_encoding() {
    let s = sample();
    let dir = tempfile::tempdir().unwrap();
    for enc in [
        VtuEncoding::Ascii,
        VtuEncoding::Base64,
        VtuEncoding::Base64Zlib,
    ] {
        let path = dir.path().join(format!("{enc:?}.vtu"));
        write_vtu(&path, &frame(&s), enc).unwrap();
        check(&s, &read_back(&path));
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text.contains("vtkZLibDataCompressor"),
            enc == VtuEncoding::Base64Zlib
        );
        assert_eq!(text.contains("format=\"ascii\""), enc == VtuEncoding::Ascii);
    }
}

#[test]
fn compressed_vtu_with_many_blocks_round_trips() {
    // 40^3 nodes * 24 bytes = 1.5 MB per vector array: dozens of 32 KiB blocks,
    // and arrays that are (points: 64000*24 = 46.875 blocks) and are not an
    // exact multiple of the block size.
    let lattice = hexmesh::Lattice::block([39, 39, 39], 0.01, [0.0; 3]).unwrap();
    let points = lattice.nodes();
    let u: Vec<[f64; 3]> = points
        .iter()
        .map(|p| [p[0].sin(), p[1] * p[2], -p[0]])
        .collect();
    // 4096 cells * 8 bytes = exactly one block for the offsets array.
    let lattice2 = hexmesh::Lattice::block([16, 16, 16], 0.01, [0.0; 3]).unwrap();
    let dir = tempfile::tempdir().unwrap();
    for (l, name) in [(&lattice, "a.vtu"), (&lattice2, "b.vtu")] {
        let path = dir.path().join(name);
        let u = &u[..l.num_nodes()];
        let f = LatticeFrame::new(l.nodes(), l.cells()).with_point_field(Field::vectors("u", u));
        write_vtu(&path, &f, VtuEncoding::Base64Zlib).unwrap();
        let r = read_back(&path);
        assert_eq!(r.points, l.nodes().as_flattened());
        assert_eq!(r.point_data["u"], u.as_flattened());
        assert_eq!(r.types.len(), l.num_cells());
    }
}

#[test]
fn legacy_vtk_round_trips_in_ascii_and_binary() {
    let s = sample();
    let dir = tempfile::tempdir().unwrap();
    for format in [LegacyFormat::Ascii, LegacyFormat::Binary] {
        let path = dir.path().join(format!("{format:?}.vtk"));
        write_legacy_vtk(&path, &frame(&s), format, "round\ntrip").unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.starts_with(b"# vtk DataFile Version 4.2\nround trip\n"));
        let kind = if format == LegacyFormat::Ascii {
            "ASCII"
        } else {
            "BINARY"
        };
        assert!(String::from_utf8_lossy(&bytes[..80]).contains(kind));
        check(&s, &read_back(&path));
    }
}

/// Values handed over from a buffer the source refills on every call,
/// as a frame writer computes a derived array when it is written.
struct Recomputed<'a> {
    values: &'a [f64],
    components: usize,
    buffer: std::sync::Mutex<Vec<f64>>,
    calls: std::sync::atomic::AtomicUsize,
    /// Numbers left out of what is handed over (to check the refusal).
    short_by: usize,
    /// Whether it computes any range of entries on its own.
    ranged: bool,
}

impl<'a> Recomputed<'a> {
    fn new(values: &'a [f64], components: usize) -> Self {
        Recomputed {
            values,
            components,
            buffer: std::sync::Mutex::new(Vec::new()),
            calls: std::sync::atomic::AtomicUsize::new(0),
            short_by: 0,
            ranged: false,
        }
    }

    fn ranged(mut self, ranged: bool) -> Self {
        self.ranged = ranged;
        self
    }
}

impl ComputedValues for Recomputed<'_> {
    fn len(&self) -> usize {
        self.values.len() / self.components
    }
    fn num_components(&self) -> usize {
        self.components
    }
    fn with_values(
        &self,
        write: &mut dyn FnMut(&[f64]) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        self.calls
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut buffer = self.buffer.lock().unwrap();
        buffer.clear();
        buffer.extend_from_slice(&self.values[..self.values.len() - self.short_by]);
        write(&buffer)
    }
    fn values_of(&self, entries: std::ops::Range<usize>, out: &mut Vec<f64>) -> bool {
        if !self.ranged {
            return false;
        }
        let c = self.components;
        let end = (entries.end * c).min(self.values.len() - self.short_by);
        out.clear();
        out.extend_from_slice(&self.values[(entries.start * c).min(end)..end]);
        true
    }
}

#[test]
fn computed_fields_write_the_bytes_of_the_same_values_held_in_slices() {
    let s = sample();
    let dir = tempfile::tempdir().unwrap();
    for ranged in [false, true] {
        let displacement = Recomputed::new(s.displacement.as_flattened(), 3).ranged(ranged);
        let strain = Recomputed::new(&s.strain, 1).ranged(ranged);
        let with_computed = || {
            LatticeFrame::new(&s.points, &s.cells)
                .with_point_field(Field::computed("displacement", &displacement))
                .with_point_field(Field::vectors("velocity", &s.velocity))
                .with_point_field(Field::flags("fixed", &s.fixed))
                .with_cell_field(Field::computed("strain", &strain))
                .with_cell_field(Field::ids("cell_id", &s.ids))
                .with_cell_field(Field::labels("label", &s.labels))
        };
        for enc in [
            VtuEncoding::Ascii,
            VtuEncoding::Base64,
            VtuEncoding::Base64Zlib,
        ] {
            let held = dir.path().join(format!("held_{enc:?}.vtu"));
            let lazy = dir.path().join(format!("computed_{enc:?}_{ranged}.vtu"));
            write_vtu(&held, &frame(&s), enc).unwrap();
            write_vtu(&lazy, &with_computed(), enc).unwrap();
            assert_eq!(std::fs::read(&held).unwrap(), std::fs::read(&lazy).unwrap());
        }
        for format in [LegacyFormat::Ascii, LegacyFormat::Binary] {
            let path = dir.path().join(format!("computed_{format:?}.vtk"));
            write_legacy_vtk(&path, &with_computed(), format, "computed").unwrap();
            check(&s, &read_back(&path));
        }
        // Each file asked for each whole computed array once; a ranged
        // source is asked for blocks instead, except by the text and legacy
        // writers.
        let whole_arrays = if ranged { 3 } else { 5 };
        for f in [&displacement, &strain] {
            let calls = f.calls.load(std::sync::atomic::Ordering::Relaxed);
            assert_eq!(calls, whole_arrays);
        }
    }

    // Blocks of 4,096 numbers that start and end inside a 3-vector entry.
    let lattice = hexmesh::Lattice::block([39, 39, 39], 0.01, [0.0; 3]).unwrap();
    let u: Vec<f64> = lattice
        .nodes()
        .as_flattened()
        .iter()
        .map(|p| (p * 37.0).sin())
        .collect();
    let ranged_u = Recomputed::new(&u, 3).ranged(true);
    for enc in [VtuEncoding::Base64, VtuEncoding::Base64Zlib] {
        let held = dir.path().join("big_held.vtu");
        let lazy = dir.path().join("big_ranged.vtu");
        let held_frame = LatticeFrame::new(lattice.nodes(), lattice.cells())
            .with_point_field(Field::vectors("u", u.as_chunks::<3>().0));
        write_vtu(&held, &held_frame, enc).unwrap();
        let lazy_frame = LatticeFrame::new(lattice.nodes(), lattice.cells())
            .with_point_field(Field::computed("u", &ranged_u));
        write_vtu(&lazy, &lazy_frame, enc).unwrap();
        assert_eq!(std::fs::read(&held).unwrap(), std::fs::read(&lazy).unwrap());
    }
    assert_eq!(ranged_u.calls.load(std::sync::atomic::Ordering::Relaxed), 0);

    // A source that hands over fewer numbers than it promised leaves no file.
    for ranged in [false, true] {
        let mut short = Recomputed::new(&s.strain, 1).ranged(ranged);
        short.short_by = 1;
        let bad = LatticeFrame::new(&s.points, &s.cells)
            .with_cell_field(Field::computed("strain", &short));
        for (name, result) in [
            (
                "short.vtu",
                write_vtu(&dir.path().join("short.vtu"), &bad, VtuEncoding::Base64Zlib),
            ),
            (
                "short.vtk",
                write_legacy_vtk(
                    &dir.path().join("short.vtk"),
                    &bad,
                    LegacyFormat::Binary,
                    "x",
                ),
            ),
        ] {
            let err = result.unwrap_err().to_string();
            assert!(err.contains("strain") && err.contains("expected"), "{err}");
            assert!(!dir.path().join(name).exists());
        }
    }
}

#[test]
fn springs_as_lines_round_trip() {
    let points = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 1.0],
    ];
    let lines = [[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]];
    let strain = [0.1, -0.2, 1.0 / 3.0, 0.0, 2e-9];
    let dir = tempfile::tempdir().unwrap();
    for enc in [
        VtuEncoding::Ascii,
        VtuEncoding::Base64,
        VtuEncoding::Base64Zlib,
    ] {
        let path = dir.path().join(format!("springs_{enc:?}.vtu"));
        write_lines_vtu(
            &path,
            &points,
            &lines,
            &[Field::scalars("strain", &strain)],
            enc,
        )
        .unwrap();
        let r = read_back(&path);
        assert_eq!(r.points, points.as_flattened());
        assert!(r.types.iter().all(|&t| t == CellType::Line));
        assert_eq!(r.cells, [2, 0, 1, 2, 1, 2, 2, 2, 3, 2, 3, 0, 2, 0, 2]);
        assert_eq!(r.cell_data["strain"], strain);
    }
    let err = write_lines_vtu(
        &dir.path().join("x.vtu"),
        &points,
        &[[0, 4]],
        &[],
        VtuEncoding::Base64,
    )
    .unwrap_err();
    assert!(err.to_string().contains("point 4"), "{err}");
}

/// Parses the `<DataSet timestep=".." file=".."/>` entries of a `.pvd`.
fn pvd_entries(path: &Path) -> Vec<(f64, String)> {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.starts_with("<?xml"));
    assert!(text.contains("<VTKFile type=\"Collection\""));
    assert!(text.trim_end().ends_with("</VTKFile>"));
    let attr = |line: &str, name: &str| -> String {
        let start = line.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        let len = line[start..].find('"').unwrap();
        line[start..start + len].to_string()
    };
    text.lines()
        .filter(|l| l.trim_start().starts_with("<DataSet "))
        .map(|l| (attr(l, "timestep").parse().unwrap(), attr(l, "file")))
        .collect()
}

#[test]
fn vtu_series_keeps_a_valid_pvd_after_every_frame() {
    let s = sample();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out/nested");
    let mut exporter = Exporters::default().frames("vtu", &out, "run").unwrap();
    assert_eq!(exporter.name(), "vtu");
    let times = [0.0, 0.125, 1.0 / 3.0, 2.5e-7];
    for (k, &t) in times.iter().enumerate() {
        exporter.write_frame(2 * k, t, &frame(&s)).unwrap();
        // As if the run were interrupted here: the .pvd lists every frame so far.
        let entries = pvd_entries(&out.join("run.pvd"));
        assert_eq!(entries.len(), k + 1);
        for (j, (time, file)) in entries.iter().enumerate() {
            assert_eq!(*time, times[j]);
            assert_eq!(file, &format!("run_{:04}.vtu", 2 * j));
            check(&s, &read_back(&out.join(file)));
        }
    }
    // Frame indices must increase.
    let err = exporter.write_frame(6, 9.0, &frame(&s)).unwrap_err();
    assert!(err.to_string().contains("does not follow"), "{err}");
    exporter.finish().unwrap();
    assert_eq!(pvd_entries(&out.join("run.pvd")).len(), times.len());
    // Only the frames and the .pvd: no temporary files left behind.
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), times.len() + 1);
}

#[test]
fn every_frame_exporter_writes_readable_files() {
    let s = sample();
    let dir = tempfile::tempdir().unwrap();
    let exporters = Exporters::default();
    for name in exporters.frame_names() {
        let name = name.as_str();
        let mut e = exporters.frames(name, dir.path(), name).unwrap();
        // "vtu-no-pvd" writes the frames of "vtu", without the collection.
        assert_eq!(e.name(), name.trim_end_matches("-no-pvd"));
        e.write_frame(0, 0.0, &frame(&s)).unwrap();
        e.write_frame(1, 0.5, &frame(&s)).unwrap();
        e.finish().unwrap();
        let ext = if name.starts_with("vtu") {
            "vtu"
        } else {
            "vtk"
        };
        for k in 0..2 {
            check(
                &s,
                &read_back(&dir.path().join(format!("{name}_{k:04}.{ext}"))),
            );
        }
    }
    assert!(dir.path().join("vtu.pvd").exists());
    assert!(!dir.path().join("vtu-no-pvd.pvd").exists());
    match exporters.frames("vtp", dir.path(), "x") {
        Err(IoError::UnknownExporter { known, .. }) => assert!(known.contains("vtu-ascii")),
        other => panic!(
            "expected UnknownExporter, got {:?}",
            other.map(|e| e.name())
        ),
    }
    assert!(exporters.frames("vtu", dir.path(), "a/b").is_err());
}

#[test]
fn invalid_frame_creates_no_file() {
    let s = sample();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.vtu");
    let short = &s.strain[1..];
    let f = LatticeFrame::new(&s.points, &s.cells).with_cell_field(Field::scalars("strain", short));
    let err = write_vtu(&path, &f, VtuEncoding::Base64).unwrap_err();
    assert!(err.to_string().contains("bad.vtu"), "{err}");
    assert!(write_legacy_vtk(&path, &f, LegacyFormat::Binary, "").is_err());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// A closed, consistently wound surface: an irregular octahedron.
fn octahedron() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let p = vec![
        [1.0 / 3.0, 0.0, 0.0],
        [-1.1, 0.0, 0.0],
        [0.0, 0.7, 0.0],
        [0.0, -1.0e-7, 0.0],
        [0.0, 0.0, 2.0f64.sqrt()],
        [0.0, 0.0, -1.5],
    ];
    let t = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    (p, t)
}

#[test]
fn obj_round_trips_with_tobj_and_exactly() {
    let (p, t) = octahedron();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("skin.obj");
    write_obj(&path, &p, &t).unwrap();

    let (models, _) = tobj::load_obj(&path, &tobj::LoadOptions::default()).unwrap();
    assert_eq!(models.len(), 1);
    let mesh = &models[0].mesh;
    assert_eq!(mesh.positions.len(), 3 * p.len());
    assert_eq!(mesh.indices.len(), 3 * t.len());
    // tobj renumbers vertices in order of first use: compare through the
    // indices. With `use_f64` (as hexmesh uses it) the exact values come back.
    let normals = vertex_normals(&p, &t);
    let at = |v: &[f64], i: u32| {
        [
            v[3 * i as usize],
            v[3 * i as usize + 1],
            v[3 * i as usize + 2],
        ]
    };
    for (j, tri) in t.iter().enumerate() {
        for (k, &v) in tri.iter().enumerate() {
            assert_eq!(at(&mesh.positions, mesh.indices[3 * j + k]), p[v as usize]);
            assert_eq!(
                at(&mesh.normals, mesh.normal_indices[3 * j + k]),
                normals[v as usize]
            );
        }
    }
    // Convex surface around the origin: every vertex normal is a unit vector
    // pointing outwards.
    for (q, n) in p.iter().zip(&normals) {
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-12);
        assert!(q[0] * n[0] + q[1] * n[1] + q[2] * n[2] > 0.0);
    }

    // Independently of tobj: the file holds the exact f64 values.
    let text = std::fs::read_to_string(&path).unwrap();
    let exact: Vec<f64> = text
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .flat_map(|l| l.split_whitespace().map(|x| x.parse::<f64>().unwrap()))
        .collect();
    assert_eq!(exact, p.as_flattened());
}

#[test]
fn stl_round_trips_with_stl_io() {
    let (p, t) = octahedron();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("skin.stl");
    write_stl(&path, &p, &t).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert!(!bytes.starts_with(b"solid"));
    assert_eq!(bytes.len(), 84 + 50 * t.len());

    let mesh = stl_io::read_stl(&mut std::fs::File::open(&path).unwrap()).unwrap();
    assert_eq!(mesh.faces.len(), t.len());
    for (face, tri) in mesh.faces.iter().zip(&t) {
        for (&vi, &pi) in face.vertices.iter().zip(tri) {
            assert_eq!(mesh.vertices[vi].0, p[pi as usize].map(|x| x as f32));
        }
        // Unit facet normal, pointing away from the origin (inside).
        let n = face.normal.0;
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-6);
        let c: Vec<f64> = (0..3)
            .map(|k| tri.iter().map(|&i| p[i as usize][k]).sum())
            .collect();
        assert!(c[0] * f64::from(n[0]) + c[1] * f64::from(n[1]) + c[2] * f64::from(n[2]) > 0.0);
    }
}

#[test]
fn skin_exporters_write_every_frame_or_the_last() {
    let (mut p, t) = octahedron();
    let dir = tempfile::tempdir().unwrap();
    let exporters = Exporters::default();
    let mut every = exporters
        .skins("obj", dir.path(), "skin", SkinFrames::Every)
        .unwrap();
    let mut last = exporters
        .skins("stl", dir.path(), "last", SkinFrames::LastOnly)
        .unwrap();
    for k in 0..3 {
        p[4][2] = 1.0 + k as f64;
        every.write_skin(k, k as f64, &p, &t).unwrap();
        last.write_skin(k, k as f64, &p, &t).unwrap();
    }
    every.finish().unwrap();
    last.finish().unwrap();
    for k in 0..3 {
        let (models, _) = tobj::load_obj(
            dir.path().join(format!("skin_{k:04}.obj")),
            &tobj::LoadOptions::default(),
        )
        .unwrap();
        let top = models[0]
            .mesh
            .positions
            .iter()
            .skip(2)
            .step_by(3)
            .fold(f64::MIN, |a, &b| a.max(b));
        assert_eq!(top, 1.0 + k as f64);
    }
    let mesh =
        stl_io::read_stl(&mut std::fs::File::open(dir.path().join("last.stl")).unwrap()).unwrap();
    let top = mesh
        .vertices
        .iter()
        .map(|v| v.0[2])
        .fold(f32::MIN, f32::max);
    assert_eq!(top, 3.0);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 4);
}

/// The surface series (`vtu` skin exporter): triangles and displacements
/// from the first frame read back exactly by vtkio and by the run reader,
/// a `.pvd` listing the frames at their times, and a resumed series that
/// goes on measuring from the first frame on disk.
#[test]
fn surface_vtu_series_round_trips_and_resumes() {
    let (mut p, t) = octahedron();
    let dir = tempfile::tempdir().unwrap();
    let exporters = Exporters::default();
    let facts = exporters.skin_facts("vtu").unwrap();
    assert_eq!(
        (facts.extension, facts.index_extension),
        ("vtu", Some("pvd"))
    );
    let mut series = exporters
        .skins("vtu", dir.path(), "surface", SkinFrames::Every)
        .unwrap();
    series.set_time_decimals(2);
    let lift = |p: &mut Vec<[f64; 3]>, k: usize| p[4][2] = 1.0 + 0.25 * k as f64;
    // Displacements are measured from the first frame written.
    lift(&mut p, 0);
    let rest = p.clone();
    for k in 0..3 {
        lift(&mut p, k);
        series.write_skin(k, 0.1 * k as f64, &p, &t).unwrap();
    }
    series.finish().unwrap();
    // Resumed after frame 1 (frame 2 is written again, as after a restart).
    let mut resumed = exporters
        .skins("vtu", dir.path(), "surface", SkinFrames::Every)
        .unwrap();
    resumed.resume(&[0.0, 0.1]).unwrap();
    resumed.write_skin(2, 0.2, &p, &t).unwrap();
    let times: Vec<f64> = pvd_entries(&dir.path().join("surface.pvd"))
        .into_iter()
        .map(|(time, _)| time)
        .collect();
    assert_eq!(times, [0.0, 0.1, 0.2]);
    for k in 0..3 {
        let path = dir.path().join(format!("surface_{k:04}.vtu"));
        lift(&mut p, k);
        let back = mss_io::vtk::read::read_surface_vtu(&path, 1 << 20).unwrap();
        assert_eq!(back.points, p);
        assert_eq!(back.triangles, t);
        let r = read_back(&path);
        assert!(r.types.iter().all(|&c| c == CellType::Triangle));
        let expected: Vec<f64> = p
            .iter()
            .zip(&rest)
            .flat_map(|(a, b)| [a[0] - b[0], a[1] - b[1], a[2] - b[2]])
            .collect();
        assert_eq!(r.point_data["displacement"], expected, "frame {k}");
    }
    // A lattice frame is not a surface.
    let s = sample();
    let lattice = dir.path().join("lattice.vtu");
    write_vtu(&lattice, &frame(&s), VtuEncoding::Base64Zlib).unwrap();
    let err = mss_io::vtk::read::read_surface_vtu(&lattice, 1 << 20).unwrap_err();
    assert!(err.to_string().contains("not a triangle"), "{err}");
}

#[test]
fn a_frame_whose_compressed_header_lies_is_refused_before_it_is_unpacked() {
    use base64::Engine as _;
    let s = sample();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frame.vtu");
    write_vtu(&path, &frame(&s), VtuEncoding::Base64Zlib).unwrap();
    let read = |p: &Path| mss_io::vtk::read::read_lattice_vtu(p, 1 << 30);
    assert_eq!(read(&path).unwrap().points.len(), s.points.len());
    // The points' header (UInt64 fields: blocks, block size, last block,
    // then each block's compressed size) rewritten to declare a gigabyte.
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("header_type=\"UInt64\""), "{text}");
    let start = text.find("<Points>").unwrap();
    let array = start + text[start..].find("format=\"binary\">").unwrap() + 16;
    let array = array + text[array..].find(|c: char| !c.is_whitespace()).unwrap();
    let engine = base64::engine::general_purpose::STANDARD;
    let honest_len = engine.encode([0u8; 32]).len();
    let mut lie = Vec::new();
    for v in [1024u64, 1 << 20, 1 << 20].into_iter().chain([1u64; 1024]) {
        lie.extend_from_slice(&v.to_le_bytes());
    }
    let forged = format!(
        "{}{}{}",
        &text[..array],
        engine.encode(lie),
        &text[array + honest_len..]
    );
    let bad = dir.path().join("forged.vtu");
    std::fs::write(&bad, forged).unwrap();
    let err = read(&bad).unwrap_err().to_string();
    // The reader names the line of the array's opening tag.
    let tag = text[..array].rfind("<DataArray").unwrap();
    let line = text[..tag].matches('\n').count() + 1;
    assert!(
        err.contains("forged.vtu")
            && err.contains(&format!("line {line}:"))
            && err.contains("compression header"),
        "{err}"
    );
}
