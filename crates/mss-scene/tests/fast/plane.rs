//! 2D scenes (`[model] dimension = 2`): the bundled bracket runs and
//! settles where the static solve puts it; its frames are VTK quads and
//! outlines; every key a 2D body cannot take is a typed error naming it.

use std::path::PathBuf;

use mss_scene::plane_job::PlaneJob;
use mss_scene::{Cancel, Job, Registry, SceneInput, no_progress};

const BRACKET: &str = include_str!("../../../../data/scenes/bracket.toml");

fn bracket_text() -> String {
    let svg = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/shapes/bracket.svg")
        .canonicalize()
        .unwrap();
    BRACKET.replace("../shapes/bracket.svg", &svg.display().to_string())
}

fn prepare(text: &str) -> Result<PlaneJob, String> {
    let input = SceneInput::from_toml(text, "plane.toml").map_err(|e| e.to_string())?;
    PlaneJob::prepare(input).map_err(|e| e.to_string())
}

#[test]
fn the_bracket_settles_where_the_static_solve_puts_it() {
    let dir = tempfile::tempdir().unwrap();
    let dynamic = prepare(&bracket_text().replace("duration = 1.0", "duration = 2.0")).unwrap();
    assert_eq!(dynamic.lattice.num_cells(), 344);
    let d = dynamic
        .run(&dir.path().join("dyn"), &Cancel::new())
        .unwrap();
    let stat =
        prepare(&bracket_text().replace("kind = \"explicit\"", "kind = \"static\"")).unwrap();
    let s = stat
        .run(&dir.path().join("static"), &Cancel::new())
        .unwrap();
    assert!(s.max_displacement > 5e-3, "{s:?}");
    assert!(
        (d.max_displacement - s.max_displacement).abs() < 1e-3 * s.max_displacement,
        "dynamic {} static {}",
        d.max_displacement,
        s.max_displacement
    );
    assert!(d.peak_displacement > d.max_displacement);
    // Frames: quads ParaView reads, and the outline carried along.
    let frame = dir.path().join("dyn/lattice_0001.vtu");
    let vtk = vtkio::Vtk::import(&frame).unwrap();
    let vtkio::model::DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
        panic!("not an unstructured grid");
    };
    let piece = pieces[0].load_piece_data(None).unwrap();
    assert_eq!(piece.cells.types.len(), 344);
    assert!(
        piece
            .cells
            .types
            .iter()
            .all(|t| *t == vtkio::model::CellType::Quad)
    );
    let svg = std::fs::read_to_string(dir.path().join("dyn/outline_0040.svg")).unwrap();
    assert_eq!(svg.matches("<path").count(), 2, "the outline and its hole");
    assert!(dir.path().join("dyn/lattice.pvd").exists());
    assert!(dir.path().join("static/summary.json").exists());
    // Implicit steps of 10 ms reach the same rest.
    let implicit = prepare(
        &bracket_text()
            .replace("kind = \"explicit\"", "kind = \"implicit\"\ndt = 0.01")
            .replace("duration = 1.0", "duration = 2.0"),
    )
    .unwrap();
    let i = implicit
        .run(&dir.path().join("implicit"), &Cancel::new())
        .unwrap();
    assert_eq!(i.steps, 200);
    assert!(
        (i.max_displacement - s.max_displacement).abs() < 1e-3 * s.max_displacement,
        "implicit {} static {}",
        i.max_displacement,
        s.max_displacement
    );
}

