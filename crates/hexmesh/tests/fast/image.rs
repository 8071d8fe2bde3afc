//! Label images: the committed fixtures written by nibabel and pynrrd
//! (`data/images/make_images.py`) read as those tools read them, bad input
//! refused with a typed error naming the file and the field, and label
//! volumes resampled to lattices whose volume, labels and surface match the
//! shapes they hold.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use hexmesh::image::{
    ImageError, ImageFormat, ImageLimits, ImageVoxelizeOptions, LabelImage, Space, load_image,
    load_image_bytes, resample,
};
use hexmesh::{Placement, Resolution};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/images/fixtures")
}

fn expected() -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(fixtures().join("expected.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn every_fixture_reads_as_nibabel_and_pynrrd_read_it() {
    let entries = expected();
    assert!(entries.len() >= 60, "{} fixtures", entries.len());
    for e in &entries {
        let file = e["file"].as_str().unwrap();
        let image = load_image(&fixtures().join(file), &ImageLimits::default())
            .unwrap_or_else(|err| panic!("{file}: {err}"));
        let dims: Vec<usize> = e["dims"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| d.as_u64().unwrap() as usize)
            .collect();
        assert_eq!(image.dims.to_vec(), dims, "{file}");
        let counts: BTreeMap<i32, usize> = image.label_counts();
        let want: BTreeMap<i32, usize> = e["counts"]
            .as_object()
            .unwrap()
            .iter()
            .map(|(k, v)| (k.parse().unwrap(), v.as_u64().unwrap() as usize))
            .collect();
        assert_eq!(counts, want, "{file}");
        for probe in e["probes"].as_array().unwrap() {
            let index: Vec<usize> = probe["index"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_u64().unwrap() as usize)
                .collect();
            let ijk = [index[0], index[1], index[2]];
            assert_eq!(
                image.label(ijk) as i64,
                probe["label"].as_i64().unwrap(),
                "{file} {ijk:?}"
            );
            let world = image.voxel_to_world(ijk.map(|v| v as f64));
            for (axis, w) in probe["world"].as_array().unwrap().iter().enumerate() {
                let w = w.as_f64().unwrap();
                // NIfTI-1 stores its transform in single precision.
                assert!(
                    (world[axis] - w).abs() < 1e-5 * (1.0 + w.abs()),
                    "{file} {ijk:?}: {world:?} against {}",
                    probe["world"]
                );
            }
        }
        let space = match e["space"].as_str().unwrap() {
            "RAS" => Space::Ras,
            "LPS" => Space::Lps,
            _ => Space::Other("voxel grid".into()),
        };
        assert_eq!(image.space, space, "{file}");
        if file.starts_with("nifti") && !file.contains("no_transform") {
            assert_eq!(image.unit_metres, Some(1e-3), "{file}");
        }
    }
}

fn read_error(bytes: &[u8], format: ImageFormat) -> String {
    match load_image_bytes(bytes, format, "bad.img", &ImageLimits::default()) {
        Ok(image) => panic!("accepted: {:?}", image.dims),
        Err(e) => {
            let text = e.to_string();
            assert!(text.starts_with("bad.img"), "{text}");
            assert!(!text.contains("{ "), "debug text in {text}");
            text
        }
    }
}

fn nifti1_bytes() -> Vec<u8> {
    std::fs::read(fixtures().join("nifti1_i2_le.nii")).unwrap()
}

fn set_i16(bytes: &mut [u8], at: usize, v: i16) {
    bytes[at..at + 2].copy_from_slice(&v.to_le_bytes());
}

fn set_f32(bytes: &mut [u8], at: usize, v: f32) {
    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

#[test]
fn bad_nifti_headers_get_typed_errors_naming_the_field() {
    let good = nifti1_bytes();
    // Truncated in the header and in the data.
    let e = read_error(&good[..200], ImageFormat::Nifti);
    assert!(e.contains("header"), "{e}");
    let e = read_error(&good[..good.len() - 3], ImageFormat::Nifti);
    assert!(e.contains("voxel data") && e.contains("280"), "{e}");
    // A zero-sized dimension.
    let mut b = good.clone();
    set_i16(&mut b, 42, 0);
    let e = read_error(&b, ImageFormat::Nifti);
    assert!(e.contains("dim[1] = 0"), "{e}");
    // Too many dimensions for a label volume.
    let mut b = good.clone();
    set_i16(&mut b, 40, 4);
    set_i16(&mut b, 48, 3);
    let e = read_error(&b, ImageFormat::Nifti);
    assert!(e.contains("dim[4] = 3"), "{e}");
    // A header that lies about its size: far more voxels than the file has
    // fails on the file's length, before any voxel is read ...
    let mut b = good.clone();
    for at in [42, 44, 46] {
        set_i16(&mut b, at, 1000);
    }
    let e = read_error(&b, ImageFormat::Nifti);
    assert!(e.contains("header declares"), "{e}");
    // ... and past the memory limit it is refused outright.
    let e = match load_image_bytes(
        &b,
        ImageFormat::Nifti,
        "bad.img",
        &ImageLimits { max_bytes: 1 << 30 },
    ) {
        Err(e @ ImageError::TooLarge { .. }) => e.to_string(),
        other => panic!("{other:?}"),
    };
    assert!(e.contains("limit"), "{e}");
    // NaN spacing where the transform needs it (no sform, no qform).
    let mut b = good.clone();
    set_i16(&mut b, 252, 0);
    set_i16(&mut b, 254, 0);
    set_f32(&mut b, 80, f32::NAN);
    let e = read_error(&b, ImageFormat::Nifti);
    assert!(e.contains("pixdim[1] = NaN"), "{e}");
    // A non-finite sform.
    let mut b = good.clone();
    set_f32(&mut b, 280, f32::NAN);
    let e = read_error(&b, ImageFormat::Nifti);
    assert!(e.contains("transform"), "{e}");
    // A complex data type, a bad magic, a wrong header size.
    let mut b = good.clone();
    set_i16(&mut b, 70, 32);
    assert!(read_error(&b, ImageFormat::Nifti).contains("datatype = 32"));
    let mut b = good.clone();
    b[344] = b'x';
    assert!(read_error(&b, ImageFormat::Nifti).contains("magic"));
    let mut b = good.clone();
    b[0] = 1;
    assert!(read_error(&b, ImageFormat::Nifti).contains("sizeof_hdr"));
    // Compressed: a stream cut short is a clean error too.
    let gz = std::fs::read(fixtures().join("nifti2_i4_be.nii.gz")).unwrap();
    let e = read_error(&gz[..gz.len() / 2], ImageFormat::Nifti);
    assert!(e.contains("decompress") || e.contains("ends"), "{e}");
}

#[test]
fn dimensions_whose_product_overflows_are_refused_as_too_large() {
    // NIfTI-2 dimensions are 64-bit: 2^40 cubed overflows any count.
    let mut b = std::fs::read(fixtures().join("nifti2_i2_le.nii")).unwrap();
    for axis in 1..=3 {
        let at = 16 + 8 * axis;
        b[at..at + 8].copy_from_slice(&(1i64 << 40).to_le_bytes());
    }
    match load_image_bytes(&b, ImageFormat::Nifti, "huge.nii", &ImageLimits::default()) {
        Err(ImageError::TooLarge { dims, .. }) => assert_eq!(dims, [1 << 40; 3]),
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_compressed_header_that_claims_more_voxels_than_its_stream_holds_costs_only_the_stream() {
    use std::io::Write;
    // 2^10 x 2^10 x 2^8 int32 voxels declared (1 GiB of labels), 100 bytes sent.
    let mut header = nifti1_bytes()[..352].to_vec();
    for (at, v) in [(42, 1024), (44, 1024), (46, 256)] {
        set_i16(&mut header, at, v);
    }
    set_i16(&mut header, 70, 8);
    set_i16(&mut header, 72, 32);
    header.extend([0u8; 100]);
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(&header).unwrap();
    let bytes = gz.finish().unwrap();
    let e = read_error(&bytes, ImageFormat::Nifti);
    assert!(e.contains("ends after 100 bytes"), "{e}");
}

fn nrrd_header(fields: &str) -> Vec<u8> {
    format!("NRRD0004\n{fields}\n").into_bytes()
}

#[test]
fn bad_nrrd_headers_get_typed_errors_naming_the_line_or_field() {
    let base = "type: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n";
    let with_data = |fields: &str, data: &[u8]| {
        let mut b = nrrd_header(fields);
        b.extend(data);
        b
    };
    let ok = with_data(base, &[1; 8]);
    assert!(load_image_bytes(&ok, ImageFormat::Nrrd, "ok.nrrd", &ImageLimits::default()).is_ok());
    let e = read_error(&with_data(base, &[1; 5]), ImageFormat::Nrrd);
    assert!(e.contains("ends after 5 bytes"), "{e}");
    let e = read_error(
        &with_data(&base.replace("2 2 2", "2 0 2"), &[1; 8]),
        ImageFormat::Nrrd,
    );
    assert!(e.contains("sizes = 2 0 2"), "{e}");
    let e = read_error(
        &with_data(&base.replace("2 2 2", "2 2"), &[1; 8]),
        ImageFormat::Nrrd,
    );
    assert!(e.contains("sizes = 2 2"), "{e}");
    let e = read_error(
        &with_data(&format!("{base}spacings: 1 nan 1\n"), &[1; 8]),
        ImageFormat::Nrrd,
    );
    assert!(e.contains("spacings = 1 nan 1"), "{e}");
    let e = read_error(
        &with_data(&base.replace("raw", "bzip2"), &[1; 8]),
        ImageFormat::Nrrd,
    );
    assert!(e.contains("encoding = bzip2"), "{e}");
    let e = read_error(
        &with_data(&format!("{base}a line without a colon\n"), &[1; 8]),
        ImageFormat::Nrrd,
    );
    assert!(e.starts_with("bad.img:6:"), "{e}");
    let e = read_error(b"P6\n2 2\n255\n", ImageFormat::Nrrd);
    assert!(e.contains("not a NRRD file"), "{e}");
    let e = read_error(
        &with_data(&base.replace("2 2 2", "100000 100000 100000"), &[1; 8]),
        ImageFormat::Nrrd,
    );
    assert!(e.contains("limit"), "{e}");
    // Four axes of which one holds several labels per voxel (overlapping
    // segments) is not a label volume.
    let e = read_error(
        &with_data(
            "type: uint8\ndimension: 4\nsizes: 2 2 2 2\nspace: RAS\nspace directions: none (1,0,0) (0,1,0) (0,0,1)\nencoding: raw\n",
            &[1; 16],
        ),
        ImageFormat::Nrrd,
    );
    assert!(e.contains("not spatial"), "{e}");
    // The same with one layer is read, its spatial axes kept.
    let image = load_image_bytes(
        &with_data(
            "type: uint8\ndimension: 4\nsizes: 1 2 3 4\nspace: RAS\nspace directions: none (1,0,0) (0,2,0) (0,0,3)\nencoding: raw\n",
            &[1; 24],
        ),
        ImageFormat::Nrrd,
        "layer.nrrd",
        &ImageLimits::default(),
    )
    .unwrap();
    assert_eq!(image.dims, [2, 3, 4]);
    assert_eq!(image.voxel_to_world([1.0, 1.0, 1.0]), [1.0, 2.0, 3.0]);
    // A float voxel that is not a whole number.
    let mut data = Vec::new();
    for v in [0.0f32, 1.0, 2.5, 0.0, 0.0, 0.0, 0.0, 0.0] {
        data.extend(v.to_le_bytes());
    }
    let e = read_error(
        &with_data(&base.replace("uint8", "float"), &data),
        ImageFormat::Nrrd,
    );
    assert!(e.contains("voxel [0, 1, 0] holds 2.5"), "{e}");
}

#[test]
fn lps_and_ras_differ_by_the_sign_of_x_and_y() {
    let path = fixtures().join("nrrd_u1_le_raw.nrrd");
    let lps = load_image(&path, &ImageLimits::default()).unwrap();
    let ras = lps.clone().in_space(&Space::Ras);
    assert_eq!(ras.space, Space::Ras);
    let p = [1.0, 2.0, 3.0];
    let (a, b) = (lps.voxel_to_world(p), ras.voxel_to_world(p));
    assert_eq!([a[0], a[1], a[2]], [-b[0], -b[1], b[2]]);
}

/// A label volume built in memory: `label_at(world point in mm)`, voxels of
/// `spacing` mm turned by `angles` (degrees about z) around `origin`.
fn synthetic(
    dims: [usize; 3],
    spacing: [f64; 3],
    turn_degrees: f64,
    label_at: impl Fn([f64; 3]) -> i32,
) -> LabelImage {
    let (s, c) = turn_degrees.to_radians().sin_cos();
    let affine = [
        [c * spacing[0], -s * spacing[1], 0.0, 3.0],
        [s * spacing[0], c * spacing[1], 0.0, -2.0],
        [0.0, 0.0, spacing[2], 1.0],
    ];
    let mut labels = Vec::with_capacity(dims.iter().product());
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [i as f64, j as f64, k as f64];
                let w = std::array::from_fn(|r| {
                    affine[r][0] * p[0] + affine[r][1] * p[1] + affine[r][2] * p[2] + affine[r][3]
                });
                labels.push(label_at(w));
            }
        }
    }
    LabelImage::new(dims, labels, affine, "synthetic").unwrap()
}

#[test]
fn a_ball_of_anisotropic_turned_voxels_becomes_its_volume_within_a_cell_layer() {
    // A ball of radius 20 mm near the middle of 110 x 110 x 42 voxels of
    // 0.5 x 0.5 x 1.25 mm turned by 30 degrees: it lies well inside.
    let centre = [13.0, 35.0, 26.5];
    let r = 20.0;
    let image = synthetic([110, 110, 42], [0.5, 0.5, 1.25], 30.0, |w| {
        let d2: f64 = (0..3).map(|k| (w[k] - centre[k]).powi(2)).sum();
        (d2 <= r * r) as i32
    });
    let to_m = image.to_metres(1e-3, &Placement::default());
    let exact = 4.0 / 3.0 * std::f64::consts::PI * (r * 1e-3f64).powi(3);
    let area = 4.0 * std::f64::consts::PI * (r * 1e-3f64).powi(2);
    let mut triangles = Vec::new();
    for cells in [8u32, 16, 24] {
        let opts = ImageVoxelizeOptions {
            resolution: Resolution::CellsAlongLongestAxis(cells),
            ..Default::default()
        };
        let out = resample(&image, &to_m, &opts).unwrap();
        let h = out.stats.h;
        let volume = out.lattice.num_cells() as f64 * h.powi(3);
        assert!(
            (volume - exact).abs() <= area * h,
            "{cells} cells: lattice {volume:e} m^3, ball {exact:e}, one layer {:e}",
            area * h
        );
        // The voxels' own volume is the ball's within the voxel layer.
        assert!((out.stats.mesh_volume - exact).abs() < area * 1.25e-3);
        assert!(out.cell_labels.iter().all(|&l| l == 1));
        // The surface is closed, outward, and holds the voxels' volume.
        let surface = &out.surface;
        let mut edges = BTreeMap::new();
        for t in &surface.triangles {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0i32) += if a < b { 1 } else { -1 };
            }
        }
        assert!(
            edges.values().all(|&n| n == 0),
            "an edge is not shared by two opposite triangles"
        );
        triangles.push(surface.triangles.len());
        let v = surface.signed_volume();
        assert!(
            (v - out.stats.mesh_volume).abs() < 0.03 * out.stats.mesh_volume,
            "surface {v:e} voxels {:e}",
            out.stats.mesh_volume
        );
    }
    // Voxels much smaller than the cells give the surface in blocks: fewer
    // triangles for coarser lattices, the volume kept.
    assert!(triangles[0] * 4 < triangles[2], "{triangles:?}");
}

