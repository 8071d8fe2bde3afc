//! A scene run through the library: progress, cancellation, plug points
//! reached by name, frame times and the time plan.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use mss_core::solver::{Integrator, IntegratorSettings, Problem, SolverError, State, StepInfo};
use mss_scene::{Cancel, Job, LoadCheckBudget, Progress, Registry, SceneInput, no_progress};

fn scene(extra: &str) -> String {
    format!(
        "[mesh]\npath = \"builtin:critter\"\n[voxelize]\ncells = 8\n[material]\nyoung = 1.0e5\n\
         poisson = 0.3\ndensity = 1000.0\n[[fixed]]\nkind = \"lowest_layer\"\n[loads]\n\
         gravity = [0.0, 0.0, -9.81]\n{extra}"
    )
}

fn input(extra: &str) -> SceneInput {
    SceneInput::from_toml(&scene(extra), "test.toml").unwrap()
}

fn prepared(extra: &str) -> Job {
    Job::prepare(input(extra), Registry::default(), &no_progress).unwrap()
}

/// Times listed in a `.pvd` file.
fn pvd_times(path: &std::path::Path) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    text.split("timestep=\"")
        .skip(1)
        .map(|t| t.split('"').next().unwrap().parse().unwrap())
        .collect()
}

#[test]
fn frames_land_on_multiples_of_every_time() {
    let job = Job::prepare(
        input("[solver]\nduration = 0.02\n[output]\nevery_time = 0.005\n"),
        Registry::default(),
        &no_progress,
    )
    .unwrap();
    // The automatic step divides the frame interval.
    let per_frame = 0.005 / job.plan.dt;
    assert!((per_frame - per_frame.round()).abs() < 1e-9, "{per_frame}");
    assert!(job.plan.dt <= job.plan.stable_dt);
    let out = tempfile::tempdir().unwrap();
    let steps = AtomicU64::new(0);
    let summary = job
        .run(
            out.path(),
            &|p| {
                if let Progress::Stepping { done, total } = p {
                    assert!(done <= total);
                    steps.store(done, Ordering::Relaxed);
                }
            },
            &Cancel::new(),
        )
        .unwrap();
    assert_eq!(steps.load(Ordering::Relaxed), summary.steps);
    assert_eq!(summary.frames as u64, job.plan.num_frames());
    let times = pvd_times(&out.path().join("lattice.pvd"));
    assert_eq!(times.len(), 5);
    for (k, t) in times.iter().enumerate() {
        assert!((t - 0.005 * k as f64).abs() < 1e-12, "frame {k} at {t}");
    }
    // Printed as the round numbers they are, not the sums of the steps.
    let text = std::fs::read_to_string(out.path().join("lattice.pvd")).unwrap();
    for k in 0..5 {
        let t = ["0", "0.005", "0.01", "0.015", "0.02"][k];
        assert!(text.contains(&format!("timestep=\"{t}\"")), "{text}");
    }
    assert!((summary.simulated_time - 0.02).abs() < 1e-12);
}

#[test]
fn a_given_step_that_does_not_divide_the_interval_writes_at_the_first_step_past_it() {
    let job = Job::prepare(
        input("[solver]\nduration = 0.01\ndt = 3e-4\n[output]\nevery_time = 0.002\n"),
        Registry::default(),
        &no_progress,
    )
    .unwrap();
    let out = tempfile::tempdir().unwrap();
    let summary = job.run(out.path(), &no_progress, &Cancel::new()).unwrap();
    let times = pvd_times(&out.path().join("lattice.pvd"));
    assert_eq!(times.len() as u64, job.plan.num_frames());
    assert_eq!(summary.frames, times.len());
    // 0, then the first step at or past 0.002, 0.004, ..., and the last step.
    for (k, t) in times.iter().enumerate().skip(1).take(4) {
        let due = 0.002 * k as f64;
        assert!(*t >= due - 1e-12 && *t < due + 3e-4, "frame {k} at {t}");
    }
}

#[test]
fn cancel_stops_between_steps_and_keeps_the_state_reached() {
    let job = Job::prepare(
        input("[solver]\nduration = 0.05\n[output]\nevery_steps = 1000\n"),
        Registry::default(),
        &no_progress,
    )
    .unwrap();
    let out = tempfile::tempdir().unwrap();
    let cancel = Cancel::new();
    let summary = job
        .run(
            out.path(),
            &|p| {
                if let Progress::Stepping { done: 7, .. } = p {
                    cancel.cancel();
                }
            },
            &cancel,
        )
        .unwrap();
    assert!(summary.interrupted);
    assert_eq!(summary.steps, 7);
    assert!((summary.simulated_time - 7.0 * job.plan.dt).abs() < 1e-12);
    // The initial frame and the state reached.
    let times = pvd_times(&out.path().join("lattice.pvd"));
    assert_eq!(times.len(), 2);
    assert!((times[1] - 7.0 * job.plan.dt).abs() < 1e-12);
}

/// Symplectic Euler written outside the library, keeping the integrator contract.
struct OutsideEuler {
    dt: f64,
    f: Vec<mss_core::Vec3>,
    g: Vec<mss_core::Vec3>,
}

