//! Hostile input: every mesh of the fuzz corpora (a fixed sample of the
//! minimized ones), the fuzz seeds' scenes, and compressed VTU files whose
//! headers declare gigabytes, go through the `mss` process under an
//! address-space limit of 1 GB. Each ends with exit code 0, 1 or 2, prints
//! no panic, and never allocates what a header declares: a file that would
//! make the reader allocate a gigabyte aborts the process under the limit,
//! which fails the test.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use base64::Engine as _;

const MSS: &str = env!("CARGO_BIN_EXE_mss");

/// Virtual memory a process may map (KiB): the binary and its threads fit
/// in a fifth of it; a gigabyte allocation does not.
const ADDRESS_SPACE_KIB: u64 = 1_000_000;

/// `mss ARGS` under the address-space limit, with `--max-memory 256MiB`.
fn mss_bounded(args: &[&str], dir: &Path) -> Output {
    mss_bounded_plus(args, dir, 0)
}

/// Address space that the dense kernels of the direct solver (faer's
/// `private-gemm-x86`) reserve, untouched, in a thread that first uses
/// them (KiB): twice the last-level cache the CPU reports, which is 64 MiB
/// on a 32 MiB-L3 machine but 960 MiB on a virtual machine reporting a
/// 480 MiB L3. A scene check solves the scene's load with that solver.
fn dense_kernel_reservation_kib() -> u64 {
    std::fs::read_to_string("/sys/devices/system/cpu/cpu0/cache/index3/size")
        .ok()
        .and_then(|s| {
            s.trim()
                .strip_suffix('K')
                .and_then(|k| k.parse::<u64>().ok())
        })
        .map_or(0, |l3| 2 * l3)
}

/// [`mss_bounded`] with `extra_kib` more address space.
fn mss_bounded_plus(args: &[&str], dir: &Path, extra_kib: u64) -> Output {
    let limit = ADDRESS_SPACE_KIB + extra_kib;
    Command::new("sh")
        .arg("-c")
        .arg(format!("ulimit -v {limit}; exec \"$0\" \"$@\""))
        .arg(MSS)
        .args(["--quiet", "--max-memory", "256MiB"])
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

/// Exit code 0, 1 or 2 and no panic text; the error, if any, on one line.
fn assert_graceful(out: &Output, what: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        matches!(out.status.code(), Some(0..=2)),
        "{what}: exit {:?}: {stderr}",
        out.status
    );
    for needle in [
        "panicked",
        "stack backtrace",
        "RUST_BACKTRACE",
        "memory allocation",
    ] {
        assert!(!stderr.contains(needle), "{what}: {stderr}");
    }
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A poly data file with one compressed `Points` array: `blocks` copies of
/// one zlib block holding `block` zero bytes, behind an honest header.
fn zero_points_vtp(points: u64, blocks: u32, block: u32) -> Vec<u8> {
    let engine = base64::engine::general_purpose::STANDARD;
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(&vec![0u8; block as usize]).unwrap();
    let one = z.finish().unwrap();
    let mut header = Vec::new();
    for v in [blocks, block, block] {
        header.extend_from_slice(&v.to_le_bytes());
    }
    for _ in 0..blocks {
        header.extend_from_slice(&(one.len() as u32).to_le_bytes());
    }
    let data = one.repeat(blocks as usize);
    format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt32\" compressor=\"vtkZLibDataCompressor\">\n\
         <PolyData>\n<Piece NumberOfPoints=\"{points}\" NumberOfPolys=\"1\">\n<Points>\n\
         <DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"binary\">\n{}{}\n\
         </DataArray>\n</Points>\n</Piece>\n</PolyData>\n</VTKFile>\n",
        engine.encode(header),
        engine.encode(data)
    )
    .into_bytes()
}