#[test]
fn each_cell_takes_the_label_that_covers_most_of_it() {
    // Two slabs, label 1 for x < 12.5 mm and label 2 beyond, up to 20.5 mm;
    // 1 mm voxels not turned, 2 mm cells (from x = 2.5 mm): every cell is
    // one label's.
    let image = synthetic([18, 8, 8], [1.0, 1.0, 1.0], 0.0, |w| {
        if w[0] < 12.5 { 1 } else { 2 }
    });
    let to_m = image.to_metres(1e-3, &Placement::default());
    let opts = ImageVoxelizeOptions {
        resolution: Resolution::CellSize(2e-3),
        ..Default::default()
    };
    let out = resample(&image, &to_m, &opts).unwrap();
    assert_eq!(out.lattice.num_cells(), 9 * 4 * 4);
    assert_eq!(out.voxels_per_label, vec![(1, 10 * 64), (2, 8 * 64)]);
    for (c, &l) in out.lattice.cell_coords().iter().zip(&out.cell_labels) {
        let x = out.lattice.origin()[0] + (c[0] as f64 + 0.5) * out.stats.h;
        assert_eq!(l, if x < 12.5e-3 { 1 } else { 2 }, "cell {c:?} at x {x}");
    }
    // Choosing one label keeps only its cells.
    let only_two = ImageVoxelizeOptions {
        labels: Some(vec![2]),
        ..opts.clone()
    };
    let out = resample(&image, &to_m, &only_two).unwrap();
    assert_eq!(out.lattice.num_cells(), 4 * 4 * 4);
    assert!(out.cell_labels.iter().all(|&l| l == 2));
    // A label nothing carries is an error, not an empty body.
    let none = ImageVoxelizeOptions {
        labels: Some(vec![7]),
        ..opts
    };
    assert!(resample(&image, &to_m, &none).is_err());
}

