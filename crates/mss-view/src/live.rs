//! The live source: a scene built by [`mss_scene::Job::prepare`], stepped
//! by an interactive [`Simulation`] at real time (times the page's scale),
//! with the page's drag and poking sphere.
//!
//! The viewer always steps explicitly, whatever `[solver] kind` says (an
//! interactive frame is a short explicit run of 1/60 s of simulated time,
//! in as many stable sub-steps as it takes), and runs until it is stopped:
//! `[solver] duration` and `[output]` do not apply. A drag holds the 8
//! nodes of the cell under the cursor by springs whose stiffness is set
//! from the material (about a cell's own stiffness, `E h`) and capped well
//! below the lattice's highest frequency, so a drag never shortens the
//! stable step. The poking sphere is a [`Steered`] obstacle built into the
//! problem from the start, parked far away while it is not used; it is
//! moved once per frame, with the velocity of that move, and put in place
//! with zero velocity, so that it never hits the body with a jump's speed.

use std::time::{Duration, Instant};

use mss_scene::hexmesh::{Embedding, Skin};
use mss_scene::mss_core::contact::{ContactSettings, Obstacle, Sphere, SteerHandle, Steered};
use mss_scene::mss_core::simulation::Simulation;
use mss_scene::mss_core::{Model, Vec3};
use mss_scene::obstacles::BuiltinShape;
use mss_scene::{Job, Registry, SceneInput};

use crate::protocol::{
    ClientMessage, ObstacleDraw, SceneInfo, Status, SurfaceFrame, SurfaceInfo, encode_frame,
    encode_topology,
};
use crate::{RateMeter, Source, SourceContext, bounds_of};

/// Where the poking sphere waits while it is not used (m).
const PARKED: f64 = 1.0e4;

/// Radius of the poking sphere, in cells.
const POKE_RADIUS_CELLS: f64 = 2.5;

/// The drag's springs stay this far below the lattice's highest
/// frequency (as a fraction of omega_max squared, per node mass).
const DRAG_FREQUENCY_FRACTION: f64 = 0.05;

/// A body the live source steps and draws: the 3D one ([`Body`]) or a
/// 2D one (`crate::plane_live::PlaneBody`). The run loop and the page see
/// only this.
pub(crate) trait LiveBody {
    /// Acts on a pick, drag, release, poke or unpoke.
    fn handle(&mut self, message: &ClientMessage);
    /// Moves the poking obstacle to its latest target, as if over `dt`.
    fn steer(&mut self, dt: f64);
    /// Advances `dt` of simulated time; the sub-steps taken.
    fn advance(&mut self, dt: f64) -> Result<u32, String>;
    /// The binary frame, the largest displacement and the grabbed nodes'
    /// centroid.
    fn frame(&mut self, generation: u64, seq: u64) -> (Vec<u8>, f64, Option<[f64; 3]>);
    /// Simulated time (s).
    fn time(&self) -> f64;
    /// Where the grab pulls, if anything is grabbed.
    fn grab_target(&self) -> Option<[f64; 3]>;
    /// The poking obstacle's centre while it is in use.
    fn poke_centre(&self) -> Option<[f64; 3]>;
    /// The scene's obstacles' offsets from their rest placement.
    fn obstacle_offsets(&self) -> Vec<[f64; 3]>;
}

/// The 3D body: everything built from the scene.
struct Body {
    sim: Simulation,
    embedding: Embedding,
    skin: Skin,
    /// One cell of each node (to pick a skin vertex's cell).
    node_cell: Vec<u32>,
    /// Cells around each node, for averaging J.
    node_cell_count: Vec<u32>,
    poke: SteerHandle,
    poke_target: Option<Vec3>,
    poke_active: bool,
    drag_stiffness: f64,
    /// The grab's centroid minus the hit point at the pick.
    grab_offset: Option<Vec3>,
    grab_target: Option<Vec3>,
    scene_obstacles: usize,
    scratch_j: Vec<f64>,
}

fn v3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

