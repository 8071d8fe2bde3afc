//! Scenes of several bodies (`[[bodies]]`): the bundled stack rests with
//! the upper cube's weight carried by the lower one; each body keeps its own
//! held nodes and loads; the outputs hold every body; bad values of every
//! new key are typed errors naming the key.

use mss_core::Vec3;
use mss_core::solver::State;
use mss_scene::{Job, Registry, SceneInput, no_progress};

const STACK: &str = include_str!("../../../../data/scenes/stack.toml");
const SQUEEZE: &str = include_str!("../../../../data/scenes/squeeze.toml");

fn job(text: &str) -> Job {
    let input = SceneInput::from_toml(text, "bodies.toml").unwrap();
    Job::prepare(input, Registry::default(), &no_progress).unwrap()
}

/// Steps `job` to `seconds`; returns the state.
fn run_to(job: &Job, seconds: f64) -> State {
    run_seeing_steps(job, seconds, |_| {})
}

/// [`run_to`], showing `each` every step's figures.
fn run_seeing_steps(
    job: &Job,
    seconds: f64,
    mut each: impl FnMut(&mss_core::solver::StepInfo),
) -> State {
    let mut it = job
        .input
        .integrator(&job.registry, &job.problem, &job.plan)
        .unwrap()
        .unwrap();
    let mut s = State::at_rest(job.problem.model());
    while s.time < seconds {
        each(&it.step(&job.problem, &mut s).unwrap());
    }
    s
}

#[test]
fn the_bundled_stack_rests_with_the_upper_weight_carried_by_the_lower_cube() {
    let text = STACK.replace("damping = 10.0", "damping = 25.0");
    let job = job(&text);
    assert_eq!(job.bodies.len(), 2);
    assert_eq!(job.bodies[1].name, "upper");
    let s = run_to(&job, 1.0);
    let model = job.problem.model();
    let contact = job.problem.contact().unwrap();
    let bodies = contact.bodies().unwrap();
    let anchors = &s.contact[s.contact.len() - bodies.num_points()..];
    let between = bodies.body_forces(&s.x, &s.v, anchors);
    let g = 9.81;
    let upper: f64 = model.masses()[model.bodies()[1].nodes.clone()]
        .iter()
        .sum::<f64>()
        * g;
    assert!(
        (between[1].z - upper).abs() < 0.01 * upper,
        "{} N for a weight of {upper} N",
        between[1].z
    );
    assert!((between[0] + between[1]).norm() < 1e-9 * upper);
    let ground: Vec3 = job.problem.contact_forces(&s).iter().sum();
    let weight = model.total_mass() * g;
    assert!(
        (ground.z - weight).abs() < 0.01 * weight,
        "{ground:?} vs {weight}"
    );
    // Nothing is inside anything beyond 2 % of the finer cell.
    assert!(bodies.max_depth(&s.x) < 0.02 * model.h());
}

/// `[solver] start = "settled"`: the stack with no damping at all starts
/// at rest under its weight (the upper cube, placed 5 mm above, has landed
/// and settled) and stays there: its largest displacement over the run is
/// the one it starts with, and the upper weight crosses the contact.
/// Started at rest, the same scene drops and rings.
#[test]
fn a_settled_stack_starts_at_rest_and_stays_without_damping() {
    let run = |start: &str| {
        let text = STACK
            .replace(
                "damping = 10.0",
                &format!("damping = 0.0\nstart = \"{start}\""),
            )
            .replace("duration = 1.0", "duration = 0.3")
            .replace("every_time = 0.02", "every_time = 0.1");
        let out = tempfile::tempdir().unwrap();
        job(&text)
            .run(out.path(), &no_progress, &mss_scene::Cancel::new())
            .unwrap()
    };
    let summary = run("settled");
    let settled = summary.settled.expect("settled");
    assert!(
        settled.steps > 0 && settled.relative_residual <= 1e-4,
        "{settled:?}"
    );
    let upper = 0.216 * 9.81;
    let between = summary.bodies[1].contact_force_from_bodies;
    assert!((between[2] - upper).abs() < 0.01 * upper, "{between:?}");
    let (end, peak) = (summary.max_displacement, summary.peak_displacement);
    assert!(peak - end < 1e-4 * end, "moved: peak {peak} m, end {end} m");
    let summary = run("rest");
    assert!(summary.settled.is_none());
    let (end, peak) = (summary.max_displacement, summary.peak_displacement);
    assert!(
        peak - end > 1e-2 * end,
        "dropped and rang: peak {peak} m, end {end} m"
    );
}