#[test]
fn the_bundled_organ_loads_and_resamples() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/images/organ.nii.gz");
    let image = load_image(&path, &ImageLimits::default()).unwrap();
    assert_eq!(image.dims, [72, 56, 30]);
    let counts = image.label_counts();
    assert_eq!(counts.keys().copied().collect::<Vec<_>>(), vec![0, 1, 2, 3]);
    let to_m = image.to_metres(image.unit_metres_or_default(), &Placement::default());
    let opts = ImageVoxelizeOptions {
        labels: Some(vec![1, 2]),
        resolution: Resolution::CellsAlongLongestAxis(16),
        ..Default::default()
    };
    let out = resample(&image, &to_m, &opts).unwrap();
    let per_label: BTreeMap<i32, usize> =
        out.cell_labels.iter().fold(BTreeMap::new(), |mut m, &l| {
            *m.entry(l).or_insert(0) += 1;
            m
        });
    assert_eq!(per_label.keys().copied().collect::<Vec<_>>(), vec![1, 2]);
    let rel = (out.stats.lattice_volume - out.stats.mesh_volume).abs() / out.stats.mesh_volume;
    assert!(
        rel < 0.1,
        "lattice {} voxels {}",
        out.stats.lattice_volume,
        out.stats.mesh_volume
    );
}

