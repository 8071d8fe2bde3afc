//! `[mesh]` placement keys and mesh formats through a scene.

use mss_scene::{Job, Registry, SceneInput, no_progress};

fn data(name: &str) -> String {
    format!("{}/../../data/meshes/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn job(mesh_keys: &str) -> Result<Job, String> {
    let text = format!(
        "[mesh]\n{mesh_keys}\n[voxelize]\ncells = 12\n[material]\nyoung = 1.0e5\n\
         poisson = 0.3\ndensity = 1000.0\n[[fixed]]\nkind = \"lowest_layer\"\n"
    );
    let input = SceneInput::from_toml(&text, "placed.toml").map_err(|e| e.to_string())?;
    Job::prepare(input, Registry::default(), &no_progress).map_err(|e| e.to_string())
}

fn cell_keys(job: &Job) -> Vec<[i64; 3]> {
    let l = &job.lattice();
    let mut keys: Vec<[i64; 3]> = l
        .cell_coords()
        .iter()
        .map(|c| std::array::from_fn(|k| c[k] as i64 + (l.origin()[k] / l.h()).round() as i64))
        .collect();
    keys.sort_unstable();
    keys
}

#[test]
fn a_y_up_mesh_in_centimetres_stands_on_z_and_every_format_gives_its_cells() {
    let keys = |path: &str| {
        format!(
            "path = {:?}\nunits = \"cm\"\nup = \"y\"\nrotate = [0.0, 0.0, 90.0]\n\
             translate = [1.0, 2.0, 3.0]",
            data(path)
        )
    };
    let obj = job(&keys("bunny.obj")).unwrap();
    // 9.657897 cm tall along y in the file: 0.09657897 m along z now.
    let b = obj.mesh().bounding_box().unwrap();
    assert!(
        (b.extent()[2] - 0.09657897).abs() < 1e-12,
        "{:?}",
        b.extent()
    );
    let raw = hexmesh::load_mesh(std::path::Path::new(&data("bunny.obj")))
        .unwrap()
        .mesh;
    let rb = raw.bounding_box().unwrap();
    // x -> (up y) x -> (90° about z) y; file -z -> (up y) y -> (about z) -x.
    assert!((b.min[1] - (0.01 * rb.min[0] + 2.0)).abs() < 1e-12);
    assert!((b.min[0] - (0.01 * rb.min[2] + 1.0)).abs() < 1e-12);
    assert!((b.min[2] - (0.01 * rb.min[1] + 3.0)).abs() < 1e-12);
    // The lowest layer is the bunny's base, not its side.
    let l = &obj.lattice();
    let lowest = l.nodes().iter().map(|p| p[2]).fold(f64::MAX, f64::min);
    assert!((lowest - b.min[2]).abs() < l.h());
    let reference = cell_keys(&obj);
    for path in [
        "formats/bunny_ascii.ply",
        "formats/bunny_be.ply",
        "formats/bunny_legacy_binary.vtk",
        "formats/bunny.vtu",
    ] {
        let other = job(&keys(path)).unwrap_or_else(|e| panic!("{path}: {e}"));
        assert_eq!(cell_keys(&other), reference, "{path}");
    }
}

#[test]
fn bad_placement_keys_name_the_key() {
    let path = format!("path = {:?}", data("bunny.obj"));
    for (keys, needle) in [
        (format!("{path}\nscale = 0.0"), "[mesh] scale"),
        (format!("{path}\nscale = [1.0, -0.0, 1.0]"), "[mesh] scale"),
        (
            format!("{path}\nscale = [1.0, 2.0]"),
            "a number or an array of 3 numbers",
        ),
        (format!("{path}\nrotate = [nan, 0.0, 0.0]"), "[mesh] rotate"),
        (
            format!("{path}\ntranslate = [inf, 0.0, 0.0]"),
            "[mesh] translate",
        ),
        (format!("{path}\nup = \"w\""), "`x`, `y`"),
        (format!("{path}\nunits = \"in\""), "`m`, `cm`"),
        (format!("{path}\nscale = 1e12"), "beyond"),
    ] {
        let err = job(&keys)
            .err()
            .unwrap_or_else(|| panic!("{keys}: accepted"));
        assert!(
            err.contains(needle) && err.contains("placed.toml"),
            "{keys}: {err}"
        );
    }
}