impl Integrator for OutsideEuler {
    fn name(&self) -> &'static str {
        "outside-euler"
    }
    fn dt(&self) -> f64 {
        self.dt
    }
    fn step(&mut self, problem: &Problem, state: &mut State) -> Result<StepInfo, SolverError> {
        let model = problem.model();
        model.internal_forces(&state.x, &mut self.f);
        self.g.iter_mut().for_each(|v| *v = mss_core::Vec3::zeros());
        problem.external_forces(state.time, &state.x, 1.0, &mut self.g);
        for n in 0..model.num_nodes() {
            let a = (self.f[n] + self.g[n]) * (self.dt / model.masses()[n]);
            let held = problem.constraints().mask(n);
            for d in (0..3).filter(|&d| !held[d]) {
                state.v[n][d] += a[d];
                state.x[n][d] += state.v[n][d] * self.dt;
            }
        }
        state.time += self.dt;
        problem.apply_constraints(state);
        Ok(StepInfo {
            time: state.time,
            dt: self.dt,
            substeps: 1,
            newton_iterations: 0,
        })
    }
}

#[test]
fn registered_plugins_are_reached_from_scene_names() {
    let mut registry = Registry::default();
    registry.integrators.register(
        "outside-euler",
        Arc::new(|p: &Problem, s: &IntegratorSettings| {
            let n = p.model().num_nodes();
            Ok(Box::new(OutsideEuler {
                dt: s.dt.unwrap_or(1e-4),
                f: vec![mss_core::Vec3::zeros(); n],
                g: vec![mss_core::Vec3::zeros(); n],
            }) as Box<dyn Integrator>)
        }),
    );
    let extra = "[solver]\nkind = \"outside-euler\"\ndt = 1e-4\nduration = 0.002\n\
                 [output]\nlast_only = true\n";
    let job = Job::prepare(input(extra), registry.clone(), &no_progress).unwrap();
    let out = tempfile::tempdir().unwrap();
    let outside = job.run(out.path(), &no_progress, &Cancel::new()).unwrap();
    assert_eq!(outside.solver, "outside-euler");
    assert_eq!(outside.steps, 20);
    // The same run with the built-in symplectic Euler gives the same motion.
    let builtin = input(&extra.replace("outside-euler", "symplectic-euler"));
    let job = Job::prepare(builtin, registry.clone(), &no_progress).unwrap();
    let out2 = tempfile::tempdir().unwrap();
    let inside = job.run(out2.path(), &no_progress, &Cancel::new()).unwrap();
    let rel = (outside.max_displacement - inside.max_displacement).abs() / inside.max_displacement;
    assert!(
        rel < 1e-9,
        "{} vs {}",
        outside.max_displacement,
        inside.max_displacement
    );
    // Unknown names are refused with the registry's list, before any file is written.
    let err = Job::prepare(input("[solver]\nkind = \"rk4\"\n"), registry, &no_progress)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("[solver] kind") && err.contains("outside-euler"),
        "{err}"
    );
}

#[test]
fn names_and_values_are_refused_with_their_key() {
    let cases = [
        (
            "[model]\nparameterization = \"magic\"\n",
            "[model] parameterization",
        ),
        ("[model]\nhourglass = -1.0\n", "[model] hourglass"),
        (
            "[[motions]]\nselect = { kind = \"box\", min = [5, 5, 5], max = [6, 6, 6] }\ndisplacement = [0, 0, 0.01]\n",
            "[[motions]] #1",
        ),
        ("[output]\nexporters = [\"vtp\"]\n", "vtp"),
    ];
    for (extra, needle) in cases {
        let r = Job::prepare(input(extra), Registry::default(), &no_progress);
        let err = match r {
            Err(e) => e.to_string(),
            Ok(job) => {
                let out = tempfile::tempdir().unwrap();
                job.run(out.path(), &no_progress, &Cancel::new())
                    .unwrap_err()
                    .to_string()
            }
        };
        assert!(err.contains(needle), "{extra:?}: {err}");
        assert!(!err.contains('\n'), "{err}");
    }
}

#[test]
fn the_bundled_scene_parses_and_plans() {
    let input = SceneInput::bundled_default();
    assert_eq!(input.scene.solver.kind, "explicit");
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    assert!(job.plan.steps > 1000);
    assert_eq!(job.plan.num_frames(), 21);
}

#[test]
fn a_run_replaces_an_earlier_runs_series_and_nothing_else() {
    let out = tempfile::tempdir().unwrap();
    std::fs::write(out.path().join("notes.txt"), b"mine").unwrap();
    let long = input("[solver]\nduration = 0.004\n[output]\nevery_steps = 1\n");
    let job = Job::prepare(long, Registry::default(), &no_progress).unwrap();
    let first = job.run(out.path(), &no_progress, &Cancel::new()).unwrap();
    let short = input("[solver]\nduration = 0.001\n[output]\nevery_steps = 1\n");
    let job = Job::prepare(short, Registry::default(), &no_progress).unwrap();
    let second = job.run(out.path(), &no_progress, &Cancel::new()).unwrap();
    assert!(first.frames > second.frames);
    let vtu = std::fs::read_dir(out.path())
        .unwrap()
        .filter(|e| {
            let name = e.as_ref().unwrap().file_name().into_string().unwrap();
            name.starts_with("lattice_") && name.ends_with(".vtu")
        })
        .count();
    assert_eq!(vtu, second.frames);
    assert_eq!(
        std::fs::read(out.path().join("notes.txt")).unwrap(),
        b"mine"
    );
}