#[test]
fn compressed_vtu_headers_are_checked_before_anything_is_unpacked() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 1 GiB of zeros in a file of about a megabyte.
    let cases: [(&str, Vec<u8>, &str); 3] = [
        // Three points cannot need a gigabyte.
        (
            "few_points.vtp",
            zero_points_vtp(3, 1024, 1 << 20),
            "more than its piece's 3 points",
        ),
        // Fifty million points could, but not within --max-memory.
        (
            "many_points.vtp",
            zero_points_vtp(50_000_000, 1024, 1 << 20),
            "bytes allowed for reading a mesh",
        ),
        // A header whose blocks lie past the array's end: the reader would
        // slice out of range (it panicked, printing a backtrace).
        (
            "lying.vtp",
            {
                let mut f = zero_points_vtp(3, 1, 72);
                let text = String::from_utf8(f.clone()).unwrap();
                let engine = base64::engine::general_purpose::STANDARD;
                let lying: Vec<u8> = [1u32, 72, 72, 0x7fff_ffff]
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect();
                let start = text.find("format=\"binary\">\n").unwrap() + 17;
                let header_chars = engine.encode(&lying);
                f.splice(start..start + header_chars.len(), header_chars.into_bytes());
                f
            },
            "compressed bytes, more than",
        ),
    ];
    for (name, bytes, words) in cases {
        std::fs::write(d.join(name), &bytes).unwrap();
        assert!(bytes.len() < 4 << 20, "{name}: {} bytes", bytes.len());
        let out = mss_bounded(&["--out", "vox", "voxelize", name], d);
        assert_graceful(&out, name);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {stderr}");
        assert!(
            stderr.contains(words) && stderr.contains(name),
            "{name}: {stderr}"
        );
        // A scene naming it: check and run refuse it the same way.
        let scene = format!(
            "[mesh]\npath = \"{name}\"\n[material]\nyoung = 1e4\npoisson = 0.3\ndensity = 1000.0\n"
        );
        std::fs::write(d.join("scene.toml"), scene).unwrap();
        for command in ["check", "run"] {
            let out = mss_bounded(&["--out", "run", command, "scene.toml"], d);
            assert_graceful(&out, &format!("{command} {name}"));
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(1), "{command} {name}: {stderr}");
            assert!(stderr.contains(words), "{command} {name}: {stderr}");
        }
    }
}

#[test]
fn every_corpus_file_ends_gracefully_within_the_memory_bound() {
    let dir = tempfile::tempdir().unwrap();
    let fuzz = repo().join("fuzz");
    let mut meshes = Vec::new();
    for kind in ["seeds", "corpus-min", "regressions"] {
        for format in ["obj", "stl", "ply", "vtk"] {
            let Ok(entries) = std::fs::read_dir(fuzz.join(kind).join(format)) else {
                continue;
            };
            let mut files: Vec<PathBuf> = entries.map(|e| e.unwrap().path()).collect();
            files.sort();
            // Every seed and regression; of the minimized corpora, every
            // eighth file in name order (a fixed sample: the whole corpus
            // is replayed in-process by hexmesh's fuzz_replay test).
            let step = if kind == "corpus-min" { 8 } else { 1 };
            for f in files.into_iter().step_by(step) {
                meshes.push((f, format));
            }
        }
    }
    assert!(meshes.len() > 200, "{} mesh files", meshes.len());
    for (i, (file, format)) in meshes.iter().enumerate() {
        // The loader goes by extension; corpus files have none.
        let named = dir.path().join(format!("case{i}.{format}"));
        std::fs::copy(file, &named).unwrap();
        let out = mss_bounded(
            &[
                "--out",
                "vox",
                "voxelize",
                named.to_str().unwrap(),
                "--cells",
                "4",
            ],
            dir.path(),
        );
        assert_graceful(&out, &file.display().to_string());
        std::fs::remove_file(&named).unwrap();
    }
    let scenes = fuzz.join("seeds").join("scene");
    for entry in std::fs::read_dir(&scenes).unwrap() {
        let scene = entry.unwrap().path();
        // One worker thread, with the solver's reservation for it on top:
        // the mesh readers above keep the strict bound.
        let out = mss_bounded_plus(
            &["--threads", "1", "check", scene.to_str().unwrap()],
            dir.path(),
            dense_kernel_reservation_kib(),
        );
        assert_graceful(&out, &scene.display().to_string());
    }
}