/// A 20 x 10 pixel slice (1 mm pixels) of label 1, its right half label 2,
/// with a 4 x 4 hole and one stray pixel.
fn slice_with_hole() -> LabelImage {
    let (nx, ny) = (24usize, 10usize);
    let mut labels = vec![0i32; nx * ny];
    for j in 0..ny {
        for i in 0..20 {
            let hole = (4..8).contains(&i) && (3..7).contains(&j);
            if !hole {
                labels[i + nx * j] = if i >= 10 { 2 } else { 1 };
            }
        }
    }
    labels[23 + nx * 9] = 1; // a stray pixel
    LabelImage {
        dims: [nx, ny, 1],
        labels,
        affine: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 5.0],
        ],
        unit_metres: Some(1e-3),
        space: Space::Other("slice".into()),
        format: ImageFormat::Nrrd,
    }
}

#[test]
fn a_slice_becomes_rectangles_and_the_outline_of_its_pixels() {
    use hexmesh::image::plane::{pixel_outline, resample_plane, slice_to_plane};
    use hexmesh::voxelize::ComponentPolicy;
    let image = slice_with_hole();
    let to_metres = image.to_metres(1e-3, &hexmesh::Placement::default());
    let map = slice_to_plane(&image, &to_metres).unwrap();
    let body = pixel_outline(&image, None, &map).unwrap();
    // The shape, its hole and the stray pixel; corners only.
    assert_eq!(body.outline.polygons().len(), 3);
    let mut sizes: Vec<usize> = body.outline.polygons().iter().map(Vec::len).collect();
    sizes.sort_unstable();
    assert_eq!(sizes, [4, 4, 4]);
    assert!(
        (body.outline.area() - 185e-6).abs() < 1e-15,
        "{}",
        body.outline.area()
    );
    assert_eq!(body.pixels_per_label, [(1, 85), (2, 100)]);
    let resampled = |cell: [f64; 2], components| {
        resample_plane(&image, None, &map, &body.outline, cell, 0.5, components).unwrap()
    };
    // Cells of 2 x 1 mm, aligned with the pixels here: every cell is full
    // or empty, the stray pixel is its own group and is dropped.
    let (lattice, labels) = resampled([2e-3, 1e-3], ComponentPolicy::LargestOnly);
    assert_eq!(lattice.num_cells(), 92);
    assert!((lattice.area() - 184e-6).abs() < 1e-15);
    let nodes = lattice.nodes();
    for (cell, &label) in lattice.cells().iter().zip(&labels) {
        let x = cell.iter().map(|&n| nodes[n as usize][0]).sum::<f64>() / 4.0;
        assert_eq!(label, if x > 9.5e-3 { 2 } else { 1 }, "cell at x = {x}");
    }
    // With every group the stray pixel's cell stays; label 2 alone is the
    // right half.
    assert_eq!(
        resampled([2e-3, 1e-3], ComponentPolicy::All).0.num_cells(),
        93
    );
    assert_eq!(
        resampled([1e-3, 1e-3], ComponentPolicy::All).0.num_cells(),
        185
    );
    // The smallest threshold keeps every cell a chosen pixel reaches, and
    // no other (each with a label).
    let (touched, labels) = resample_plane(
        &image,
        None,
        &map,
        &body.outline,
        [3e-3, 3e-3],
        1e-12,
        ComponentPolicy::All,
    )
    .unwrap();
    assert_eq!(labels.len(), touched.num_cells());
    assert!(touched.area() >= 185e-6);
    let right = pixel_outline(&image, Some(&[2]), &map).unwrap();
    assert!((right.outline.area() - 100e-6).abs() < 1e-15);
    // Cells across the pixels: a boundary cell is kept when the pixels
    // cover half of it, so the lattice's area is off by at most about half
    // a cell along the boundary (76 mm long), and converges as cells shrink.
    for cell in [2.7e-3, 1.3e-3, 0.33e-3, 0.1e-3] {
        let (l, _) = resampled([cell, cell], ComponentPolicy::LargestOnly);
        let error = (l.area() - 184e-6).abs();
        assert!(
            error <= 0.5 * 76e-3 * cell + 4.0 * cell * cell,
            "cell {cell}: area {}",
            l.area()
        );
    }
}