#[test]
fn static_solver_keys_reach_the_solver() {
    // With hourglass control: the paper's model's equilibrium here fails the
    // stability test (docs/robustness.md).
    let base = "[model]\nparameterization = \"volumetric-barrier+hg\"\n[solver]\nkind = \"static\"\n[output]\nlast_only = true\n";
    let run = |extra: &str| {
        let text = base.replace(
            "kind = \"static\"\n",
            &format!("kind = \"static\"\n{extra}"),
        );
        let job = Job::prepare(input(&text), Registry::default(), &no_progress).unwrap();
        let out = tempfile::tempdir().unwrap();
        job.run(out.path(), &no_progress, &Cancel::new())
            .unwrap()
            .max_displacement
    };
    let direct = run("linear_solver = \"direct\"\n");
    let iterative = run("linear_solver = \"iterative\"\nload_steps = 4\n");
    let small_strain = run("linear = true\n");
    assert!(
        (iterative - direct).abs() <= 1e-6 * direct,
        "{iterative} vs {direct}"
    );
    // Soft enough that the small-strain answer differs, close enough to agree roughly.
    assert!(small_strain != direct);
    assert!(
        (small_strain - direct).abs() <= 0.2 * direct,
        "{small_strain} vs {direct}"
    );
    let err = SceneInput::from_toml(
        &scene("[solver]\nkind = \"static\"\nload_steps = 0\n"),
        "s.toml",
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("[solver] load_steps"), "{err}");
    let err = SceneInput::from_toml(&scene("[solver]\nlinear_solver = \"magic\"\n"), "s.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("`iterative`"), "{err}");
}

/// A run that blows up writes no frame that failed the divergence checks,
/// never goes back in time in its series, and says where it failed.
#[test]
fn a_diverging_run_writes_only_checked_frames_in_time_order() {
    for (force, every) in [(1.0e15, 1), (2.0e3, 1), (2.0e3, 3)] {
        let job = Job::prepare(
            input(&format!(
                "[model]\nparameterization = \"paper\"\n\
                 [[loads.forces]]\nselect = {{ kind = \"face\", face = \"z+\" }}\n\
                 force = [{force:e}, 0.0, 0.0]\n[solver]\nduration = 0.05\n\
                 accept_unstable = true\n\
                 [output]\nevery_steps = {every}\n"
            )),
            Registry::default(),
            &no_progress,
        )
        .unwrap();
        let out = tempfile::tempdir().unwrap();
        let err = job
            .run(out.path(), &no_progress, &Cancel::new())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("diverged at step")
                && (err.contains("cell ") || err.contains("(first: "))
                && err.contains("last good time"),
            "{err}"
        );
        let times = pvd_times(&out.path().join("lattice.pvd"));
        assert!(times.windows(2).all(|w| w[1] > w[0]), "{force}: {times:?}");
        // Every frame written is a state that passed the checks: no cell
        // turned inside out, no non-finite position.
        let model = job.problem.model();
        for k in 0..times.len() {
            let path = out.path().join(format!("surface_{k:04}.vtu"));
            let surface = mss_io::vtk::read::read_surface_vtu(&path, 1 << 30).unwrap();
            assert!(
                surface.points.iter().flatten().all(|c| c.is_finite()),
                "{force}: frame {k}"
            );
        }
        assert!(model.num_cells() > 0);
    }
}

/// Jobs estimated to need more memory than the limit are refused before the
/// allocation, naming the figures; a run whose output would not fit is
/// refused before it writes anything.
#[test]
fn resource_limits_refuse_before_allocating_or_writing() {
    use mss_scene::limits::Limits;
    let tight = |memory: u64| Limits {
        memory_bytes: memory,
        ..Limits::default()
    };
    let err = |extra: &str, limits: Limits| {
        Job::prepare_with_limits(input(extra), Registry::default(), limits, &no_progress)
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    // The grid alone: 8 cells along the critter need a few hundred grid cells.
    let e = err("", tight(100));
    assert!(
        e.contains("voxelizing") && e.contains("limit of 100 B (as set)"),
        "{e}"
    );
    // The same jobs fit the default limit.
    let fits = Job::prepare(
        input("[solver]\nkind = \"static\"\n"),
        Registry::default(),
        &no_progress,
    )
    .unwrap();
    let (cells, nodes) = (fits.lattice().num_cells(), fits.lattice().num_nodes());
    let explicit = mss_scene::limits::run_memory_estimate(cells, nodes, false);
    let matrices = mss_scene::limits::run_memory_estimate(cells, nodes, true);
    // The lattice: allowed to classify, not to build the run.
    let e = err("", tight(explicit - 1000));
    assert!(e.contains(&format!("a lattice of {cells} cells")), "{e}");
    // Matrices of a static solve: the explicit run would fit; the way out is named.
    let e = err("[solver]\nkind = \"static\"\n", tight(matrices - 1));
    assert!(e.contains("explicit solver") && e.contains("memory"), "{e}");
    Job::prepare_with_limits(
        input(""),
        Registry::default(),
        tight(matrices - 1),
        &no_progress,
    )
    .unwrap();

    let limits = Limits {
        output_bytes: Some(10_000),
        ..Limits::default()
    };
    let job =
        Job::prepare_with_limits(input(""), Registry::default(), limits, &no_progress).unwrap();
    let out = tempfile::tempdir().unwrap();
    let dir = out.path().join("run");
    let e = job
        .run(&dir, &no_progress, &Cancel::new())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("would write about") && e.contains("free there"),
        "{e}"
    );
    assert!(!dir.exists() || std::fs::read_dir(&dir).unwrap().next().is_none());
}