/// A static solve of bodies that only contact holds (the bundled squeeze:
/// no node is fixed, the ball starts above the block): Newton has nothing
/// to start from and says what works; settled (backward Euler, along the
/// plate's path), the ball rests between the block and the pressing plate,
/// and the two push each other equally.
#[test]
fn a_static_settle_holds_bodies_only_contact_holds() {
    // At 0.6 s the plate is 3 cm down, 2 cm into the ball: placed there at
    // once it would shoot the ball out; the settling follows its path.
    let text = SQUEEZE
        .replace("cells = 12", "cells = 8")
        .replace("duration = 1.2", "duration = 0.6")
        .replace("kind = \"explicit\"", "kind = \"static\"");
    let out = tempfile::tempdir().unwrap();
    let e = job(&text)
        .run(out.path(), &no_progress, &mss_scene::Cancel::new())
        .unwrap_err()
        .to_string();
    assert!(e.contains("start = \"settled\""), "{e}");
    let text = text.replace("[solver]", "[solver]\nstart = \"settled\"");
    let summary = job(&text)
        .run(out.path(), &no_progress, &mss_scene::Cancel::new())
        .unwrap();
    let settled = summary.settled.unwrap();
    assert!(settled.relative_residual <= 1e-4);
    // Backward Euler settled it: its Newton iterations are the solve's.
    assert!(settled.newton_iterations > 0);
    assert_eq!(summary.newton_iterations, settled.newton_iterations);
    let (a, b) = (
        summary.bodies[0].contact_force_from_bodies,
        summary.bodies[1].contact_force_from_bodies,
    );
    let ball_weight = summary.bodies[1].mass * 9.81;
    assert!(
        a[2] < -5.0 * ball_weight && (a[2] + b[2]).abs() < 1e-9 * a[2].abs(),
        "{a:?} {b:?}"
    );
}

/// A static solve that fails because one body floats free (the block is
/// held, the ball above it touches nothing) names that body as the scene
/// does.
#[test]
fn a_static_solve_names_the_body_that_floats_free() {
    let text = SQUEEZE
        .replace("cells = 12", "cells = 6")
        .replace("duration = 1.2", "duration = 0.1")
        .replace("kind = \"explicit\"", "kind = \"static\"")
        .replace(
            "translate = [0.0, 0.0, 0.03]\n",
            "translate = [0.0, 0.0, 0.03]\n[[bodies.fixed]]\nkind = \"lowest_layer\"\n",
        );
    let out = tempfile::tempdir().unwrap();
    let e = job(&text)
        .run(out.path(), &no_progress, &mss_scene::Cancel::new())
        .unwrap_err()
        .to_string();
    assert!(e.contains("body \"ball\" has no fixed node"), "{e}");
    assert!(e.contains("start = \"settled\""), "{e}");
}

