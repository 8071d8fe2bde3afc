//! Outputs for Blender: point caches beside their rest shapes, flat-shaded
//! skins.

use mss_io::pc2::read_pc2;
use mss_scene::{Cancel, Job, Registry, SceneInput, no_progress};

fn obj_vertices(path: &std::path::Path) -> (Vec<[f64; 3]>, usize, usize, bool) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut v = Vec::new();
    let (mut vn, mut f) = (0, 0);
    for line in text.lines() {
        let mut t = line.split_whitespace();
        match t.next() {
            Some("v") => {
                let c: Vec<f64> = t.map(|x| x.parse().unwrap()).collect();
                v.push([c[0], c[1], c[2]]);
            }
            Some("vn") => vn += 1,
            Some("f") => f += 1,
            _ => {}
        }
    }
    (v, vn, f, text.contains("\ns off\n"))
}

fn close_f32(a: &[[f64; 3]], b: &[[f64; 3]]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(p, q)| {
            (0..3).all(|k| (p[k] as f32 as f64 - q[k]).abs() <= 1e-7 * (1.0 + q[k].abs()))
        })
}

#[test]
fn point_caches_hold_every_frame_of_their_rest_shapes() {
    let text = "[mesh]\npath = \"builtin:critter\"\n[voxelize]\ncells = 8\n[material]\n\
                young = 1.0e5\npoisson = 0.3\ndensity = 1000.0\n[[fixed]]\nkind = \"lowest_layer\"\n\
                [loads]\ngravity = [0.0, 0.0, -9.81]\n[solver]\nduration = 0.02\n\
                [output]\nevery_time = 0.005\npc2 = true\nskin_obj = true\nsurface_format = \"obj\"\n";
    let input = SceneInput::from_toml(text, "pc2.toml").unwrap();
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    let out = tempfile::tempdir().unwrap();
    let summary = job.run(out.path(), &no_progress, &Cancel::new()).unwrap();
    let d = out.path();
    for (stem, frames_prefix, flat) in [("skin", "skin", true), ("surface", "surface", false)] {
        let cache = read_pc2(&d.join(format!("{stem}.pc2"))).unwrap();
        let (rest, vn, f, s_off) = obj_vertices(&d.join(format!("{stem}_rest.obj")));
        assert_eq!(cache.num_points, rest.len(), "{stem}");
        assert_eq!(cache.frames.len(), summary.frames, "{stem}");
        // The first frame is the rest state; the last is the last OBJ frame.
        assert!(close_f32(&cache.frames[0], &rest), "{stem}");
        let last = d.join(format!("{frames_prefix}_{:04}.obj", summary.frames - 1));
        let (last_v, last_vn, _, last_flat) = obj_vertices(&last);
        assert!(close_f32(cache.frames.last().unwrap(), &last_v), "{stem}");
        assert!(
            !close_f32(cache.frames.last().unwrap(), &rest),
            "{stem} did not move"
        );
        // Flat shading: one normal per triangle; smooth: one per vertex.
        assert_eq!(s_off, flat, "{stem}");
        assert_eq!(last_flat, flat, "{stem}");
        assert_eq!(vn, if flat { f } else { rest.len() }, "{stem}");
        assert_eq!(last_vn, vn, "{stem}");
    }
    // Counted, and removed as files of an earlier run.
    let listed =
        mss_scene::output::previous_run_files(d, &mss_scene::Registry::default().exporters);
    for name in [
        "skin.pc2",
        "skin_rest.obj",
        "surface.pc2",
        "surface_rest.obj",
    ] {
        assert!(listed.contains(&d.join(name)), "{name}");
    }
    // (summary.json is the front end's to write.)
    assert_eq!(summary.files, listed.len());
}

#[test]
fn smooth_skins_on_request() {
    let text = "[mesh]\npath = \"builtin:critter\"\n[voxelize]\ncells = 6\n[material]\n\
                young = 1.0e5\npoisson = 0.3\ndensity = 1000.0\n[[fixed]]\nkind = \"lowest_layer\"\n\
                [solver]\nduration = 0.002\n[output]\nlast_only = true\n\nskin_normals = \"smooth\"\nsurface_normals = \"flat\"\n\
                embedded = true\nskin_obj = true\nsurface_format = \"obj\"\n";
    let input = SceneInput::from_toml(text, "smooth.toml").unwrap();
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    let out = tempfile::tempdir().unwrap();
    job.run(out.path(), &no_progress, &Cancel::new()).unwrap();
    let (v, vn, _, s_off) = obj_vertices(&out.path().join("skin_0000.obj"));
    assert!(!s_off && vn == v.len());
    let (_, vn, f, s_off) = obj_vertices(&out.path().join("surface_0000.obj"));
    assert!(s_off && vn == f);
    assert!(!out.path().join("skin.pc2").exists());
    let err = SceneInput::from_toml(&text.replace("\"smooth\"", "\"shiny\""), "bad.toml")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("bad.toml") && err.contains("`smooth`"),
        "{err}"
    );
}