#[test]
fn the_bracket_dropped_on_the_ground_stays_on_it() {
    // Its post free, the bracket falls 1 cm onto the ground and settles.
    let text = bracket_text()
        .replace("[[fixed]]\nkind = \"face\"\nface = \"x-\"\n", "")
        .replace("duration = 1.0", "duration = 1.5")
        + "\n[[obstacles]]\nshape = { kind = \"ground\", gap = 0.01 }\nfriction = 0.5\n";
    let job = prepare(&text).unwrap();
    assert!(job.problem.held.iter().all(|h| !h[0] && !h[1]));
    let dir = tempfile::tempdir().unwrap();
    let s = job.run(dir.path(), &Cancel::new()).unwrap();
    // It fell the gap and stopped there (in free fall it would be 11 m
    // down): the ground holds it (the weight it carries is checked in
    // mss-core's plane tests).
    assert!(
        s.max_displacement > 0.009 && s.max_displacement < 0.03,
        "{s:?}"
    );
    let p = &job.problem;
    let c = p.contact.as_ref().unwrap();
    let ground = -0.2 - 0.01;
    assert!(
        matches!(c.obstacles()[0], mss_core::plane::PlaneObstacle::HalfPlane { point, .. } if (point[1] - ground).abs() < 1e-9)
    );
    // Defaults as in 3D: friction 0.5 sticking and sliding, damping ratio
    // 0.2; each obstacle takes its own.
    let s = c.settings()[0];
    assert_eq!(
        (s.friction_static, s.friction_kinetic, s.damping_ratio),
        (0.5, 0.5, 0.2)
    );
    let own = text
        + "\n[[obstacles]]\nshape = { kind = \"sphere\", centre = [1.0, 0.0, 0.0], radius = 0.1 }\n\
           friction = 0.8\nfriction_kinetic = 0.4\ndamping_ratio = 0.7\nstiffness = 3.0e4\n";
    let job = prepare(&own).unwrap();
    let settings = job.problem.contact.as_ref().unwrap().settings().to_vec();
    assert_eq!(settings[0].friction_static, 0.5);
    let s = settings[1];
    assert_eq!(
        (
            s.friction_static,
            s.friction_kinetic,
            s.damping_ratio,
            s.stiffness
        ),
        (0.8, 0.4, 0.7, 3.0e4)
    );
}

#[test]
fn what_a_2d_body_cannot_take_is_refused_by_key() {
    // Elongated cells: the paper's element needs its hourglass control.
    let text = bracket_text().replace("cell_size = [0.01, 0.01]", "cell_size = [0.02, 0.01]");
    for (change, key, words) in [
        (
            ("thickness = 0.01", ""),
            "[model] thickness",
            "needs its thickness",
        ),
        (
            ("thickness = 0.01", "thickness = -1.0"),
            "[model] thickness",
            "positive",
        ),
        (
            ("dimension = 2", "dimension = 4"),
            "[model] dimension",
            "3 (cubes) or 2",
        ),
        (
            ("gravity = [0.0, -9.81, 0.0]", "gravity = [0.0, 0.0, -9.81]"),
            "[loads] gravity",
            "in the plane",
        ),
        (
            ("kind = \"explicit\"", "kind = \"newmark\""),
            "[solver] kind",
            "\"explicit\", \"implicit\" or \"static\"",
        ),
        (
            ("paper+hg", "volumetric"),
            "[model] parameterization",
            "paper, springs, areal",
        ),
        (
            ("= \"paper+hg\"", "= \"paper\""),
            "[model] parameterization",
            "unstable in bending",
        ),
        (
            ("face = \"x-\"", "face = \"z-\""),
            "[[fixed]] #1",
            "no z faces",
        ),
        (
            (
                "kind = \"explicit\"",
                "kind = \"implicit\"\nprecision = \"f32\"",
            ),
            "[solver] precision",
            "Newton",
        ),
    ] {
        let e = prepare(&text.replace(change.0, change.1)).unwrap_err();
        assert!(e.contains(key) && e.contains(words), "{change:?}: {e}");
    }
    let e = prepare(&format!(
        "{text}\n[[motions]]\nselect = {{ kind = \"face\", face = \"x+\" }}\ndisplacement = [0.0, 0.0, 0.01]\n"
    ))
    .unwrap_err();
    assert!(
        e.contains("[[motions]] #1 displacement") && e.contains("x-y plane"),
        "{e}"
    );
    let moving = format!(
        "{text}\n[[obstacles]]\nshape = {{ kind = \"ground\" }}\nmotion = [[0.0, 0.0, 0.0, 0.0], [1.0, 0.1, 0.0, 0.1]]\n"
    );
    let e = prepare(&moving).unwrap_err();
    assert!(
        e.contains("[[obstacles]] #1 motion") && e.contains("2D"),
        "{e}"
    );
    let sliding_harder = format!(
        "{text}\n[[obstacles]]\nshape = {{ kind = \"ground\" }}\nfriction = 0.3\nfriction_kinetic = 0.5\n"
    );
    let e = prepare(&sliding_harder).unwrap_err();
    assert!(
        e.contains("[[obstacles]] #1") && e.contains("kinetic friction 0.5"),
        "{e}"
    );
    let capsule = format!(
        "{text}\n[[obstacles]]\nshape = {{ kind = \"capsule\", a = [0.0, 0.0, 0.0], b = [1.0, 0.0, 0.0], radius = 0.1 }}\n"
    );
    let e = prepare(&capsule).unwrap_err();
    assert!(
        e.contains("[[obstacles]] #1 shape") && e.contains("disc"),
        "{e}"
    );
    // Per-axis cell sides are for 2D bodies only.
    let cube = "[mesh]\npath = \"builtin:cube\"\nscale = 0.1\n[voxelize]\ncell_size = [0.01, 0.02]\n\
                [material]\nyoung = 1e4\npoisson = 0.3\ndensity = 1000.0\n";
    let input = SceneInput::from_toml(cube, "cube.toml");
    let e = input.map(|_| ()).unwrap_err().to_string();
    assert!(
        e.contains("[voxelize] cell_size") && e.contains("2D"),
        "{e}"
    );
    // The 3D job and its front ends say where a 2D scene runs.
    let input = SceneInput::from_toml(&text, "plane.toml").unwrap();
    let e = Job::prepare(input, Registry::default(), &no_progress)
        .unwrap_err()
        .to_string();
    assert!(e.contains("mss run"), "{e}");
}