/// The scene fuzz inputs kept in the repository (`fuzz/seeds/scene`,
/// `fuzz/corpus-min/scene`, `fuzz/regressions/scene`) parse or give a
/// one-line error, as the fuzz target asserts.
#[test]
fn kept_scene_fuzz_inputs_parse_or_fail_on_one_line() {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let mut n = 0;
    for kind in ["seeds", "corpus-min", "regressions"] {
        let Ok(dir) = std::fs::read_dir(root.join(kind).join("scene")) else {
            continue;
        };
        for entry in dir.filter_map(Result::ok) {
            let bytes = std::fs::read(entry.path()).unwrap();
            if let Ok(text) = std::str::from_utf8(&bytes)
                && let Err(e) = mss_scene::Scene::from_toml_str(text, "fuzz.toml")
            {
                assert!(
                    !e.to_string().contains('\n'),
                    "{}: {e}",
                    entry.path().display()
                );
            }
            n += 1;
        }
    }
    assert!(n >= 2);
}

/// `[[obstacles]]` reach the problem, their forces the frames, and bad
/// values are refused with their key.
#[test]
fn obstacles_reach_the_problem_and_bad_ones_are_refused() {
    let ground = "[[obstacles]]\nshape = { kind = \"ground\" }\nfriction = 0.4\n\
                  [solver]\nduration = 0.01\n[output]\nlast_only = true\n";
    let job = Job::prepare(input(ground), Registry::default(), &no_progress).unwrap();
    let contact = job.problem.contact().expect("contact");
    let (o, s) = contact.obstacles().next().unwrap();
    assert_eq!((s.friction_static, s.friction_kinetic), (0.4, 0.4));
    let lowest = job
        .problem
        .model()
        .rest_positions()
        .iter()
        .map(|p| p.z)
        .fold(f64::INFINITY, f64::min);
    assert!(
        o.penetration(0.0, mss_core::Vec3::new(0.0, 0.0, lowest - 1e-6))
            .is_some()
    );
    assert!(
        o.penetration(0.0, mss_core::Vec3::new(0.0, 0.0, lowest + 1e-6))
            .is_none()
    );
    let out = tempfile::tempdir().unwrap();
    job.run(out.path(), &no_progress, &Cancel::new()).unwrap();
    let vtu = std::fs::read_to_string(out.path().join("lattice_0000.vtu")).unwrap();
    assert!(vtu.contains("Name=\"contact_force\""));
    // A closed mesh as the obstacle: a slab under the body, from a file.
    let dir = tempfile::tempdir().unwrap();
    let slab = hexmesh::generate::box_mesh([-1.0, -1.0, lowest - 0.1], [1.0, 1.0, lowest - 1e-3]);
    let mut obj = String::new();
    for p in &slab.vertices {
        obj += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for t in &slab.triangles {
        obj += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    let slab_path = dir.path().join("slab.obj");
    std::fs::write(&slab_path, obj).unwrap();
    let text = scene(&format!(
        "[[obstacles]]\nshape = {{ kind = \"mesh\", path = {:?} }}\n",
        slab_path.display().to_string()
    ));
    let job = Job::prepare(
        SceneInput::from_toml(&text, "test.toml").unwrap(),
        Registry::default(),
        &no_progress,
    )
    .unwrap();
    let (o, _) = job.problem.contact().unwrap().obstacles().next().unwrap();
    let inside = o
        .penetration(0.0, mss_core::Vec3::new(0.0, 0.0, lowest - 0.01))
        .unwrap();
    assert!((inside.depth - (0.01 - 1e-3)).abs() < 1e-9 && inside.normal.z > 0.999);
    for (extra, needle) in [
        (
            "shape = { kind = \"mesh\", path = \"no/such.obj\" }\n",
            "no/such.obj",
        ),
        (
            "shape = { kind = \"sphere\", centre = [0.0, 0.0, 0.0], radius = -1.0 }\n",
            "radius",
        ),
        (
            "shape = { kind = \"plane\", point = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 0.0] }\n",
            "normal",
        ),
        (
            "shape = { kind = \"ground\" }\nfriction = -0.1\n",
            "friction",
        ),
        (
            "shape = { kind = \"ground\" }\nfriction = 0.2\nfriction_kinetic = 0.5\n",
            "kinetic",
        ),
        (
            "shape = { kind = \"ground\" }\nstiffness = 0.0\n",
            "stiffness",
        ),
        (
            "shape = { kind = \"ground\" }\nmotion = [[1.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0]]\n",
            "increasing",
        ),
        (
            "shape = { kind = \"cone\" }\n",
            "shape kind \"cone\"; known: plane, ground",
        ),
        (
            "shape = { kind = \"ground\" }\nbounce = 1.0\n",
            "unknown field `bounce`",
        ),
    ] {
        let e = SceneInput::from_toml(&scene(&format!("[[obstacles]]\n{extra}")), "test.toml")
            .and_then(|i| Job::prepare(i, Registry::default(), &no_progress))
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(needle) && e.contains("test.toml"),
            "{extra}: {e}"
        );
        if !needle.starts_with("unknown") {
            assert!(e.contains("[[obstacles]] #1"), "{e}");
        }
    }
}

#[test]
fn a_rebuilt_problem_is_the_jobs_problem() {
    // Ground contact on the embedded surface, loads and held nodes: a
    // fresh copy for an owner (an interactive Simulation) must be the same
    // problem, step for step.
    let extra = "[[obstacles]]\nshape = { kind = \"ground\", gap = 0.01 }\n[contact]\npoints = \"both\"\n\
                 [solver]\nduration = 0.05\n";
    let job = Job::prepare(input(extra), Registry::default(), &no_progress).unwrap();
    let copy = job.rebuild_problem().unwrap();
    assert_eq!(
        copy.constraints().fully_fixed_nodes(),
        job.problem.constraints().fully_fixed_nodes()
    );
    assert!(copy.contact().is_some());
    let run = |p: &Problem| {
        let mut s = State::at_rest(p.model());
        p.apply_constraints(&mut s);
        let mut integ = job
            .input
            .integrator(&job.registry, p, &job.plan)
            .unwrap()
            .unwrap();
        for _ in 0..job.plan.steps {
            integ.step(p, &mut s).unwrap();
        }
        s
    };
    let (a, b) = (run(&job.problem), run(&copy));
    assert_eq!(a.x, b.x);
    assert_eq!(a.v, b.v);
    assert!(
        a.x.iter()
            .zip(job.problem.model().rest_positions())
            .any(|(p, r)| (p - r).norm() > 1e-6)
    );
}

/// Every file of a run folder by name, with summary.json's timings and
/// folder name removed.
fn folder_contents(dir: &std::path::Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            let mut bytes = std::fs::read(&p).unwrap();
            if name == "summary.json" {
                let mut v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
                for key in [
                    "voxelize_seconds",
                    "simulate_seconds",
                    "wall_seconds",
                    "peak_memory_bytes",
                    "output_folder",
                ] {
                    v.as_object_mut().unwrap().remove(key);
                }
                bytes = v.to_string().into_bytes();
            }
            (name, bytes)
        })
        .collect();
    files.sort();
    files
}

