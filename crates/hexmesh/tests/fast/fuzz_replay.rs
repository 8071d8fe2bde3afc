//! Replays the fuzz inputs kept in the repository through the loaders, with
//! the fuzz targets' assertions: the seeds (`fuzz/seeds/FORMAT`), the
//! minimized corpora of earlier fuzzing runs (`fuzz/corpus-min/FORMAT`) and
//! every input that once crashed a target (`fuzz/regressions/FORMAT`). Each
//! must load or give a typed error naming the file, one sentence without
//! the parsers' debug text, never panic.

use std::path::PathBuf;

use hexmesh::load::{MeshFormat, load_mesh_bytes};

fn inputs(format: &str) -> Vec<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let mut files = Vec::new();
    for kind in ["seeds", "corpus-min", "regressions"] {
        if let Ok(dir) = std::fs::read_dir(root.join(kind).join(format)) {
            files.extend(dir.filter_map(Result::ok).map(|e| e.path()));
        }
    }
    files.sort();
    files
}

#[test]
fn every_kept_fuzz_input_loads_or_fails_cleanly() {
    let mut raw_messages = std::collections::BTreeSet::new();
    for (name, format) in [
        ("obj", MeshFormat::Obj),
        ("stl", MeshFormat::Stl),
        ("ply", MeshFormat::Ply),
        ("vtk", MeshFormat::Vtk),
    ] {
        let files = inputs(name);
        assert!(!files.is_empty(), "no fuzz inputs for {name}");
        for path in files {
            let bytes = std::fs::read(&path).unwrap();
            match load_mesh_bytes(&bytes, format, "replay") {
                Ok(m) => {
                    let n = m.mesh.vertices.len() as u32;
                    assert!(
                        m.mesh.triangles.iter().flatten().all(|&i| i < n),
                        "{}",
                        path.display()
                    );
                    assert!(m.mesh.vertices.iter().flatten().all(|v| v.is_finite()));
                }
                Err(e) => {
                    let msg = e.to_string();
                    assert!(
                        msg.contains("replay") && !msg.contains('\n'),
                        "{}: {msg}",
                        path.display()
                    );
                    // A sentence, not a parser's state or a Debug dump.
                    for raw in &[
                        "ParseError {",
                        "LineCol",
                        "ParseIntError",
                        "kind: ",
                        "Parse error",
                        "expected one of \"",
                        "Error: error at",
                    ] {
                        if msg.contains(raw) {
                            raw_messages.insert(msg.replace("replay", "FILE"));
                        }
                    }
                }
            }
        }
    }
    assert!(
        raw_messages.is_empty(),
        "messages with a parser's own text:\n{}",
        raw_messages.into_iter().collect::<Vec<_>>().join("\n")
    );
}

/// The label image readers take every kept input, and each one cut short
/// and with single bytes of its header overwritten, returning an image that
/// holds its declared voxels or a one-line error naming the file, within a
/// 64 MiB limit (as the fuzz targets `nifti` and `nrrd` do).
#[test]
fn image_readers_survive_kept_inputs_cuts_and_overwritten_bytes() {
    use hexmesh::image::{ImageFormat, ImageLimits, load_image_bytes};
    let limits = ImageLimits {
        max_bytes: 64 << 20,
    };
    let mut tried = 0;
    for (name, format) in [("nifti", ImageFormat::Nifti), ("nrrd", ImageFormat::Nrrd)] {
        let files = inputs(name);
        assert!(!files.is_empty(), "no fuzz inputs for {name}");
        for path in files {
            let bytes = std::fs::read(&path).unwrap();
            let mut variants = vec![bytes.clone()];
            for cut in (0..bytes.len()).step_by(bytes.len() / 23 + 1) {
                variants.push(bytes[..cut].to_vec());
            }
            for at in (0..bytes.len().min(560)).step_by(3) {
                for value in [0x00, 0xff, bytes[at].wrapping_add(1)] {
                    let mut v = bytes.clone();
                    v[at] = value;
                    variants.push(v);
                }
            }
            for v in variants {
                tried += 1;
                match load_image_bytes(&v, format, "replay", &limits) {
                    Ok(image) => {
                        assert_eq!(image.labels.len(), image.dims.iter().product::<usize>());
                        assert!(image.affine.iter().flatten().all(|x| x.is_finite()));
                    }
                    Err(e) => {
                        let msg = e.to_string();
                        assert!(
                            msg.contains("replay") && !msg.contains('\n'),
                            "{}: {msg}",
                            path.display()
                        );
                    }
                }
            }
        }
    }
    assert!(tried > 1000, "{tried}");
}