/// An SVG of one rectangle, `width` x `height` mm, at the origin.
fn strip_svg(dir: &std::path::Path, width: u32, height: u32) -> PathBuf {
    let svg = dir.join("strip.svg");
    std::fs::write(
        &svg,
        format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\"><rect x=\"0\" y=\"0\" width=\"{width}\" height=\"{height}\"/></svg>"
        ),
    )
    .unwrap();
    svg
}

/// A 2D scene of the strip drawn in `svg` (mm): `cells` rectangles, the
/// `paper+hg` element 1 cm thick, E = 100 kPa and Poisson's ratio
/// `poisson`, its x- side held; a test adds its loads and solver.
fn strip_scene(svg: &std::path::Path, cells: &str, poisson: f64) -> String {
    format!(
        "[mesh]\npath = {:?}\nunits = \"mm\"\n[voxelize]\ncells = {cells}\n\
         [model]\ndimension = 2\nthickness = 0.01\nparameterization = \"paper+hg\"\n\
         [material]\nyoung = 1e5\npoisson = {poisson:?}\ndensity = 1000.0\n\
         [[fixed]]\nkind = \"face\"\nface = \"x-\"\n",
        svg.display().to_string()
    )
}

/// `cells = [nx, ny]`: that many rectangles along each side of the
/// outline's box (here 0.4 x 0.1 m: cells of 0.05 x 0.025 m); a 3D body
/// refuses two counts, and every count must be at least 1.
#[test]
fn cells_per_axis_give_rectangles_of_the_box() {
    let dir = tempfile::tempdir().unwrap();
    let svg = strip_svg(dir.path(), 400, 100);
    let scene = |cells: &str| {
        format!(
            "{}[solver]\nkind = \"static\"\n",
            strip_scene(&svg, cells, 0.3)
        )
    };
    let job = prepare(&scene("[8, 4]")).unwrap();
    assert_eq!(job.lattice.num_cells(), 32);
    let [lx, ly] = job.problem.model.cell_size();
    assert!(
        (lx - 0.05).abs() < 1e-12 && (ly - 0.025).abs() < 1e-12,
        "{lx} {ly}"
    );
    // One number: squares, that many along the longest side.
    let squares = prepare(&scene("8")).unwrap();
    assert_eq!(squares.lattice.num_cells(), 16);
    let e = prepare(&scene("[8, 0]")).unwrap_err();
    assert!(
        e.contains("[voxelize] cells") && e.contains("at least 1"),
        "{e}"
    );
    let cube = "[mesh]\npath = \"builtin:cube\"\nscale = 0.1\n[voxelize]\ncells = [4, 8]\n\
                [material]\nyoung = 1e4\npoisson = 0.3\ndensity = 1000.0\n";
    let e = SceneInput::from_toml(cube, "cube.toml")
        .map(|_| ())
        .unwrap_err()
        .to_string();
    assert!(e.contains("[voxelize] cells") && e.contains("2D"), "{e}");
}