/// A scene whose every output kind is on and whose step control works:
/// a soft critter dropped onto the ground with friction.
fn resumable_scene() -> SceneInput {
    let text = scene(
        "[model]\nparameterization = \"volumetric-barrier+hg\"\nhourglass = 1.0\n\
         [[obstacles]]\nshape = { kind = \"ground\", gap = 0.03 }\nfriction = 0.5\n\
         [solver]\nduration = 0.2\ndamping = 1.0\n\
         [output]\nevery_time = 0.02\npc2 = true\nsprings = true\nvtk = true\nskin_stl = true\n\
         checkpoint_every = 0.03\n",
    )
    .replace("young = 1.0e5", "young = 4.0e3")
    .replace("[[fixed]]\nkind = \"lowest_layer\"\n", "");
    SceneInput::from_toml(&text, "test.toml").unwrap()
}

fn run_whole(job: &Job, dir: &std::path::Path) -> mss_scene::RunSummary {
    let s = job.run(dir, &no_progress, &Cancel::new()).unwrap();
    mss_scene::write_summary(dir, &s).unwrap();
    s
}

#[test]
fn an_interrupted_run_resumed_is_bitwise_the_uninterrupted_one() {
    let job = Job::prepare(resumable_scene(), Registry::default(), &no_progress).unwrap();
    let whole = tempfile::tempdir().unwrap();
    let reference = run_whole(&job, whole.path());
    assert!(!whole.path().join("checkpoint.mss").exists());

    // Interrupted between two frames, then resumed: early, at the landing
    // (where the step control halves the sub-step) and late.
    for fifth in 1..5 {
        let resumed = interrupted_and_resumed(&job, job.plan.steps * fifth / 5 + 3, whole.path());
        assert_eq!(resumed.frames, reference.frames);
        assert_eq!(resumed.bytes_written, reference.bytes_written);
    }
}

/// Runs `job` in a new folder, interrupted after `stop_at` steps, resumes
/// it there, and checks that the folder holds what the uninterrupted run
/// wrote in `whole`.
fn interrupted_and_resumed(
    job: &Job,
    stop_at: u64,
    whole: &std::path::Path,
) -> mss_scene::RunSummary {
    let cut = tempfile::tempdir().unwrap();
    let cancel = Cancel::new();
    let progress = |p: Progress| {
        if let Progress::Stepping { done, .. } = p
            && done == stop_at
        {
            cancel.cancel();
        }
    };
    let first = job.run(cut.path(), &progress, &cancel).unwrap();
    assert!(first.interrupted && first.steps == stop_at);
    assert!(cut.path().join("checkpoint.mss").exists());
    let resumed = job
        .resume(cut.path(), &no_progress, &Cancel::new())
        .unwrap();
    mss_scene::write_summary(cut.path(), &resumed).unwrap();
    assert!(!resumed.interrupted);
    assert_eq!(
        folder_contents(cut.path()),
        folder_contents(whole),
        "stopped at step {stop_at}"
    );
    resumed
}

/// An implicit landing: the direct solver keeps its factors from step to
/// step and preconditions the next matrices with them.
fn resumable_implicit_scene() -> SceneInput {
    let text = scene(
        "[[obstacles]]\nshape = { kind = \"ground\", gap = 0.002 }\nfriction = 0.5\n\
         [solver]\nkind = \"implicit\"\ndt = 0.005\nduration = 0.1\n\
         [output]\nevery_time = 0.01\npc2 = true\n",
    )
    .replace("[[fixed]]\nkind = \"lowest_layer\"\n", "");
    SceneInput::from_toml(&text, "test.toml").unwrap()
}

#[test]
fn an_interrupted_implicit_run_resumed_is_bitwise_the_uninterrupted_one() {
    let job = Job::prepare(
        resumable_implicit_scene(),
        Registry::default(),
        &no_progress,
    )
    .unwrap();
    let whole = tempfile::tempdir().unwrap();
    let reference = run_whole(&job, whole.path());
    assert!(reference.newton_iterations > job.plan.steps as u64 / 2);
    for stop_at in [4, job.plan.steps / 2 + 1] {
        interrupted_and_resumed(&job, stop_at, whole.path());
    }
}

