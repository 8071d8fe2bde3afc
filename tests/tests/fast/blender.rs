//! The README's Blender steps, replayed in Blender itself when it is
//! installed (`apt-get install blender`; it is not part of CI): the rest
//! OBJ imported with Z up and a Mesh Cache modifier on the `.pc2` give
//! every frame's positions.

use std::process::Command;

use mss_scene::{Cancel, Job, Registry, SceneInput, no_progress};

#[test]
fn blender_plays_the_point_caches_as_the_readme_says() {
    if Command::new("blender").arg("--version").output().is_err() {
        eprintln!("blender is not installed: the replay in Blender is skipped");
        return;
    }
    let text = "[mesh]\npath = \"builtin:critter\"\n[voxelize]\ncells = 8\n[material]\n\
                young = 2.0e4\npoisson = 0.3\ndensity = 1000.0\n[model]\n\
                parameterization = \"volumetric-barrier+hg\"\nhourglass = 1.0\n[[fixed]]\n\
                kind = \"lowest_layer\"\n[loads]\ngravity = [0.0, 0.0, -9.81]\n[solver]\n\
                duration = 0.1\n[output]\nevery_time = 0.025\npc2 = true\n";
    let job = Job::prepare(
        SceneInput::from_toml(text, "blender.toml").unwrap(),
        Registry::default(),
        &no_progress,
    )
    .unwrap();
    let out = tempfile::tempdir().unwrap();
    job.run(out.path(), &no_progress, &Cancel::new()).unwrap();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/blender/mesh_cache.py");
    for stem in ["skin", "surface"] {
        let r = Command::new("blender")
            .args([
                "-b",
                "--factory-startup",
                "--python-exit-code",
                "1",
                "--python",
                script,
                "--",
            ])
            .arg(out.path())
            .arg(stem)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&r.stdout);
        assert!(
            r.status.success() && stdout.contains(&format!("RESULT {stem}: 5 frames")),
            "{stdout}\n{}",
            String::from_utf8_lossy(&r.stderr)
        );
    }
}