/// `[[motions]]` in a 2D scene: a strip held at x-, pulled at x+ by 2 mm
/// over 0.1 s and sagging under its weight between its ends; the static
/// run, the damped explicit and the implicit runs end at the same largest
/// displacement (the sag's, more than the pull).
#[test]
fn a_strip_pulled_by_a_motion_ends_where_the_static_solve_puts_it() {
    let dir = tempfile::tempdir().unwrap();
    let svg = strip_svg(dir.path(), 200, 40);
    let scene = |solver: &str| {
        format!(
            "{}[[motions]]\nselect = {{ kind = \"face\", face = \"x+\" }}\ndisplacement = [0.002, 0.0, 0.0]\nramp = 0.1\n\
             [loads]\ngravity = [0.0, -9.81, 0.0]\n[solver]\n{solver}\nduration = 0.6\n[output]\nlast_only = true\n",
            strip_scene(&svg, "[10, 2]", 0.3)
        )
    };
    let run = |solver: &str, name: &str| {
        prepare(&scene(solver))
            .unwrap()
            .run(&dir.path().join(name), &Cancel::new())
            .unwrap()
    };
    let s = run("kind = \"static\"", "static");
    assert!(s.max_displacement > 0.0025, "{s:?}");
    for (solver, name) in [
        ("kind = \"explicit\"\ndamping = 60.0", "explicit"),
        (
            "kind = \"implicit\"\ndamping = 60.0\ndt = 0.005",
            "implicit",
        ),
    ] {
        let d = run(solver, name);
        assert!(
            (d.max_displacement - s.max_displacement).abs() < 1e-3 * s.max_displacement,
            "{name}: {} against {}",
            d.max_displacement,
            s.max_displacement
        );
    }
}

/// `[[regions]]` in a 2D scene: the right half of a long strip of nu = 0
/// four times stiffer stretches it by 5/8 of the one-material stretch (springs
/// in series); the frames carry each cell's `material`; a region that
/// selects no cell is refused by its number.
#[test]
fn a_stiffer_region_of_a_strip_stretches_as_springs_in_series() {
    let dir = tempfile::tempdir().unwrap();
    let svg = strip_svg(dir.path(), 800, 40);
    let scene = |regions: &str| {
        format!(
            "{}[[loads.forces]]\nselect = {{ kind = \"face\", face = \"x+\" }}\nforce = [0.4, 0.0, 0.0]\n\
             [solver]\nkind = \"static\"\n{regions}",
            strip_scene(&svg, "[40, 2]", 0.0)
        )
    };
    let run = |regions: &str, name: &str| {
        prepare(&scene(regions))
            .unwrap()
            .run(&dir.path().join(name), &Cancel::new())
            .unwrap()
    };
    let one = run("", "one");
    let region = "[[regions]]\nselect = { kind = \"box\", min = [0.5, 0.0, 0.0], max = [1.0, 1.0, 1.0], relative = true }\nyoung = 4e5\n";
    let two = run(region, "two");
    let ratio = two.max_displacement / one.max_displacement;
    // Up to the end's local response to equal nodal forces (1.5 % here).
    assert!((ratio - 0.625).abs() < 0.015 * 0.625, "{ratio}");
    let vtk = vtkio::Vtk::import(dir.path().join("two/lattice_0001.vtu")).unwrap();
    let vtkio::model::DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
        panic!("not an unstructured grid");
    };
    let piece = pieces[0].load_piece_data(None).unwrap();
    let material = piece
        .data
        .cell
        .iter()
        .find_map(|a| match a {
            vtkio::model::Attribute::DataArray(d) if d.name == "material" => {
                d.data.clone().cast_into::<u32>()
            }
            _ => None,
        })
        .expect("a material field");
    assert_eq!(material.iter().filter(|&&m| m == 1).count(), 40);
    let nowhere = region
        .replace("min = [0.5, 0.0, 0.0]", "min = [2.0, 0.0, 0.0]")
        .replace("max = [1.0", "max = [3.0");
    let e = prepare(&scene(&nowhere)).unwrap_err();
    assert!(
        e.contains("[[regions]] #1") && e.contains("selects no cell"),
        "{e}"
    );
}