#[test]
fn an_interrupted_matrix_free_implicit_run_resumes_bitwise_with_its_load_check() {
    // Above 4,000 free dofs the implicit solves keep no matrix and
    // precondition the next steps with a kept hierarchy, which the
    // checkpoint carries; the summary keeps the verdict of the load check
    // that only the first part ran.
    let text = scene(
        "[solver]\nkind = \"implicit\"\ndt = 0.005\nduration = 0.03\n\
         [output]\nevery_time = 0.01\n",
    )
    .replace("builtin:critter", "builtin:cube")
    .replace("cells = 8", "cells = 12");
    let input = SceneInput::from_toml(&text, "test.toml").unwrap();
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    let whole = tempfile::tempdir().unwrap();
    let reference = run_whole(&job, whole.path());
    assert!(reference.load_check.is_some());
    let resumed = interrupted_and_resumed(&job, 3, whole.path());
    assert_eq!(resumed.load_check, reference.load_check);
}

#[test]
fn a_periodic_checkpoint_resumes_bitwise_after_a_crash() {
    let job = Job::prepare(resumable_scene(), Registry::default(), &no_progress).unwrap();
    let whole = tempfile::tempdir().unwrap();
    run_whole(&job, whole.path());

    // Keep the periodic checkpoint as a crash would leave it, let the run
    // finish (which removes it and finishes the point caches), put it back.
    let crashed = tempfile::tempdir().unwrap();
    let kept = tempfile::tempdir().unwrap();
    let total = job.plan.steps;
    let copy_at = total * 3 / 4;
    let progress = |p: Progress| {
        if let Progress::Stepping { done, .. } = p
            && done == copy_at
        {
            std::fs::copy(
                crashed.path().join("checkpoint.mss"),
                kept.path().join("checkpoint.mss"),
            )
            .unwrap();
        }
    };
    job.run(crashed.path(), &progress, &Cancel::new()).unwrap();
    std::fs::copy(
        kept.path().join("checkpoint.mss"),
        crashed.path().join("checkpoint.mss"),
    )
    .unwrap();
    let resumed = job
        .resume(crashed.path(), &no_progress, &Cancel::new())
        .unwrap();
    mss_scene::write_summary(crashed.path(), &resumed).unwrap();
    assert_eq!(
        folder_contents(crashed.path()),
        folder_contents(whole.path())
    );
}

#[test]
fn resuming_refuses_a_changed_scene_a_missing_checkpoint_and_a_static_solve() {
    let job = Job::prepare(resumable_scene(), Registry::default(), &no_progress).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let e = job
        .resume(dir.path(), &no_progress, &Cancel::new())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cannot resume") && e.contains("checkpoint_every"),
        "{e}"
    );
    let cancel = Cancel::new();
    cancel.cancel();
    job.run(dir.path(), &no_progress, &cancel).unwrap();
    let mut changed = resumable_scene();
    changed.scene.material.as_mut().unwrap().young *= 1.01;
    let other = Job::prepare(changed, Registry::default(), &no_progress).unwrap();
    let e = other
        .resume(dir.path(), &no_progress, &Cancel::new())
        .unwrap_err()
        .to_string();
    assert!(e.contains("another scene"), "{e}");
    let statics = Job::prepare(
        input("[solver]\nkind = \"static\"\n"),
        Registry::default(),
        &no_progress,
    )
    .unwrap();
    let e = statics
        .resume(dir.path(), &no_progress, &Cancel::new())
        .unwrap_err()
        .to_string();
    assert!(e.contains("nothing to resume"), "{e}");
    let bad = SceneInput::from_toml(
        &scene("[solver]\nkind = \"static\"\n[output]\ncheckpoint_every = 0.1\n"),
        "t.toml",
    )
    .unwrap_err()
    .to_string();
    assert!(bad.contains("checkpoint_every"), "{bad}");
    let bad = SceneInput::from_toml(&scene("[output]\ncheckpoint_every = -1.0\n"), "t.toml")
        .unwrap_err()
        .to_string();
    assert!(bad.contains("checkpoint_every"), "{bad}");
}

#[test]
fn uncompressed_frames_hold_the_same_lattice() {
    let dir = tempfile::tempdir().unwrap();
    let mut sizes = Vec::new();
    for compression in ["zlib", "none"] {
        let out = dir.path().join(compression);
        let job = Job::prepare(
            input(&format!(
                "[solver]\nduration = 0.01\n[output]\nlast_only = true\ncompression = \"{compression}\"\n"
            )),
            Registry::default(),
            &no_progress,
        )
        .unwrap();
        job.run(&out, &no_progress, &Cancel::new()).unwrap();
        let path = out.join("lattice_0000.vtu");
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text.contains("vtkZLibDataCompressor"),
            compression == "zlib"
        );
        // Read back: the boundary of its hexahedra.
        let surface = hexmesh::load::Loaders::default().load(&path).unwrap();
        sizes.push((surface.mesh.triangles.len(), text.len()));
    }
    assert_eq!(sizes[0].0, sizes[1].0);
    assert!(sizes[1].1 > sizes[0].1, "{sizes:?}");
    let bad = SceneInput::from_toml(&scene("[output]\ncompression = \"lzma\"\n"), "t.toml")
        .unwrap_err()
        .to_string();
    assert!(bad.contains("lzma") && bad.contains("zlib"), "{bad}");
}

