//! `[[regions]]`: materials per region through a scene.

use mss_scene::{Cancel, Job, Registry, SceneInput, no_progress};
use vtkio::model::{Attribute, DataSet, Piece};

fn bar(extra: &str) -> String {
    // A bar 0.2 x 0.04 x 0.04 m from a box surface, x- face clamped, gravity.
    format!(
        "[mesh]\npath = \"BAR\"\n[voxelize]\ncells = 10\n[material]\nyoung = 1.0e5\n\
         poisson = 0.3\ndensity = 1000.0\n[model]\nparameterization = \"volumetric-barrier+hg\"\n\
         hourglass = 1.0\n[[fixed]]\nkind = \"face\"\nface = \"x-\"\n[loads]\n\
         gravity = [0.0, 0.0, -9.81]\n[solver]\nkind = \"static\"\n{extra}"
    )
}

fn job(dir: &std::path::Path, extra: &str) -> Result<Job, String> {
    job_with(dir, extra, 1.0e5)
}

fn job_with(dir: &std::path::Path, extra: &str, young: f64) -> Result<Job, String> {
    let mesh = dir.join("bar.obj");
    if !mesh.exists() {
        write_box_obj(&mesh, [0.2, 0.04, 0.04]);
    }
    let toml = bar(extra)
        .replacen("young = 1.0e5", &format!("young = {young:e}"), 1)
        .replace("BAR", &mesh.display().to_string());
    let input = SceneInput::from_toml(&toml, "regions.toml").map_err(|e| e.to_string())?;
    Job::prepare(input, Registry::default(), &no_progress).map_err(|e| e.to_string())
}

/// Writes the box `0 ..= max` as an OBJ file.
fn write_box_obj(path: &std::path::Path, max: [f64; 3]) {
    let b = hexmesh::generate::box_mesh([0.0; 3], max);
    let mut text = String::new();
    for v in &b.vertices {
        text += &format!("v {} {} {}\n", v[0], v[1], v[2]);
    }
    for t in &b.triangles {
        text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    std::fs::write(path, text).unwrap();
}

fn material_field(path: &std::path::Path) -> Vec<u32> {
    let vtk = vtkio::Vtk::import(path).unwrap();
    let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
        panic!("not a grid")
    };
    let Some(Piece::Inline(piece)) = pieces.into_iter().next() else {
        panic!("no piece")
    };
    for a in piece.data.cell {
        if let Attribute::DataArray(d) = a
            && d.name == "material"
        {
            return d.data.cast_into::<u32>().unwrap();
        }
    }
    Vec::new()
}

fn tip(job: &Job, out: &std::path::Path) -> f64 {
    let s = job.run(out, &no_progress, &Cancel::new()).unwrap();
    assert!(s.max_displacement > 0.0);
    s.max_displacement
}

#[test]
fn a_stiff_clamped_half_deflects_as_beam_theory_says_and_is_written_as_cell_data() {
    let dir = tempfile::tempdir().unwrap();
    // E = 10 MPa: a small deflection, so beam theory applies.
    let plain = job_with(dir.path(), "", 1.0e7).unwrap();
    assert!(plain.regions().is_none());
    let stiff = job_with(
        dir.path(),
        "[[regions]]\nselect = { kind = \"box\", min = [0.0, 0.0, 0.0], max = [0.5, 1.0, 1.0], \
         relative = true }\nyoung = 1.0e8\n",
        1.0e7,
    )
    .unwrap();
    let a = stiff.regions().unwrap();
    assert_eq!(a.cells_per_material(), vec![20, 20]);
    let (out_plain, out_stiff) = (dir.path().join("plain"), dir.path().join("stiff"));
    let (w_plain, w_stiff) = (tip(&plain, &out_plain), tip(&stiff, &out_stiff));
    // Euler-Bernoulli for a clamped half ten times stiffer under a uniform
    // load: tip deflection (15 / 10 + 1) / 16 = 0.156 of the uniform beam's.
    // Shear deformation (Timoshenko) raises it a little.
    let ratio = w_stiff / w_plain;
    assert!(
        ratio > 0.14 && ratio < 0.20,
        "{w_stiff} vs {w_plain}: {ratio}"
    );
    let field = material_field(&out_stiff.join("lattice_0001.vtu"));
    assert_eq!(field, a.cell_material);
    assert!(material_field(&out_plain.join("lattice_0001.vtu")).is_empty());
}