/// `[[loads.tractions]]` in a 2D scene: 1 kPa on the free end of a strip of
/// nu = 0 stretches it by sigma L / E (4 mm); a traction out of the plane,
/// or a box holding no boundary edge, is refused by its number.
#[test]
fn a_traction_on_the_end_of_a_strip_stretches_it_by_sigma_l_over_e() {
    let dir = tempfile::tempdir().unwrap();
    let svg = strip_svg(dir.path(), 400, 40);
    let scene = |traction: &str| {
        format!(
            "{}[[loads.tractions]]\nmin = [0.399, -1.0, -1.0]\nmax = [0.401, 1.0, 1.0]\n{traction}\n\
             [solver]\nkind = \"static\"\n",
            strip_scene(&svg, "[20, 2]", 0.0)
        )
    };
    let s = prepare(&scene("traction = [1000.0, 0.0, 0.0]"))
        .unwrap()
        .run(&dir.path().join("out"), &Cancel::new())
        .unwrap();
    let expected = 1000.0 * 0.4 / 1e5;
    assert!(
        (s.max_displacement - expected).abs() < 1e-2 * expected,
        "{} against {expected}",
        s.max_displacement
    );
    let e = prepare(&scene("traction = [0.0, 0.0, 1000.0]")).unwrap_err();
    assert!(
        e.contains("[[loads.tractions]] #1 traction") && e.contains("x-y plane"),
        "{e}"
    );
    let e = prepare(
        &scene("traction = [1000.0, 0.0, 0.0]")
            .replace("min = [0.399, -1.0, -1.0]", "min = [0.399, -1.0, 0.5]"),
    )
    .unwrap_err();
    assert!(
        e.contains("[[loads.tractions]] #1") && e.contains("no boundary edge"),
        "{e}"
    );
}

