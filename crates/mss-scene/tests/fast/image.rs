//! Scenes whose body is a label image (`[image]`): the bundled organ builds
//! with its labels and a region per label, writes the `label` cell field,
//! sags under gravity to the static equilibrium; bad images and
//! inconsistent tables are typed errors naming the key.

use std::path::PathBuf;

use mss_scene::{Job, Registry, SceneInput, no_progress};

const ORGAN: &str = include_str!("../../../../data/scenes/organ.toml");

fn images() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/images")
        .canonicalize()
        .unwrap()
}

/// The organ scene with its image path made absolute (the scene is given as
/// text, so relative paths would be the working directory's).
fn organ_text() -> String {
    let path = images().join("organ.nii.gz");
    ORGAN.replace("../images/organ.nii.gz", &path.display().to_string())
}

fn prepare(text: &str) -> Result<Job, String> {
    let input = SceneInput::from_toml(text, "image.toml").map_err(|e| e.to_string())?;
    Job::prepare(input, Registry::default(), &no_progress).map_err(|e| e.to_string())
}

#[test]
fn the_organ_scene_builds_with_labels_and_a_region_per_label() {
    let job = prepare(&organ_text()).unwrap();
    let body = &job.bodies[0];
    let labels = body.cell_labels.as_ref().unwrap();
    assert_eq!(labels.len(), body.lattice.num_cells());
    assert!(
        labels.iter().all(|&l| l == 1 || l == 2),
        "label 3 is not part of the body"
    );
    let nodule = labels.iter().filter(|&&l| l == 2).count();
    assert!(nodule > 10, "{nodule} nodule cells");
    // The label region gives exactly the label-2 cells the region's material.
    let regions = body.regions.as_ref().unwrap();
    for (&l, &m) in labels.iter().zip(&regions.cell_material) {
        assert_eq!(m, u32::from(l == 2));
    }
    assert_eq!(regions.materials[1].young, 1.0e5);
    // The surface is the labels' boundary, closed, with the body's volume.
    let v = body.mesh.signed_volume();
    let rel = (v - body.vox_stats.mesh_volume).abs() / body.vox_stats.mesh_volume;
    assert!(
        rel < 0.05,
        "surface {v} voxels {}",
        body.vox_stats.mesh_volume
    );
    let rel = (body.lattice.volume() - v).abs() / v;
    assert!(rel < 0.1, "lattice {} surface {v}", body.lattice.volume());
    // Without `labels`, every non-zero label: the bone (3) joins, and only
    // the largest component is kept unless `components = "all"`.
    let all = organ_text()
        .replace("labels = [1, 2]", "")
        .replace("cells = 20", "cells = 20\ncomponents = \"all\"");
    let job = prepare(&all).unwrap();
    assert!(job.bodies[0].cell_labels.as_ref().unwrap().contains(&3));
}

#[test]
fn the_organ_sags_and_settles_at_its_static_equilibrium() {
    let job = prepare(&organ_text()).unwrap();
    let dynamic = {
        let mut it = job
            .input
            .integrator(&job.registry, &job.problem, &job.plan)
            .unwrap()
            .unwrap();
        let mut s = mss_core::solver::State::at_rest(job.problem.model());
        while s.time < 1.5 {
            it.step(&job.problem, &mut s).unwrap();
        }
        s
    };
    let mut static_state = mss_core::solver::State::at_rest(job.problem.model());
    mss_core::solver::solve_static(&job.problem, &mut static_state, &Default::default()).unwrap();
    let model = job.problem.model();
    let rest = model.rest_positions();
    let sag = |x: &[mss_core::Vec3]| {
        x.iter()
            .zip(rest)
            .map(|(p, r)| r.z - p.z)
            .fold(0.0f64, f64::max)
    };
    let (d, s) = (sag(&dynamic.x), sag(&static_state.x));
    assert!(s > 1e-3, "the organ sags {s} m");
    assert!(
        (d - s).abs() < 0.03 * s,
        "damped dynamics {d} m, static {s} m"
    );
}