/// A static solve stops when the job is cancelled (Ctrl-C), before its next
/// load increment, and writes nothing.
#[test]
fn a_cancelled_static_solve_stops_and_writes_nothing() {
    let job = prepared("[solver]\nkind = \"static\"\n");
    let out = tempfile::tempdir().unwrap();
    let cancel = Cancel::new();
    cancel.cancel();
    let err = job.run(out.path(), &no_progress, &cancel).unwrap_err();
    match &err {
        mss_scene::JobError::Solver { source, .. } => assert!(
            matches!(**source, SolverError::Cancelled { load_factor } if load_factor == 0.0),
            "{source:?}"
        ),
        other => panic!("{other:?}"),
    }
    assert!(err.to_string().contains("stopped"), "{err}");
    assert_eq!(std::fs::read_dir(out.path()).unwrap().count(), 0);
    // Not cancelled, the same job solves.
    assert!(job.run(out.path(), &no_progress, &Cancel::new()).is_ok());
}

/// A run cancelled while the static check of a non-default model runs
/// (docs/robustness.md, refused up front) skips the check and stops at its
/// first step, as interrupted.
#[test]
fn a_cancelled_check_before_a_run_stops_it_as_interrupted() {
    let job = prepared("[model]\nparameterization = \"springs\"\n[solver]\nduration = 0.05\n");
    let out = tempfile::tempdir().unwrap();
    // Not cancelled, the check refuses it (springs fold under the weight).
    let err = job
        .run(out.path(), &no_progress, &Cancel::new())
        .unwrap_err();
    assert!(
        matches!(err, mss_scene::JobError::WouldFold { .. }),
        "{err}"
    );
    let cancel = Cancel::new();
    cancel.cancel();
    let summary = job.run(out.path(), &no_progress, &cancel).unwrap();
    assert!(summary.interrupted);
}

#[test]
fn resuming_refuses_a_forged_time_and_a_lost_frame() {
    use mss_scene::checkpoint::{CHECKPOINT_FILE, Checkpoint, fingerprint};
    let job = Job::prepare(resumable_scene(), Registry::default(), &no_progress).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let cancel = Cancel::new();
    let stop_at = job.plan.steps / 2;
    let progress = |p: Progress| {
        if let Progress::Stepping { done, .. } = p
            && done == stop_at
        {
            cancel.cancel();
        }
    };
    assert!(job.run(dir.path(), &progress, &cancel).unwrap().interrupted);
    let nodes = job.problem.model().num_nodes();
    let print = fingerprint(&job.input.scene);
    let good = Checkpoint::read(dir.path(), print, nodes).unwrap();
    let kept = std::fs::read(dir.path().join(CHECKPOINT_FILE)).unwrap();
    let refused = |what: &str| {
        job.resume(dir.path(), &no_progress, &Cancel::new())
            .map(|_| ())
            .unwrap_err()
            .to_string()
            .contains(what)
    };

    // A valid checksum over a negative time.
    let mut forged = good.clone();
    forged.state.time = -4.98;
    forged.write(dir.path()).unwrap();
    assert!(refused("does not match its step"));
    // A frame time beyond the time reached.
    let mut forged = good.clone();
    forged.frame_times.push(good.state.time + 1.0);
    forged.write(dir.path()).unwrap();
    assert!(refused("outside the"));

    // A frame file deleted after the interruption.
    std::fs::write(dir.path().join(CHECKPOINT_FILE), &kept).unwrap();
    std::fs::remove_file(dir.path().join("lattice_0001.vtu")).unwrap();
    assert!(refused("lattice_0001.vtu"));
    assert!(refused("missing"));
}

/// The summary carries the largest displacement over the run and its time:
/// the bundled press squeezes the critter and lets go, so its peak is well
/// above the displacement it ends with, and comes before the end.
#[test]
fn the_summary_carries_the_peak_displacement_and_its_time() {
    let input = SceneInput::load(Some(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../data/scenes/press.toml"
    ))))
    .unwrap();
    let job = Job::prepare(input, Registry::default(), &no_progress).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let s = job.run(dir.path(), &no_progress, &Cancel::new()).unwrap();
    assert!(
        s.peak_displacement > 2.0 * s.max_displacement,
        "peak {} end {}",
        s.peak_displacement,
        s.max_displacement
    );
    assert!(
        s.peak_displacement_time > 0.0 && s.peak_displacement_time < s.simulated_time,
        "{}",
        s.peak_displacement_time
    );
}