/// Drag springs and custom loads in 2D: `[[loads.custom]] kind = "force"`
/// is `[[loads.forces]]`; a drag pulls the arm toward its target; a load a
/// program registers in 2D (here one lifting every node by its weight)
/// runs; a kind with no 2D form, an unknown kind and a target off the
/// plane are errors naming the entry.
#[test]
fn drags_and_custom_loads_act_on_a_2d_body() {
    use mss_core::plane::{PlaneLoad, PlaneNodalForces};
    use std::sync::Arc;
    let statics = bracket_text().replace("kind = \"explicit\"", "kind = \"static\"");
    let run = |text: &str, kinds: &mss_scene::scene::LoadKinds| {
        let input = SceneInput::from_toml(text, "plane.toml").unwrap();
        let job = PlaneJob::prepare_with(input, kinds).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let s = job.run(dir.path(), &Cancel::new()).unwrap();
        (job, s)
    };
    let kinds = mss_scene::scene::LoadKinds::default();
    let select = "select = { kind = \"face\", face = \"x+\" }";
    let (_, forces) = run(
        &format!("{statics}\n[[loads.forces]]\n{select}\nforce = [0.0, -2.0, 0.0]\n"),
        &kinds,
    );
    let (_, custom) = run(
        &format!(
            "{statics}\n[[loads.custom]]\nkind = \"force\"\n{select}\nforce = [0.0, -2.0, 0.0]\n"
        ),
        &kinds,
    );
    let (_, weight_only) = run(&statics, &kinds);
    assert!(forces.max_displacement > 1.2 * weight_only.max_displacement);
    assert!(
        (forces.max_displacement - custom.max_displacement).abs() < 1e-9 * forces.max_displacement,
        "{} vs {}",
        forces.max_displacement,
        custom.max_displacement
    );
    // A drag of the arm's end 5 cm up: it rises toward the target.
    let (job, _) = run(
        &format!(
            "{statics}\n[[loads.drags]]\n{select}\ntarget = [0.2, 0.1, 0.0]\nstiffness = 50.0\n"
        ),
        &kinds,
    );
    assert_eq!(job.problem.loads.len(), 1);
    let p = &job.problem;
    let face = p
        .model
        .select_nodes(&mss_core::constraints::NodeSelector::face(
            mss_core::constraints::Face::XMax,
        ))
        .unwrap();
    let face_y = |x: &[mss_core::Vec3]| {
        face.iter().map(|&n| x[n as usize].y).sum::<f64>() / face.len() as f64
    };
    let rest = p.model.rest_positions().to_vec();
    let mut dragged = rest.clone();
    p.solve_static(0.0, &mut dragged).unwrap();
    let mut sagging = rest.clone();
    let mut no_drag = p.clone();
    no_drag.loads.clear();
    no_drag.solve_static(0.0, &mut sagging).unwrap();
    assert!(face_y(&sagging) < face_y(&rest), "it sags without the drag");
    assert!(
        face_y(&dragged) > face_y(&rest) && face_y(&dragged) < 0.1,
        "the drag lifts the arm's end toward y = 0.1: {} from {}",
        face_y(&dragged),
        face_y(&rest)
    );
    // A program's own 2D load: every node lifted by its weight.
    let mut lifting = kinds.clone();
    lifting.register_plane(
        "uplift",
        Arc::new(|_, model| {
            let forces = (0..model.num_nodes() as u32)
                .zip(model.masses())
                .map(|(n, m)| (n, [0.0, 9.81 * m]))
                .collect();
            let load: Box<dyn PlaneLoad> =
                Box::new(PlaneNodalForces::new("uplift", model, forces)?);
            Ok(load)
        }),
    );
    let (_, lifted) = run(
        &format!("{statics}\n[[loads.custom]]\nkind = \"uplift\"\n"),
        &lifting,
    );
    assert!(lifted.max_displacement < 1e-9, "{lifted:?}");
    // Errors.
    let mut only_3d = kinds.clone();
    only_3d.register(
        "wind",
        Arc::new(|_, _| {
            Ok(Box::new(mss_core::loads::Gravity {
                g: mss_core::Vec3::zeros(),
            }))
        }),
    );
    for (text, kinds, key, words) in [
        (
            format!("{statics}\n[[loads.custom]]\nkind = \"wind\"\n"),
            &only_3d,
            "[[loads.custom]] #1",
            "no 2D form",
        ),
        (
            format!("{statics}\n[[loads.custom]]\nkind = \"gust\"\n"),
            &kinds,
            "[[loads.custom]] #1",
            "unknown load kind",
        ),
        (
            format!(
                "{statics}\n[[loads.drags]]\n{select}\ntarget = [0.2, 0.1, 0.3]\nstiffness = 50.0\n"
            ),
            &kinds,
            "[[loads.drags]] #1",
            "x-y plane",
        ),
        (
            format!(
                "{statics}\n[[loads.custom]]\nkind = \"force\"\nselect = {{ kind = \"face\", face = \"z-\" }}\nforce = [1.0, 0.0, 0.0]\n"
            ),
            &kinds,
            "[[loads.custom]] #1",
            "no z faces",
        ),
    ] {
        let input = SceneInput::from_toml(&text, "plane.toml").unwrap();
        let e = PlaneJob::prepare_with(input, kinds)
            .unwrap_err()
            .to_string();
        assert!(e.contains(key) && e.contains(words), "{key}: {e}");
    }
}