#[test]
fn the_label_field_is_written_with_every_lattice_frame() {
    let dir = tempfile::tempdir().unwrap();
    let text = organ_text()
        .replace("duration = 0.6", "duration = 0.01")
        .replace("every_time = 0.03", "every_time = 0.01")
        .replace(
            "folder = \"out\"",
            &format!("folder = {:?}", dir.path().display().to_string()),
        );
    let job = prepare(&text).unwrap();
    job.run(dir.path(), &no_progress, &mss_scene::Cancel::new())
        .unwrap();
    let frame = std::fs::read_to_string(dir.path().join("lattice_0001.vtu")).unwrap();
    assert!(frame.contains("Name=\"label\""), "no label field");
    assert!(frame.contains("type=\"Int32\" Name=\"label\""));
}

#[test]
fn bad_image_tables_are_typed_errors_naming_the_key() {
    let text = organ_text();
    // Both a mesh and an image.
    let both = format!("{text}\n[mesh]\npath = \"builtin:cube\"\n");
    let e = prepare(&both).unwrap_err();
    assert!(e.contains("[image]") && e.contains("not both"), "{e}");
    // A threshold out of range, an empty label list.
    let e = prepare(&text.replace("threshold = 0.5", "threshold = 0.0")).unwrap_err();
    assert!(e.contains("[image] threshold"), "{e}");
    let e = prepare(&text.replace("labels = [1, 2]", "labels = []")).unwrap_err();
    assert!(e.contains("[image] labels"), "{e}");
    // Labels the image does not hold.
    let e = prepare(&text.replace("labels = [1, 2]", "labels = [9]")).unwrap_err();
    assert!(
        e.contains("[9]") && e.contains("labels are [0, 1, 2, 3]"),
        "{e}"
    );
    // A missing file, and a file that is not an image.
    let e = prepare(&text.replace("organ.nii.gz", "gone.nii.gz")).unwrap_err();
    assert!(
        e.contains("[image] path") && e.contains("gone.nii.gz"),
        "{e}"
    );
    let e = prepare(&text.replace("organ.nii.gz", "make_images.py")).unwrap_err();
    assert!(
        e.contains("[image] path") && e.contains("make_images.py"),
        "{e}"
    );
    // A label region on a body made from a mesh.
    let mesh_body = "[mesh]\npath = \"builtin:cube\"\nscale = 0.1\n[material]\nyoung = 1e4\n\
                     poisson = 0.3\ndensity = 1000.0\n[[regions]]\n\
                     select = { kind = \"label\", labels = [2] }\nyoung = 2e4\n";
    let e = prepare(mesh_body).unwrap_err();
    assert!(
        e.contains("[[regions]] #1") && e.contains("[image] body"),
        "{e}"
    );
}

#[test]
fn an_image_body_joins_a_scene_of_bodies() {
    let path = images().join("organ.nii.gz");
    let text = format!(
        "[[bodies]]\nname = \"organ\"\n[bodies.image]\npath = {:?}\nlabels = [1, 2]\n\
         [bodies.voxelize]\ncells = 12\n[bodies.material]\nyoung = 2e4\npoisson = 0.45\n\
         density = 1050.0\n[[bodies.regions]]\nselect = {{ kind = \"label\", labels = [2] }}\n\
         young = 1e5\n\
         [[bodies]]\nname = \"tool\"\n[bodies.mesh]\npath = \"builtin:cube\"\nscale = 0.02\n\
         translate = [0.0, 0.0, 0.2]\n[bodies.material]\nyoung = 1e6\npoisson = 0.3\n\
         density = 1000.0\n",
        path.display().to_string()
    );
    let job = prepare(&text).unwrap();
    assert!(job.bodies[0].cell_labels.is_some());
    assert!(job.bodies[1].cell_labels.is_none());
    // A body with neither a mesh nor an image.
    let e = prepare(&text.replace("[bodies.image]", "[bodies.picture]")).unwrap_err();
    assert!(e.contains("picture"), "{e}");
}