fn arr(v: Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn scene_input(source: &Source) -> Result<SceneInput, String> {
    let one_line = |e: mss_scene::JobError| mss_scene::error::one_line(&e);
    match source {
        Source::Bundled => Ok(SceneInput::bundled_default()),
        Source::SceneFile(path) => SceneInput::load(Some(path)).map_err(one_line),
        Source::Input(input) => Ok((**input).clone()),
        Source::Replay(p) => Err(format!(
            "{}: a run folder is replayed, not run live",
            p.display()
        )),
    }
}

fn source_name(source: &Source) -> String {
    match source {
        Source::Bundled => "the bundled default scene".into(),
        Source::SceneFile(p) | Source::Replay(p) => p.display().to_string(),
        Source::Input(i) => i.name(),
    }
}

/// Draws of the scene's obstacles at their rest placement.
pub(crate) fn obstacle_draws(
    input: &SceneInput,
    model: &Model,
    mesh_bounds: &dyn Fn(&str) -> Option<[[f64; 3]; 2]>,
) -> Vec<ObstacleDraw> {
    let lowest = model
        .rest_positions()
        .iter()
        .map(|p| p.z)
        .fold(f64::INFINITY, f64::min);
    input
        .scene
        .obstacles
        .iter()
        .map(|o| match &BuiltinShape::of(&o.shape) {
            None => ObstacleDraw::Other {
                shape: o.shape.kind.clone(),
            },
            Some(BuiltinShape::Plane { point, normal }) => {
                let n = v3(*normal);
                let n = if n.norm() > 0.0 {
                    n / n.norm()
                } else {
                    Vec3::z()
                };
                ObstacleDraw::Plane {
                    point: *point,
                    normal: arr(n),
                }
            }
            Some(BuiltinShape::Ground { gap }) => ObstacleDraw::Plane {
                point: [0.0, 0.0, lowest - gap],
                normal: [0.0, 0.0, 1.0],
            },
            Some(BuiltinShape::Sphere { centre, radius }) => ObstacleDraw::Sphere {
                centre: *centre,
                radius: *radius,
            },
            Some(BuiltinShape::Box { min, max }) => ObstacleDraw::Box {
                min: *min,
                max: *max,
            },
            Some(BuiltinShape::Capsule { a, b, radius }) => ObstacleDraw::Capsule {
                a: *a,
                b: *b,
                radius: *radius,
            },
            Some(BuiltinShape::Mesh { path }) => {
                let [min, max] = mesh_bounds(path).unwrap_or([[0.0; 3]; 2]);
                ObstacleDraw::Mesh { min, max }
            }
        })
        .collect()
}

impl Body {
    fn build(
        input: SceneInput,
        options: &crate::ViewOptions,
    ) -> Result<(Body, SceneInfo, Vec<u8>), String> {
        let job = Job::prepare_with_limits(
            input,
            Registry::default(),
            options.limits,
            &mss_scene::no_progress,
        )
        .map_err(|e| mss_scene::error::one_line(&e))?;
        let model = job.problem.model();
        let h = model.h();
        let poke_radius = POKE_RADIUS_CELLS * h;
        let (sphere, poke) = Steered::new(Box::new(
            Sphere::new(Vec3::zeros(), poke_radius).map_err(|e| e.to_string())?,
        ));
        poke.move_to(Vec3::new(0.0, 0.0, PARKED), 0.0);
        let settings = ContactSettings::for_model(model);
        let extra: Vec<(Box<dyn Obstacle>, ContactSettings)> = vec![(Box::new(sphere), settings)];
        let problem = job
            .interactive_problem(extra)
            .map_err(|e| mss_scene::error::one_line(&e))?;
        let mut sim = Simulation::new(problem).map_err(|e| e.to_string())?;
        let solver = &job.input.scene.solver;
        if solver.start == mss_scene::scene::Start::Settled {
            // Settled before the first frame, as `mss run` starts it.
            sim.settle(&solver.settle_options())
                .map_err(|e| format!("{}: settling the start failed: {e}", job.input.name()))?;
        }

        let embedding = job.embedding();
        let skin = job.skin();
        let n = model.num_nodes();
        let mut node_cell = vec![0u32; n];
        let mut node_cell_count = vec![0u32; n];
        for (c, cell) in model.cells().iter().enumerate() {
            for &i in cell {
                node_cell[i as usize] = c as u32;
                node_cell_count[i as usize] += 1;
            }
        }
        let young = model
            .materials()
            .iter()
            .map(|m| m.young)
            .fold(0.0, f64::max);
        let mean_mass = model.total_mass() / n.max(1) as f64;
        let omega = 2.0 / model.critical_time_step();
        let drag_stiffness =
            (young * h / 8.0).min(DRAG_FREQUENCY_FRACTION * mean_mass * omega * omega);

        let rest: Vec<[f64; 3]> = model.rest_positions().iter().map(|p| arr(*p)).collect();
        let loaders = &job.registry.loaders;
        let mesh_bounds = |path: &str| {
            job.input
                .load_placed_mesh(path, loaders)
                .ok()
                .map(|m| bounds_of(m.vertices.iter().copied()))
        };
        let info = SceneInfo {
            kind: "scene".into(),
            generation: 0,
            mode: "live".into(),
            name: job.input.name(),
            cells: model.num_cells(),
            nodes: n,
            cell_size: h,
            bounds: bounds_of(rest.iter().copied()),
            surfaces: vec![
                SurfaceInfo {
                    name: "surface".into(),
                    vertices: embedding.vertex_cells().len() as u32,
                    triangles: embedding.triangles().len() as u32,
                    has_jacobian: true,
                },
                SurfaceInfo {
                    name: "skin".into(),
                    vertices: skin.vertex_nodes.len() as u32,
                    triangles: skin.triangles.len() as u32,
                    has_jacobian: true,
                },
            ],
            obstacles: obstacle_draws(&job.input, model, &mesh_bounds),
            poke_radius,
            frame_times: Vec::new(),
            error: None,
        };
        let topology = encode_topology(&[embedding.triangles(), &skin.triangles]);
        let scene_obstacles = job.input.scene.obstacles.len();
        Ok((
            Body {
                sim,
                embedding,
                skin,
                node_cell,
                node_cell_count,
                poke,
                poke_target: None,
                poke_active: false,
                drag_stiffness,
                grab_offset: None,
                grab_target: None,
                scene_obstacles,
                scratch_j: Vec::new(),
            },
            info,
            topology,
        ))
    }

    /// The 8 nodes of the cell under a hit on `surface`'s `triangle`.
    fn cell_under(&self, surface: u32, triangle: u32, point: Vec3) -> Option<[u32; 8]> {
        let x = self.sim.positions();
        match surface {
            0 => {
                let t = self.embedding.triangles().get(triangle as usize)?;
                let nearest = t.iter().copied().min_by(|&a, &b| {
                    let pa = self.vertex_position(a as usize, x);
                    let pb = self.vertex_position(b as usize, x);
                    (pa - point)
                        .norm_squared()
                        .total_cmp(&(pb - point).norm_squared())
                })?;
                Some(self.embedding.vertex_cells()[nearest as usize])
            }
            1 => {
                let t = self.skin.triangles.get(triangle as usize)?;
                let node = t
                    .iter()
                    .map(|&v| self.skin.vertex_nodes[v as usize])
                    .min_by(|&a, &b| {
                        (x[a as usize] - point)
                            .norm_squared()
                            .total_cmp(&(x[b as usize] - point).norm_squared())
                    })?;
                let cell = self.node_cell[node as usize];
                Some(self.sim.problem().model().cells()[cell as usize])
            }
            _ => None,
        }
    }

    fn vertex_position(&self, v: usize, x: &[Vec3]) -> Vec3 {
        let (nodes, w) = self.embedding.vertex_weights(v);
        nodes.iter().zip(w).map(|(&n, w)| x[n as usize] * w).sum()
    }

    fn on_message(&mut self, message: &ClientMessage) {
        match *message {
            ClientMessage::Pick {
                surface,
                triangle,
                point,
            } => {
                let point = v3(point);
                let Some(nodes) = self.cell_under(surface, triangle, point) else {
                    log::warn!(
                        "viewer: pick of triangle {triangle} on surface {surface}: no such triangle"
                    );
                    return;
                };
                if let Err(e) = self.sim.pick(&nodes, self.drag_stiffness) {
                    log::warn!("viewer: {e}");
                    return;
                }
                let x = self.sim.positions();
                let centroid = nodes.iter().map(|&n| x[n as usize]).sum::<Vec3>() / 8.0;
                self.grab_offset = Some(centroid - point);
                self.grab_target = Some(centroid);
            }
            ClientMessage::Drag { target } => {
                if let Some(offset) = self.grab_offset {
                    let t = v3(target) + offset;
                    self.sim.drag_to(t);
                    self.grab_target = Some(t);
                }
            }
            ClientMessage::Release => {
                self.sim.release();
                self.grab_offset = None;
                self.grab_target = None;
            }
            ClientMessage::Poke { centre } => {
                let c = v3(centre);
                if self.poke_active {
                    self.poke_target = Some(c);
                } else {
                    // Put in place at rest: a parked sphere has no speed
                    // to bring into the body.
                    self.poke.move_to(c, 0.0);
                    self.poke_active = true;
                    self.poke_target = None;
                }
            }
            ClientMessage::Unpoke => {
                self.poke.move_to(Vec3::new(0.0, 0.0, PARKED), 0.0);
                self.poke_active = false;
                self.poke_target = None;
            }
            _ => {}
        }
    }

    /// Moves the poking sphere to its latest target, as if over `dt`.
    fn steer_poke(&mut self, dt: f64) {
        if let Some(t) = self.poke_target.take() {
            self.poke.move_to(t, dt);
        } else if self.poke_active {
            // Still: no velocity left over from the last move.
            let at = self.poke.offset();
            self.poke.move_to(at, 0.0);
        }
    }

    fn draw(&mut self, generation: u64, seq: u64) -> (Vec<u8>, f64, Option<[f64; 3]>) {
        let model = self.sim.problem().model();
        let x = self.sim.positions();
        let rest = model.rest_positions();
        let h = model.h();
        // J at each cell's centre from its mean edge vectors, averaged to nodes.
        let n = x.len();
        self.scratch_j.clear();
        self.scratch_j.resize(n, 0.0);
        for cell in model.cells() {
            let p = |k: usize| x[cell[k] as usize];
            let dx = (p(1) - p(0) + p(2) - p(3) + p(5) - p(4) + p(6) - p(7)) / (4.0 * h);
            let dy = (p(3) - p(0) + p(2) - p(1) + p(7) - p(4) + p(6) - p(5)) / (4.0 * h);
            let dz = (p(4) - p(0) + p(5) - p(1) + p(6) - p(2) + p(7) - p(3)) / (4.0 * h);
            let j = dx.dot(&dy.cross(&dz));
            for &i in cell {
                self.scratch_j[i as usize] += j;
            }
        }
        for (j, &c) in self.scratch_j.iter_mut().zip(&self.node_cell_count) {
            *j /= c.max(1) as f64;
        }
        let mut max_disp: f64 = 0.0;
        for (a, b) in x.iter().zip(rest) {
            max_disp = max_disp.max((a - b).norm());
        }
        let nv = self.embedding.vertex_cells().len();
        let mut surface = SurfaceFrame {
            positions: Vec::with_capacity(nv),
            displacement: Vec::with_capacity(nv),
            jacobian: Vec::with_capacity(nv),
        };
        for v in 0..nv {
            let (nodes, w) = self.embedding.vertex_weights(v);
            let mut p = Vec3::zeros();
            let mut u = Vec3::zeros();
            let mut j = 0.0;
            for (&i, w) in nodes.iter().zip(w) {
                let i = i as usize;
                p += x[i] * w;
                u += (x[i] - rest[i]) * w;
                j += self.scratch_j[i] * w;
            }
            surface.positions.push([p.x as f32, p.y as f32, p.z as f32]);
            surface.displacement.push(u.norm() as f32);
            surface.jacobian.push(j as f32);
        }
        let skin = SurfaceFrame {
            positions: self
                .skin
                .vertex_nodes
                .iter()
                .map(|&i| {
                    let p = x[i as usize];
                    [p.x as f32, p.y as f32, p.z as f32]
                })
                .collect(),
            displacement: self
                .skin
                .vertex_nodes
                .iter()
                .map(|&i| (x[i as usize] - rest[i as usize]).norm() as f32)
                .collect(),
            jacobian: self
                .skin
                .vertex_nodes
                .iter()
                .map(|&i| self.scratch_j[i as usize] as f32)
                .collect(),
        };
        let centroid = self.grab_target.and_then(|_| {
            let grab = self.sim.grabbed_nodes();
            (!grab.is_empty())
                .then(|| arr(grab.iter().map(|&i| x[i as usize]).sum::<Vec3>() / grab.len() as f64))
        });
        let time = self.sim.state().time;
        (
            encode_frame(generation, seq, time, &[surface, skin]),
            max_disp,
            centroid,
        )
    }

    fn offsets(&self) -> Vec<[f64; 3]> {
        let t = self.sim.state().time;
        self.sim
            .problem()
            .contact()
            .map(|c| {
                c.obstacles()
                    .take(self.scene_obstacles)
                    .map(|(o, _)| arr(o.offset(t)))
                    .collect()
            })
            .unwrap_or_default()
    }
}

impl LiveBody for Body {
    fn handle(&mut self, message: &ClientMessage) {
        self.on_message(message);
    }
    fn steer(&mut self, dt: f64) {
        self.steer_poke(dt);
    }
    fn advance(&mut self, dt: f64) -> Result<u32, String> {
        self.sim
            .step(dt)
            .map(|info| info.substeps)
            .map_err(|e| e.to_string())
    }
    fn frame(&mut self, generation: u64, seq: u64) -> (Vec<u8>, f64, Option<[f64; 3]>) {
        self.draw(generation, seq)
    }
    fn time(&self) -> f64 {
        self.sim.state().time
    }
    fn grab_target(&self) -> Option<[f64; 3]> {
        self.grab_target.map(arr)
    }
    fn poke_centre(&self) -> Option<[f64; 3]> {
        self.poke_active.then(|| arr(self.poke.offset()))
    }
    fn obstacle_offsets(&self) -> Vec<[f64; 3]> {
        self.offsets()
    }
}

/// The body a scene makes: 2D scenes (`[model] dimension = 2`) their own.
type Built = (Box<dyn LiveBody>, SceneInfo, Vec<u8>);

fn build_body(input: SceneInput, options: &crate::ViewOptions) -> Result<Built, String> {
    if input.scene.is_plane() {
        let (b, info, topology) = crate::plane_live::PlaneBody::build(input)?;
        return Ok((Box::new(b), info, topology));
    }
    let (b, info, topology) = Body::build(input, options)?;
    Ok((Box::new(b), info, topology))
}

/// The run's controls and figures, as the page sees them.
struct Run {
    generation: u64,
    seq: u64,
    playing: bool,
    time_scale: f64,
    meter: RateMeter,
    frame_ms: f64,
    substeps: u32,
    error: Option<String>,
}

impl Run {
    /// Publishes the body's current state as the next frame.
    fn publish(&mut self, ctx: &SourceContext, body: &mut dyn LiveBody) {
        self.seq += 1;
        let (binary, max_displacement, centroid) = body.frame(self.generation, self.seq);
        let time = body.time();
        let status = Status {
            kind: "status".into(),
            generation: self.generation,
            seq: self.seq,
            time,
            playing: self.playing,
            time_scale: self.time_scale,
            real_time_factor: if self.playing {
                self.meter.record(time)
            } else {
                0.0
            },
            frame_ms: self.frame_ms,
            substeps: self.substeps,
            frame: 0,
            grab_target: body.grab_target(),
            grab_centroid: centroid,
            poke_centre: body.poke_centre(),
            obstacle_offsets: body.obstacle_offsets(),
            max_displacement,
            error: self.error.clone(),
        };
        ctx.publish_frame(status, binary);
    }
}

/// Runs the live source until the viewer stops.
pub(crate) fn run(source: Source, ctx: SourceContext) {
    let frame_period = Duration::from_secs_f64(1.0 / ctx.options.frame_rate);
    let name = source_name(&source);
    let mut run = Run {
        generation: 0,
        seq: 0,
        playing: !ctx.options.paused,
        time_scale: 1.0,
        meter: RateMeter::default(),
        frame_ms: 0.0,
        substeps: 0,
        error: None,
    };
    let mut rebuild = true;
    let mut body: Option<Box<dyn LiveBody>> = None;
    let mut next_tick = Instant::now();
    while !ctx.stopped() {
        if rebuild {
            rebuild = false;
            run.generation += 1;
            run.seq = 0;
            run.meter.reset();
            run.error = None;
            body = None;
            let built = scene_input(&source).and_then(|input| build_body(input, &ctx.options));
            match built {
                Ok((mut b, mut info, topology)) => {
                    info.generation = run.generation;
                    log::info!(
                        "viewer: {} built: {} cells, {} nodes",
                        info.name,
                        info.cells,
                        info.nodes
                    );
                    ctx.publish_scene(info, topology);
                    // The first frame shows the body at rest.
                    run.publish(&ctx, b.as_mut());
                    body = Some(b);
                }
                Err(e) => {
                    log::error!("viewer: {name}: {e}");
                    ctx.publish_scene(
                        SceneInfo::failed(run.generation, "live", name.clone(), e),
                        encode_topology(&[]),
                    );
                }
            }
            next_tick = Instant::now();
        }
        // Everything the pages asked since the last frame.
        let advancing = run.playing && body.is_some() && run.error.is_none();
        let wait = if advancing {
            Duration::ZERO
        } else {
            frame_period
        };
        let mut first = true;
        let mut changed = false;
        let mut step_once = false;
        while let Some(message) = ctx.next_command(if first { wait } else { Duration::ZERO }) {
            first = false;
            changed = true;
            match message {
                ClientMessage::Play => {
                    run.playing = true;
                    run.meter.reset();
                    next_tick = Instant::now();
                }
                ClientMessage::Pause => run.playing = false,
                ClientMessage::Step => {
                    run.playing = false;
                    step_once = true;
                }
                ClientMessage::Reset => rebuild = true,
                ClientMessage::TimeScale { value } => {
                    run.time_scale = value;
                    run.meter.reset();
                }
                ClientMessage::Seek { .. } => {}
                other => {
                    if let Some(b) = body.as_mut() {
                        b.handle(&other);
                    }
                }
            }
        }
        if rebuild || ctx.stopped() {
            continue;
        }
        let Some(b) = body.as_mut() else {
            continue;
        };
        if !(run.playing || step_once) || run.error.is_some() {
            if changed {
                // Paused: the page still sees what it changed (the pause
                // itself, the scale, the grab, the sphere).
                run.publish(&ctx, b.as_mut());
            }
            continue;
        }
        let frame_dt = run.time_scale / ctx.options.frame_rate;
        b.steer(frame_dt);
        let started = Instant::now();
        match b.advance(frame_dt) {
            Ok(substeps) => run.substeps = substeps,
            Err(e) => {
                let message = format!(
                    "the simulation stopped at t = {:.4} s: {e}; press Reset to start again",
                    b.time()
                );
                log::error!("viewer: {message}");
                run.error = Some(message);
                run.playing = false;
            }
        }
        run.frame_ms = started.elapsed().as_secs_f64() * 1e3;
        run.publish(&ctx, b.as_mut());
        // Real time: wait for the frame's slot; a slow frame starts the
        // next at once (the achieved factor shows it).
        next_tick += frame_period;
        let now = Instant::now();
        if next_tick > now {
            std::thread::sleep(next_tick - now);
        } else {
            next_tick = now;
        }
    }
}