#[test]
fn a_region_of_the_same_material_changes_nothing_and_later_regions_win() {
    let dir = tempfile::tempdir().unwrap();
    let plain = job(dir.path(), "").unwrap();
    let same = job(
        dir.path(),
        "[[regions]]\nselect = { kind = \"sphere\", centre = [0.1, 0.02, 0.02], radius = 0.05 }\n\
         young = 1.0e5\n",
    )
    .unwrap();
    let (a, b) = (
        tip(&plain, &dir.path().join("a")),
        tip(&same, &dir.path().join("b")),
    );
    assert!((a - b).abs() <= 1e-9 * a, "{a} vs {b}");
    // The second region covers the first entirely.
    let two = job(
        dir.path(),
        "[[regions]]\nselect = { kind = \"sphere\", centre = [0.1, 0.02, 0.02], radius = 0.03 }\n\
         density = 500.0\n[[regions]]\nselect = { kind = \"box\", min = [0.0, 0.0, 0.0], \
         max = [0.2, 0.04, 0.04] }\npoisson = 0.4\n",
    )
    .unwrap();
    let r = two.regions().unwrap();
    assert_eq!(r.cells_per_material(), vec![0, 0, 40]);
    assert!(r.selected[0] > 0);
    assert_eq!(r.materials[2].poisson, 0.4);
    assert_eq!(r.materials[2].density, 1000.0);
}

#[test]
fn a_second_mesh_selects_the_cells_inside_it() {
    let dir = tempfile::tempdir().unwrap();
    // Region meshes are placed like [mesh]: here both are in centimetres.
    write_box_obj(&dir.path().join("root.obj"), [6.0, 4.0, 4.0]);
    let job_cm = |extra: &str| {
        let mesh = dir.path().join("bar_cm.obj");
        write_box_obj(&mesh, [20.0, 4.0, 4.0]);
        let toml = bar(extra).replace(
            "path = \"BAR\"",
            &format!("path = {:?}\nunits = \"cm\"", mesh.display().to_string()),
        );
        let input = SceneInput::from_toml(&toml, "regions.toml").unwrap();
        Job::prepare(input, Registry::default(), &no_progress).map_err(|e| e.to_string())
    };
    let root = dir.path().join("root.obj").display().to_string();
    let j = job_cm(&format!(
        "[[regions]]\nselect = {{ kind = \"mesh\", path = {root:?} }}\nyoung = 2.0e5\n"
    ))
    .unwrap();
    assert_eq!(j.regions().unwrap().cells_per_material(), vec![28, 12]);
}

#[test]
fn bad_regions_are_refused_with_their_key() {
    let dir = tempfile::tempdir().unwrap();
    for (extra, needle) in [
        (
            "[[regions]]\nselect = { kind = \"sphere\", centre = [5.0, 5.0, 5.0], radius = 0.1 }\nyoung = 1.0\n",
            "[[regions]] #1: selects no cell",
        ),
        (
            "[[regions]]\nselect = { kind = \"sphere\", centre = [0.0, 0.0, 0.0], radius = 0.0 }\nyoung = 1.0\n",
            "positive length",
        ),
        (
            "[[regions]]\nselect = { kind = \"box\", min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n",
            "gives none of young",
        ),
        (
            "[[regions]]\nselect = { kind = \"box\", min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\npoisson = 0.7\n",
            "[[regions]] #1",
        ),
        (
            "[[regions]]\nselect = { kind = \"mesh\", path = \"nowhere.obj\" }\nyoung = 1.0\n",
            "nowhere.obj",
        ),
        (
            "[[regions]]\nselect = { kind = \"cube\" }\nyoung = 1.0\n",
            "unknown region selector kind \"cube\"; known: box, sphere, mesh",
        ),
        (
            "[[regions]]\nselect = { kind = \"box\", min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nyoung = 1.0\nstiffness = 2.0\n",
            "unknown field `stiffness`",
        ),
        (
            "[[regions]]\nselect = { kind = \"box\", min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nyoung = nan\n",
            "finite",
        ),
    ] {
        let err = job(dir.path(), extra)
            .err()
            .unwrap_or_else(|| panic!("{extra}: accepted"));
        assert!(
            err.contains(needle) && err.contains("regions.toml"),
            "{extra}: {err}"
        );
    }
}

/// The template with its commented example that starts with `first_line`
/// uncommented.
fn template_with_example(first_line: &str) -> String {
    let template = mss_scene::scene::TEMPLATE_SCENE_TOML;
    let start = template.find(first_line).expect("the example");
    let end = start + template[start..].find("\n\n").unwrap();
    let uncommented: String = template[start..end]
        .lines()
        .map(|l| l.trim_start_matches("# "))
        .collect::<Vec<_>>()
        .join("\n");
    format!(
        "{}{}\n{}",
        &template[..start],
        uncommented,
        &template[end..]
    )
}

#[test]
fn the_templates_region_example_works_on_the_critter() {
    let text = template_with_example("# [[regions]]");
    assert!(text.contains("\n[[regions]]\nselect = "));
    let input = SceneInput::from_toml(&text, "template.toml").unwrap();
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    let a = job.regions().unwrap();
    assert!(a.selected[0] > 0 && a.materials[1].young == 2.0e5);
}

#[test]
fn the_templates_obstacle_examples_work_on_the_critter() {
    let text = template_with_example("# [[obstacles]]");
    let input = SceneInput::from_toml(&text, "template.toml").unwrap();
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    assert_eq!(job.problem.contact().unwrap().obstacles().count(), 2);
}