#[test]
fn a_squeezed_ball_and_the_block_push_each_other_equally_and_the_outputs_hold_both() {
    // The bundled squeeze until the plate presses hardest, frames every 0.1 s.
    let text = SQUEEZE
        .replace("duration = 1.2", "duration = 0.6")
        .replace("every_time = 0.02", "every_time = 0.1")
        .replace("cells = 12", "cells = 8");
    let job = job(&text);
    let out = tempfile::tempdir().unwrap();
    let summary = job
        .run(out.path(), &no_progress, &mss_scene::Cancel::new())
        .unwrap();
    assert_eq!(summary.bodies.len(), 2);
    assert_eq!(summary.bodies[0].name, "block");
    assert_eq!(
        summary.cells,
        summary.bodies.iter().map(|b| b.cells).sum::<usize>()
    );
    // The plate pushes the ball into the block: equal and opposite.
    let (a, b) = (
        summary.bodies[0].contact_force_from_bodies,
        summary.bodies[1].contact_force_from_bodies,
    );
    assert!(
        a[2] < -1.0 && (a[2] + b[2]).abs() < 1e-9 * a[2].abs(),
        "{a:?} {b:?}"
    );
    // Each body has its own files, its name after the stem, and
    // lattice.pvd lists both as the parts of each frame.
    let pvd = mss_io::vtk::read::read_pvd(&out.path().join("lattice.pvd")).unwrap();
    assert_eq!(pvd.len(), 2 * 7, "7 frames of 2 parts");
    for (k, body) in job.bodies.iter().enumerate() {
        let entry = &pvd[2 * 6 + k];
        assert_eq!(entry.part, k as u32);
        assert_eq!(entry.name.as_deref(), Some(body.name.as_str()));
        assert_eq!(entry.file, format!("lattice_{}_0006.vtu", body.name));
        let frame =
            mss_io::vtk::read::read_lattice_vtu(&out.path().join(&entry.file), 1 << 30).unwrap();
        assert_eq!(frame.points.len(), body.lattice.num_nodes());
        assert_eq!(frame.cells.len(), summary.bodies[k].cells);
        let own_pvd = out.path().join(format!("lattice_{}.pvd", body.name));
        assert_eq!(mss_io::vtk::read::read_pvd(&own_pvd).unwrap().len(), 7);
        // The embedded surface per body and frame, as one series per body.
        let surface = out.path().join(format!("surface_{}_0006.vtu", body.name));
        let frame = mss_io::vtk::read::read_surface_vtu(&surface, 1 << 30).unwrap();
        assert_eq!(frame.points.len(), body.mesh.vertices.len());
        let surface_pvd = out.path().join(format!("surface_{}.pvd", body.name));
        assert_eq!(mss_io::vtk::read::read_pvd(&surface_pvd).unwrap().len(), 7);
    }
    // Every file of the run is recognised as one (a new run there removes
    // them), and counted in the summary.
    let written: Vec<_> = std::fs::read_dir(out.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    let exporters = mss_scene::Registry::default().exporters;
    let recognised = mss_scene::output::previous_run_files(out.path(), &exporters);
    assert_eq!(recognised.len(), written.len(), "{written:?}");
}

#[test]
fn each_body_keeps_its_own_held_nodes_and_loads() {
    // Two columns side by side, each held at its base, pushed sideways by
    // its own force: each bends its own way; the top-level gravity pulls
    // both.
    let column = |name: &str, x: f64, force: &str| {
        format!(
            "[[bodies]]\nname = \"{name}\"\n[bodies.mesh]\npath = \"builtin:cube\"\n\
             scale = [0.02, 0.02, 0.1]\ntranslate = [{x}, 0.0, 0.05]\n[bodies.voxelize]\n\
             cells = 10\n[bodies.material]\nyoung = 1.0e6\npoisson = 0.3\ndensity = 1000.0\n\
             [[bodies.fixed]]\nkind = \"lowest_layer\"\n[[bodies.loads.forces]]\n\
             select = {{ kind = \"box\", min = [-1.0, -1.0, 0.099], max = [1.0, 1.0, 1.0] }}\n\
             force = {force}\n"
        )
    };
    let text = format!(
        "[loads]\ngravity = [0.0, 0.0, -9.81]\n[solver]\nkind = \"static\"\n{}{}",
        column("left", 0.0, "[0.5, 0.0, 0.0]"),
        column("right", 0.1, "[0.0, -0.5, 0.0]")
    );
    let job = job(&text);
    let model = job.problem.model();
    let mut s = State::at_rest(model);
    mss_core::solve_static(&job.problem, &mut s, &job.input.static_options()).unwrap();
    let tip = |b: usize| {
        let span = &model.bodies()[b];
        let (x, r) = (
            &s.x[span.nodes.clone()],
            &model.rest_positions()[span.nodes.clone()],
        );
        let top = r.iter().map(|p| p.z).fold(f64::MIN, f64::max);
        let moved: Vec<Vec3> = x
            .iter()
            .zip(r)
            .filter(|(_, p)| p.z > top - 1e-9)
            .map(|(x, p)| x - p)
            .collect();
        moved.iter().sum::<Vec3>() / moved.len() as f64
    };
    let (left, right) = (tip(0), tip(1));
    assert!(left.x > 1e-4 && left.y.abs() < 1e-3 * left.x, "{left:?}");
    assert!(
        right.y < -1e-4 && right.x.abs() < 1e-3 * right.y.abs(),
        "{right:?}"
    );
    assert!(left.z < 0.0 && right.z < 0.0, "gravity on both");
    let held = model
        .bodies()
        .iter()
        .map(|b| {
            b.nodes
                .clone()
                .filter(|&n| job.problem.constraints().mask(n)[0])
                .count()
        })
        .collect::<Vec<_>>();
    assert_eq!(held[0], held[1]);
    assert!(held[0] > 0);
}

#[test]
fn every_bodys_embedded_surface_touches_the_obstacles_when_asked() {
    let text = SQUEEZE.replace("[contact]\n", "[contact]\npoints = \"both\"\n");
    let job = job(&text);
    let contact = job.problem.contact().unwrap();
    let surface_vertices: usize = job.bodies.iter().map(|b| b.mesh.vertices.len()).sum();
    assert_eq!(contact.surface_points().len(), surface_vertices);
    // And they land on the block: the ball's surface vertices are never
    // inside the plate or the ground after a short run.
    let s = run_to(&job, 0.05);
    assert!(s.x.iter().all(|x| x.z > -1e-3));
}

#[test]
fn bad_bodies_are_typed_errors_naming_the_key() {
    let body = |name: &str, extra: &str| {
        format!(
            "[[bodies]]\nname = \"{name}\"\n[bodies.mesh]\npath = \"builtin:cube\"\nscale = 0.1\n\
             [bodies.material]\nyoung = 1e5\npoisson = 0.3\ndensity = 1000.0\n{extra}"
        )
    };
    let cases = [
        (
            format!("{}{}", body("a", ""), body("a", "")),
            "[[bodies]] #2 name",
        ),
        (body("a b", ""), "[[bodies]] #1 name"),
        (
            format!("[mesh]\npath = \"builtin:cube\"\n{}", body("a", "")),
            "[mesh]",
        ),
        (
            format!("[[fixed]]\nkind = \"lowest_layer\"\n{}", body("a", "")),
            "[[fixed]]",
        ),
        (
            body("a", "[bodies.loads]\ngravity = [0.0, 0.0, -9.81]\n"),
            "[[bodies]] #1 (a) [loads] gravity",
        ),
        (
            body("a", "[bodies.voxelize]\ncells = 0\n"),
            "[[bodies]] #1 (a) [voxelize] cells",
        ),
        (body("a", "[bodies.material]\n"), "material"),
        (
            format!("[contact]\nfriction = -1.0\n{}", body("a", "")),
            "[contact] friction",
        ),
        (
            format!("[contact]\nstiffness = 0.0\n{}", body("a", "")),
            "[contact] stiffness",
        ),
        (
            format!(
                "[contact]\nfriction = 0.2\nfriction_kinetic = 0.5\n{}",
                body("a", "")
            ),
            "[contact] friction_kinetic",
        ),
        (body("a", "self_contact = 3\n"), "self_contact"),
        (
            body(
                "a",
                "[[bodies.fixed]]\nkind = \"box\"\nmin = [1.0, 0.0, 0.0]\nmax = [0.0, 1.0, 1.0]\n",
            ),
            "[[bodies]] #1 (a) [[fixed]] #1",
        ),
        ("[solver]\nkind = \"static\"\n".to_owned(), "[mesh]"),
        (
            format!("[solver]\nstart = \"later\"\n{}", body("a", "")),
            "start",
        ),
        (
            format!("[solver]\nsettle_time = -1.0\n{}", body("a", "")),
            "settle_time",
        ),
        (
            format!("[solver]\nsettle_tolerance = 2.0\n{}", body("a", "")),
            "settle_tolerance",
        ),
    ];
    for (text, key) in cases {
        let e = SceneInput::from_toml(&text, "bad.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains(key), "{key}: {e}");
        assert!(!e.contains('\n'), "{e}");
    }
    // Found when the job is built: a body whose selection is empty, and
    // surface contact points, which bodies do not have yet.
    let prepare = |text: String| {
        let input = SceneInput::from_toml(&text, "bad.toml").unwrap();
        Job::prepare(input, Registry::default(), &no_progress)
            .unwrap_err()
            .to_string()
    };
    let e = prepare(body(
        "a",
        "[[bodies.fixed]]\nkind = \"box\"\nmin = [5.0, 5.0, 5.0]\nmax = [6.0, 6.0, 6.0]\n",
    ));
    assert!(e.contains("[[bodies]] #1 (a) [[fixed]] #1"), "{e}");
}

#[test]
fn a_run_of_several_bodies_interrupted_and_resumed_writes_the_uninterrupted_files() {
    // Every per-body output on: lattice (.vtu and .vtk), skins with point
    // caches, embedded surfaces, springs.
    let text = STACK
        .replace("duration = 1.0", "duration = 0.06")
        .replace(
            "every_time = 0.02     # s",
            "every_time = 0.01\npc2 = true\nvtk = true\nembedded = true\nsprings = true",
        )
        .replace("cells = 8", "cells = 4");
    let job = job(&text);
    let whole = tempfile::tempdir().unwrap();
    let reference = job
        .run(whole.path(), &no_progress, &mss_scene::Cancel::new())
        .unwrap();
    let cut = tempfile::tempdir().unwrap();
    let cancel = mss_scene::Cancel::new();
    let stop_at = job.plan.steps / 2 + 1;
    let progress = |p: mss_scene::Progress| {
        if let mss_scene::Progress::Stepping { done, .. } = p
            && done == stop_at
        {
            cancel.cancel();
        }
    };
    assert!(job.run(cut.path(), &progress, &cancel).unwrap().interrupted);
    let resumed = job
        .resume(cut.path(), &no_progress, &mss_scene::Cancel::new())
        .unwrap();
    assert_eq!(resumed.bytes_written, reference.bytes_written);
    let contents = |dir: &std::path::Path| {
        let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .map(|p| {
                (
                    p.file_name().unwrap().to_string_lossy().into_owned(),
                    std::fs::read(&p).unwrap(),
                )
            })
            .collect();
        files.sort();
        files
    };
    let (a, b) = (contents(cut.path()), contents(whole.path()));
    assert_eq!(
        a.iter().map(|f| &f.0).collect::<Vec<_>>(),
        b.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    assert!(a == b, "the resumed files differ");
    for name in [
        "lattice_upper_0006.vtu",
        "skin_lower.pc2",
        "surface_upper_rest.obj",
        "springs_0006.vtu",
    ] {
        assert!(b.iter().any(|f| f.0 == name), "{name} written");
    }
}

/// A ball dropped 2 mm onto a block (the bundled squeeze without its
/// plate), `[contact] points` as given, run 1 s with damping: the ball's
/// weight through the contact, and how far the ball's drawn surface ends
/// above the block's (negative: inside it).
fn ball_on_block(points: &str) -> (f64, f64, f64, f64) {
    let plate = SQUEEZE
        .find("[[obstacles]]\nshape = { kind = \"box\"")
        .unwrap();
    let end = plate + SQUEEZE[plate..].find("\n\n").unwrap();
    let text = format!(
        "{}{}",
        &SQUEEZE[..plate],
        &SQUEEZE[end..]
            .replace(
                "[contact]\n",
                &format!("[contact]\npoints = \"{points}\"\n")
            )
            .replace("damping = 10.0", "damping = 30.0")
            .replace("cells = 12", "cells = 10")
            // The block's top half-way through a layer of its 12 mm cells.
            .replace("scale = [0.12, 0.12, 0.06]", "scale = [0.12, 0.12, 0.066]")
            .replace(
                "translate = [0.0, 0.0, 0.03]",
                "translate = [0.0, 0.0, 0.033]"
            )
            .replace(
                "translate = [0.0, 0.0, 0.102]",
                "translate = [0.0, 0.0, 0.108]"
            )
    );
    let job = job(&text);
    let s = run_to(&job, 1.0);
    let model = job.problem.model();
    let bodies = job.problem.contact().unwrap().bodies().unwrap();
    assert_eq!(bodies.on_embedded_surface(), points != "nodes");
    let anchors = &s.contact[s.contact.len() - bodies.num_points()..];
    let between = bodies.body_forces(&s.x, &s.v, anchors);
    let ball_weight: f64 = model.masses()[model.bodies()[1].nodes.clone()]
        .iter()
        .sum::<f64>()
        * 9.81;
    let embedding = job.embedding();
    let surface = embedding.deform(mss_core::as_arrays(&s.x));
    let ball = |i: usize| model.body_of_node(embedding.vertex_cells()[i][0] as usize) == 1;
    let lowest_ball = (0..surface.len())
        .filter(|&i| ball(i))
        .map(|i| surface[i][2])
        .fold(f64::INFINITY, f64::min);
    // The block's top face (the built-in cube's top corners).
    let block_top = (0..surface.len())
        .filter(|&i| !ball(i))
        .map(|i| surface[i][2])
        .fold(f64::NEG_INFINITY, f64::max);
    (
        between[1].z / ball_weight,
        (between[0] + between[1]).norm() / ball_weight,
        lowest_ball - block_top,
        bodies.max_depth(&s.x) / model.h(),
    )
}

/// With `[contact] points = "both"` the bodies touch where they are drawn:
/// a ball resting on a block whose top lies half-way through a layer of its
/// cells ends with its drawn surface on the block's (overlapping by the
/// penalty's depth, 1.3 mm here), where through the lattices it floats
/// 2.5 mm above it (the lattice's top is not the drawn top). The weight
/// goes through the contact either way.
#[test]
fn bodies_touch_through_their_drawn_surfaces_with_points_both() {
    let h_block = 0.012;
    let (carried, imbalance, gap, depth) = ball_on_block("both");
    assert!(
        (carried - 1.0).abs() < 0.01,
        "carried {carried} of the weight"
    );
    assert!(imbalance < 1e-9, "action != reaction by {imbalance}");
    assert!(
        gap <= 0.0 && gap > -0.15 * h_block,
        "the drawn surfaces {gap} m apart"
    );
    assert!(depth < 0.15, "{depth} cells deep");
    let (carried, _, lattice_gap, _) = ball_on_block("nodes");
    assert!(
        (carried - 1.0).abs() < 0.01,
        "carried {carried} of the weight"
    );
    assert!(
        lattice_gap > 0.1 * h_block,
        "through the lattices the drawn surfaces are {lattice_gap} m apart"
    );
}

/// The bundled squeeze stepped implicitly at 10 ms through the ball's
/// landing and the plate's press (0.5 s): every step is taken whole, no
/// Newton solve fails. Before points kept the triangles they were anchored
/// to ([`mss_core::contact::TRIANGLE_PREFERENCE`]), the landing's points
/// switched between the two halves of bent faces at every Newton iteration
/// and the run stopped at 0.05 s with its step halved down to 1.25 ms.
#[test]
fn the_bundled_squeeze_steps_implicitly_without_halving_a_step() {
    let text = SQUEEZE
        .replace("kind = \"explicit\"", "kind = \"implicit\"\ndt = 0.01")
        .replace("duration = 1.2", "duration = 0.5");
    let job = job(&text);
    let mut newton = 0;
    let s = run_seeing_steps(&job, 0.5 - 1e-9, |info| {
        assert_eq!(info.substeps, 1, "the step to {} s was halved", info.time);
        newton += info.newton_iterations;
    });
    // The plate presses the ball into the block: they push each other.
    let bodies = job.problem.contact().unwrap().bodies().unwrap();
    let anchors = &s.contact[s.contact.len() - bodies.num_points()..];
    let between = bodies.body_forces(&s.x, &s.v, anchors);
    assert!(between[1].z > 1.0, "{between:?}");
    assert!(newton < 8 * 50, "{newton} Newton iterations in 50 steps");
}