#[test]
fn what_is_not_a_slice_in_the_plane_is_refused() {
    use hexmesh::image::plane::{PlaneImageError, pixel_outline, slice_to_plane};
    let mut image = slice_with_hole();
    let turned = hexmesh::Placement {
        rotate_degrees: [90.0, 0.0, 0.0],
        ..hexmesh::Placement::default()
    };
    let e = slice_to_plane(&image, &image.to_metres(1e-3, &turned)).unwrap_err();
    assert!(matches!(e, PlaneImageError::NotInPlane(_)), "{e}");
    assert!(e.to_string().contains("rotate"), "{e}");
    let map = slice_to_plane(&image, &image.to_metres(1e-3, &Default::default())).unwrap();
    let e = pixel_outline(&image, Some(&[7]), &map).unwrap_err();
    assert!(e.to_string().contains("(1, 85)"), "{e}");
    image.dims = [24, 5, 2];
    let e = slice_to_plane(&image, &image.to_metres(1e-3, &Default::default())).unwrap_err();
    assert!(matches!(e, PlaneImageError::NotASlice(2, _)), "{e}");
}

#[test]
fn a_2d_nrrd_with_a_2d_space_reads_as_a_slice() {
    let mut bytes = nrrd_header(
        "type: uint8\ndimension: 2\nsizes: 3 2\nspace dimension: 2\n\
         space directions: (0.5,0) (0,2)\nspace origin: (10,20)\nencoding: raw\n",
    );
    bytes.extend([0, 1, 1, 0, 1, 0]);
    let image = load_image_bytes(
        &bytes,
        ImageFormat::Nrrd,
        "slice.nrrd",
        &ImageLimits::default(),
    )
    .unwrap();
    assert_eq!(image.dims, [3, 2, 1]);
    assert_eq!(image.labels, [0, 1, 1, 0, 1, 0]);
    assert_eq!(image.affine[0], [0.5, 0.0, 0.0, 10.0]);
    assert_eq!(image.affine[1], [0.0, 2.0, 0.0, 20.0]);
    assert_eq!(image.affine[2][3], 0.0);
    let bad = nrrd_header(
        "type: uint8\ndimension: 2\nsizes: 3 2\nspace dimension: 2\n\
         space directions: (0.5,0,0) (0,2,0)\nencoding: raw\n",
    );
    let e = read_error(&bad, ImageFormat::Nrrd);
    assert!(e.contains("2 finite components"), "{e}");
}