/// `[solver] precision = "f32"` reaches the explicit force pass (the run
/// ends within f32's accuracy of the f64 one, not on its bits) and the
/// Newton solvers refuse it with the key named.
#[test]
fn solver_precision_reaches_the_explicit_run_and_newton_refuses_it() {
    let run = |extra: &str| {
        let text =
            format!("[solver]\nduration = 0.1\ndamping = 5.0\n{extra}[output]\nlast_only = true\n");
        let job = Job::prepare(input(&text), Registry::default(), &no_progress).unwrap();
        let out = tempfile::tempdir().unwrap();
        job.run(out.path(), &no_progress, &Cancel::new())
            .unwrap()
            .max_displacement
    };
    let double = run("");
    let single = run("precision = \"f32\"\n");
    assert_eq!(double, run("precision = \"f64\"\n"));
    assert!(single != double, "the f32 pass ran in f64");
    assert!(
        (single - double).abs() < 1e-3 * double,
        "{single} vs {double}"
    );
    let err = SceneInput::from_toml(
        &scene("[solver]\nkind = \"static\"\nprecision = \"f32\"\n"),
        "s.toml",
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("[solver] precision"), "{err}");
    let text = "[solver]\nkind = \"implicit\"\nprecision = \"f32\"\nduration = 0.01\n";
    let err = match Job::prepare(input(text), Registry::default(), &no_progress) {
        Err(e) => e.to_string(),
        Ok(job) => {
            let out = tempfile::tempdir().unwrap();
            job.run(out.path(), &no_progress, &Cancel::new())
                .unwrap_err()
                .to_string()
        }
    };
    assert!(err.contains("f32") && err.contains("[solver]"), "{err}");
    let err = SceneInput::from_toml(&scene("[solver]\nprecision = \"f16\"\n"), "s.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("precision") && err.contains("f32"), "{err}");
}

/// A dynamic run of the default model reports its load check's verdict in
/// the summary (as `mss check` words it); without time for the check it
/// runs anyway and says the check was stopped; a model the check may
/// refuse is checked whatever the time given.
#[test]
fn the_run_reports_its_load_check_and_does_not_wait_past_its_limit() {
    use mss_scene::limits::Limits;
    let short = "[solver]\nduration = 0.002\n[output]\nlast_only = true\n";
    let run = |extra: &str, seconds: f64| {
        let limits = Limits {
            load_check_seconds: seconds,
            ..Limits::default()
        };
        let job = Job::prepare_with_limits(input(extra), Registry::default(), limits, &no_progress)
            .unwrap();
        let out = tempfile::tempdir().unwrap();
        job.run(out.path(), &no_progress, &Cancel::new())
    };
    let checked = run(short, 60.0).unwrap();
    let verdict = checked.load_check.expect("a check ran");
    assert!(verdict.contains("stable static equilibrium"), "{verdict}");

    let hurried = run(short, 0.0).unwrap();
    assert_eq!(
        hurried.load_check.as_deref(),
        Some("stopped after 0 s, before its verdict")
    );
    // The same frames: the check never changes the run.
    assert_eq!(hurried.max_displacement, checked.max_displacement);

    // Springs alone fold under this load: refused, time limit or not.
    let springs = format!("[model]\nparameterization = \"springs\"\n{short}");
    assert!(matches!(
        run(&springs, 0.0),
        Err(mss_scene::JobError::WouldFold { .. })
    ));
    // A static run has no check before it; accept_unstable skips it.
    let accepted = short.replace("[solver]\n", "[solver]\naccept_unstable = true\n");
    assert_eq!(run(&accepted, 60.0).unwrap().load_check, None);

    // What `mss check` adds to its time estimate for the run's own check.
    let budget = |extra: &str| {
        let limits = Limits {
            load_check_seconds: 7.0,
            ..Limits::default()
        };
        Job::prepare_with_limits(input(extra), Registry::default(), limits, &no_progress)
            .unwrap()
            .run_load_check_budget()
    };
    assert_eq!(budget(short), LoadCheckBudget::AtMost(7.0));
    assert_eq!(budget(&springs), LoadCheckBudget::ToTheVerdict);
    assert_eq!(budget(&accepted), LoadCheckBudget::None);
    assert_eq!(
        budget(&short.replace("[solver]\n", "[solver]\nkind = \"static\"\n")),
        LoadCheckBudget::None
    );
}

/// The critter at 5 kPa hanging from the 12 nodes of its top 5 %, for 0.3 s,
/// with the model `parameterization`.
fn hanging_critter(parameterization: &str) -> Job {
    let text = format!(
        "[mesh]\npath = \"builtin:critter\"\nscale = 0.96\n[voxelize]\ncells = 24\n\
         [material]\nyoung = 5.0e3\npoisson = 0.4\ndensity = 1000.0\n\
         [model]\nparameterization = \"{parameterization}\"\nhourglass = 1.0\n\
         [[fixed]]\nkind = \"box\"\nmin = [0.0, 0.0, 0.95]\nmax = [1.0, 1.0, 1.01]\nrelative = true\n\
         [loads]\ngravity = [0.0, 0.0, -9.81]\n\
         [solver]\nkind = \"explicit\"\ndamping = 20.0\nduration = 0.3\naccept_unstable = true\n\
         [output]\nevery_time = 0.05\nembedded = false\n"
    );
    let input = SceneInput::from_toml(&text, "hanging.toml").unwrap();
    Job::prepare(input, Registry::default(), &no_progress).unwrap()
}

#[test]
fn a_run_reports_cells_folded_at_a_corner() {
    // Without the barrier law (and its corner barrier) the hanging critter's
    // cells near the held nodes fold at a corner within 0.15 s while their
    // centres stay healthy: the run goes on and says so in its summary.
    let dir = tempfile::tempdir().unwrap();
    let job = hanging_critter("volumetric+hg");
    let s = run_whole(&job, dir.path());
    assert!(s.most_folded_cells.0 > 0, "{:?}", s.most_folded_cells);
    assert!(s.most_folded_cells.1 > 0.0 && s.most_folded_cells.1 <= 0.3);
    assert!(s.folded_cells > 0 && s.folded_cells <= s.most_folded_cells.0);
    let json = std::fs::read_to_string(dir.path().join("summary.json")).unwrap();
    assert!(json.contains("\"most_folded_cells\""), "{json}");
    // The default model on the same scene folds none.
    let s = run_whole(&hanging_critter("volumetric-barrier+hg"), dir.path());
    assert_eq!((s.folded_cells, s.most_folded_cells.0), (0, 0));
}
