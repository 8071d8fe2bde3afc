//! Frame writing speed for a 64^3 lattice (262 144 cells, 274 625 nodes) with
//! two vector point fields, per format, plus vtkio's own XML writer for
//! comparison (the reason `.vtu` is written by this crate).
//!
//! `cargo bench -p mss-io --bench write`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use mss_io::vtk::{Field, LatticeFrame, LegacyFormat, VtuEncoding, write_legacy_vtk, write_vtu};
use std::hint::black_box;

struct Data {
    points: Vec<[f64; 3]>,
    cells: Vec<[u32; 8]>,
    displacement: Vec<[f64; 3]>,
    velocity: Vec<[f64; 3]>,
}

fn data() -> Data {
    let lattice = hexmesh::Lattice::block([64, 64, 64], 0.01, [0.0; 3]).expect("lattice");
    // Smooth but not constant fields, like a deforming body: realistic for
    // compression (constant data would compress unrealistically well).
    let displacement: Vec<[f64; 3]> = lattice
        .nodes()
        .iter()
        .map(|p| {
            [
                1e-3 * (7.0 * p[2]).sin(),
                2e-4 * p[0] * p[1],
                -1e-3 * p[2] * p[2],
            ]
        })
        .collect();
    let velocity: Vec<[f64; 3]> = displacement
        .iter()
        .map(|u| [u[1] * 3.1, -u[0] * 1.7, u[2] * 0.3])
        .collect();
    let points = lattice
        .nodes()
        .iter()
        .zip(&displacement)
        .map(|(p, u)| [p[0] + u[0], p[1] + u[1], p[2] + u[2]])
        .collect();
    Data {
        points,
        cells: lattice.cells().to_vec(),
        displacement,
        velocity,
    }
}

fn vtkio_model(d: &Data) -> vtkio::Vtk {
    use vtkio::model::*;
    let n = d.cells.len();
    Vtk {
        version: Version::new_xml(1, 0),
        byte_order: ByteOrder::LittleEndian,
        title: String::new(),
        file_path: None,
        data: DataSet::inline(UnstructuredGridPiece {
            points: d.points.as_flattened().to_vec().into(),
            cells: Cells {
                cell_verts: VertexNumbers::XML {
                    connectivity: d
                        .cells
                        .as_flattened()
                        .iter()
                        .map(|&i| u64::from(i))
                        .collect(),
                    offsets: (1..=n as u64).map(|k| 8 * k).collect(),
                },
                types: vec![CellType::Hexahedron; n],
            },
            data: Attributes {
                point: vec![
                    Attribute::vectors("displacement")
                        .with_data(d.displacement.as_flattened().to_vec()),
                    Attribute::vectors("velocity").with_data(d.velocity.as_flattened().to_vec()),
                ],
                cell: vec![],
            },
        }),
    }
}

fn bench(c: &mut Criterion) {
    let d = data();
    let frame = LatticeFrame::new(&d.points, &d.cells)
        .with_point_field(Field::vectors("displacement", &d.displacement))
        .with_point_field(Field::vectors("velocity", &d.velocity));
    // Raw payload: 3 float vectors per node + Int64 connectivity and offsets
    // + one type byte per cell.
    let raw_bytes = (3 * 24 * d.points.len() + (8 * 8 + 8 + 1) * d.cells.len()) as u64;
    let dir = tempfile::tempdir().expect("tempdir");

    let mut g = c.benchmark_group("frame_64cubed");
    g.sample_size(10);
    g.throughput(Throughput::Bytes(raw_bytes));
    for (name, enc) in [
        ("vtu_zlib", VtuEncoding::Base64Zlib),
        ("vtu_base64", VtuEncoding::Base64),
    ] {
        let path = dir.path().join(format!("{name}.vtu"));
        g.bench_function(name, |b| {
            b.iter(|| write_vtu(black_box(&path), black_box(&frame), enc).expect("write"))
        });
        let size = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        eprintln!("{name}: file size {:.1} MB", size as f64 / 1e6);
    }
    let path = dir.path().join("legacy.vtk");
    g.bench_function("legacy_binary", |b| {
        b.iter(|| write_legacy_vtk(&path, &frame, LegacyFormat::Binary, "bench").expect("write"))
    });
    for (name, compressor, level) in [
        ("vtkio_xml_zlib", vtkio::xml::Compressor::ZLib, 1),
        ("vtkio_xml_base64", vtkio::xml::Compressor::None, 0),
    ] {
        let path = dir.path().join(format!("{name}.vtu"));
        g.bench_function(name, |b| {
            b.iter(|| {
                let file = vtkio_model(&d)
                    .try_into_xml_format(compressor, level)
                    .expect("convert");
                file.export(&path).expect("export");
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
