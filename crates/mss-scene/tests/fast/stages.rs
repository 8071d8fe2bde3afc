//! The stages every front end shares: a scene's job builds its lattice
//! through them (the same lattice as calling them directly), their guards
//! refuse before allocating, and a front end's own table check names the
//! key.

use mss_scene::hexmesh::{Placement, Resolution, UpAxis, VoxelizeOptions};
use mss_scene::limits::Limits;
use mss_scene::scene::{MeshSource, VoxelizeSection};
use mss_scene::stages::{RunNeeds, StageError, lattice_within, load_placed};
use mss_scene::{Job, JobError, Registry, SceneInput, no_progress};

const SCENE: &str = "[mesh]\npath = \"builtin:critter\"\nup = \"y\"\nscale = 2.0\n\
    [voxelize]\ncells = 10\n[material]\nyoung = 1.0e5\npoisson = 0.3\ndensity = 1000.0\n\
    [[fixed]]\nkind = \"lowest_layer\"\n";

#[test]
fn a_job_builds_the_lattice_the_stages_build() {
    let job = Job::prepare(
        SceneInput::from_toml(SCENE, "stages.toml").unwrap(),
        Registry::default(),
        &no_progress,
    )
    .unwrap();
    let placement = Placement {
        scale: [2.0; 3],
        up: UpAxis::Y,
        ..Placement::default()
    };
    let placed = load_placed(
        &MeshSource::Builtin("critter".into()),
        &placement,
        &Default::default(),
    )
    .unwrap();
    assert_eq!(placed.mesh.vertices, job.mesh().vertices);
    let options = VoxelizeOptions {
        resolution: Resolution::CellsAlongLongestAxis(10),
        ..Default::default()
    };
    let vox = lattice_within(
        &placed.mesh,
        &placed.name,
        &options,
        &Limits::default(),
        RunNeeds::EXPLICIT,
        &|_, _| {},
    )
    .unwrap();
    assert_eq!(vox.lattice.cells(), job.lattice().cells());
    assert_eq!(vox.lattice.nodes(), job.lattice().nodes());
}

#[test]
fn memory_guards_refuse_before_allocating_and_name_the_run() {
    let placed = load_placed(
        &MeshSource::Builtin("critter".into()),
        &Placement::default(),
        &Default::default(),
    )
    .unwrap();
    let options = VoxelizeOptions {
        resolution: Resolution::CellsAlongLongestAxis(40),
        ..Default::default()
    };
    // Room for the bounding grid but not for a static run of the lattice.
    let limits = Limits {
        memory_bytes: 20 << 20,
        ..Limits::default()
    };
    let needs = RunNeeds {
        solver: "static",
        needs_matrix: true,
    };
    let err = lattice_within(
        &placed.mesh,
        &placed.name,
        &options,
        &limits,
        needs,
        &|_, _| {},
    )
    .unwrap_err();
    let StageError::Memory { needed, limit, .. } = &err else {
        panic!("expected a memory error, got {err}");
    };
    assert!(needed > limit);
    let text = err.to_string();
    assert!(text.contains("explicit solver"), "{text}");
    // The same limit through a scene: the job's error names the scene.
    let scene = SCENE.replace("cells = 10", "cells = 40") + "[solver]\nkind = \"static\"\n";
    let err = Job::prepare_with_limits(
        SceneInput::from_toml(&scene, "big.toml").unwrap(),
        Registry::default(),
        limits,
        &no_progress,
    )
    .unwrap_err();
    assert!(matches!(err, JobError::Memory { .. }), "{err}");
    assert!(err.to_string().starts_with("big.toml: "), "{err}");
}

#[test]
fn the_voxelize_table_checks_its_own_keys() {
    let good = VoxelizeSection::default();
    assert!(good.check().is_ok());
    for (section, key) in [
        (
            VoxelizeSection {
                cells: Some(0),
                ..good.clone()
            },
            "cells",
        ),
        (
            VoxelizeSection {
                cell_size: Some(-0.1),
                ..good.clone()
            },
            "cell_size",
        ),
        (
            VoxelizeSection {
                fraction: 1.5,
                ..good.clone()
            },
            "fraction",
        ),
        (
            VoxelizeSection {
                max_cells: 0,
                ..good.clone()
            },
            "max_cells",
        ),
        (
            VoxelizeSection {
                cells: Some(4),
                cell_size: Some(0.1),
                ..good.clone()
            },
            "",
        ),
    ] {
        let err = section.check().unwrap_err();
        assert_eq!(err.key, key, "{err:?}");
        assert_eq!(
            err.scene_key("[voxelize]"),
            if key.is_empty() {
                "[voxelize]".to_owned()
            } else {
                format!("[voxelize] {key}")
            }
        );
    }
}