const SECTION: &str = include_str!("../../../../data/scenes/section.toml");

fn section_text() -> String {
    let image = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/images/section.nrrd")
        .canonicalize()
        .unwrap();
    SECTION.replace("../images/section.nrrd", &image.display().to_string())
}

/// The bundled section (a 2D label image): its cells carry the labels,
/// the nodule's cells take the region's material, the vessel is a hole,
/// the frames carry `label`; the probe's static press ends where the
/// damped run does; a volume is refused as a 2D body's image.
#[test]
fn a_label_slice_becomes_a_2d_body() {
    let job = prepare(&section_text()).unwrap();
    let labels = job.cell_labels.as_ref().unwrap();
    assert_eq!(labels.len(), job.lattice.num_cells());
    let nodule = labels.iter().filter(|&&l| l == 2).count();
    // A disc of 3 mm radius in cells of 1 mm^2.
    assert!((20..=36).contains(&nodule), "{nodule}");
    assert!(labels.iter().all(|&l| l == 1 || l == 2));
    let materials = job.problem.model.cell_materials();
    for (l, m) in labels.iter().zip(materials) {
        assert_eq!(*m, u32::from(*l == 2));
    }
    // No cell within 1 mm of the vessel's centre (12, 10) mm.
    let nodes = job.lattice.nodes();
    for c in job.lattice.cells() {
        let x = c.iter().map(|&n| nodes[n as usize][0]).sum::<f64>() / 4.0;
        let y = c.iter().map(|&n| nodes[n as usize][1]).sum::<f64>() / 4.0;
        assert!(
            (x - 0.012).hypot(y - 0.010) > 1e-3,
            "a cell at ({x}, {y}) in the vessel"
        );
    }
    assert_eq!(
        job.outline.polygons().len(),
        2,
        "the section and its vessel"
    );
    let dir = tempfile::tempdir().unwrap();
    let run = job.run(&dir.path().join("run"), &Cancel::new()).unwrap();
    let vtk = vtkio::Vtk::import(dir.path().join("run/lattice_0001.vtu")).unwrap();
    let vtkio::model::DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
        panic!("not an unstructured grid");
    };
    let piece = pieces[0].load_piece_data(None).unwrap();
    let names: Vec<String> = piece
        .data
        .cell
        .iter()
        .map(|a| a.name().to_owned())
        .collect();
    assert!(
        names.contains(&"label".to_owned()) && names.contains(&"material".to_owned()),
        "{names:?}"
    );
    // The probe goes 4 mm down; the tissue under it follows by most of it.
    assert!(
        run.max_displacement > 2e-3 && run.max_displacement < 4.5e-3,
        "{run:?}"
    );
    let statics = prepare(&section_text().replace("kind = \"explicit\"", "kind = \"static\""))
        .unwrap()
        .run(&dir.path().join("static"), &Cancel::new())
        .unwrap();
    assert!(
        (statics.max_displacement - run.max_displacement).abs() < 0.02 * statics.max_displacement,
        "static {} dynamic {}",
        statics.max_displacement,
        run.max_displacement
    );
    // A volume is not a slice.
    let organ = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/images/organ.nii.gz")
        .canonicalize()
        .unwrap();
    let text = section_text().replace(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../data/images/section.nrrd")
            .canonicalize()
            .unwrap()
            .display()
            .to_string(),
        &organ.display().to_string(),
    );
    let e = prepare(&text).unwrap_err();
    assert!(e.contains("[image]") && e.contains("one slice"), "{e}");
}
