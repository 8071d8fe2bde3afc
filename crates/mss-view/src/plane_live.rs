//! The live source of a 2D scene (`[model] dimension = 2`): the body of a
//! [`PlaneJob`], stepped explicitly at real time, drawn as its lattice's
//! rectangles (two triangles each), dragged and poked from the page.
//!
//! The page's camera has z up; a 2D body lives in the x-y plane with y up.
//! So the page sees the plane's `(x, y)` as its `(x, 0, y)`: the body
//! stands upright facing the camera, and every point the page sends back
//! (a pick, a drag target, the poking centre) is read through the same map
//! (its x and z). A drag holds the 4 nodes of the picked rectangle by a
//! [`PlaneDrag`] whose stiffness is set from the material (about a cell's
//! own, `E t`) and capped well below the lattice's highest frequency, so a
//! drag never shortens the stable step. The poking disc is an obstacle of
//! the problem's contact, moved along a path over each frame (so that
//! friction sees its velocity) and parked far away while not in use.

use std::sync::Arc;

use mss_scene::SceneInput;
use mss_scene::mss_core::Vec3;
use mss_scene::mss_core::contact::Path;
use mss_scene::mss_core::plane::{
    PlaneContact, PlaneContactSettings, PlaneDrag, PlaneObstacle, PlaneProblem,
};
use mss_scene::plane_job::PlaneJob;

use crate::live::LiveBody;
use crate::protocol::{
    ClientMessage, ObstacleDraw, SceneInfo, SurfaceFrame, SurfaceInfo, encode_frame,
    encode_topology,
};

/// Where the poking disc waits while it is not used (m).
const PARKED: [f64; 2] = [1.0e4, 1.0e4];

/// Radius of the poking disc, in cells (of the shorter side).
const POKE_RADIUS_CELLS: f64 = 2.5;

/// The drag's springs stay this far below the lattice's highest
/// frequency (as a fraction of omega_max squared, per node mass).
const DRAG_FREQUENCY_FRACTION: f64 = 0.05;

/// The safety factor on the explicit step.
const SAFETY: f64 = 0.9;

/// The page's point `(x, y, z)` in the plane.
fn to_plane(p: [f64; 3]) -> [f64; 2] {
    [p[0], p[2]]
}

/// The plane's point in the page's frame.
fn to_page(p: [f64; 2]) -> [f64; 3] {
    [p[0], 0.0, p[1]]
}

/// A 2D body in the live viewer.
pub(crate) struct PlaneBody {
    problem: PlaneProblem,
    /// The scene's own contact (before the poking disc is added).
    scene_contact: Option<PlaneContact>,
    /// The poking disc's settings.
    poke_settings: PlaneContactSettings,
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    time: f64,
    dt: f64,
    poke_radius: f64,
    /// Where the disc is (m) and where it goes next frame.
    poke_at: [f64; 2],
    poke_target: Option<[f64; 2]>,
    poke_active: bool,
    drag_stiffness: f64,
    /// The picked rectangle's nodes, the grab's centroid minus the hit
    /// point at the pick, and the target.
    grab: Option<([u32; 4], [f64; 2])>,
    grab_target: Option<[f64; 2]>,
    /// The scene's own loads (the drag comes after them).
    scene_loads: usize,
    /// Rectangles around each node, for averaging the area change.
    node_cell_count: Vec<u32>,
}

impl PlaneBody {
    /// Builds the body of a 2D scene, its scene description and topology.
    pub(crate) fn build(input: SceneInput) -> Result<(Self, SceneInfo, Vec<u8>), String> {
        let job = PlaneJob::prepare(input).map_err(|e| mss_scene::error::one_line(&e))?;
        let problem = job.problem.clone();
        let model = &problem.model;
        let [lx, ly] = model.cell_size();
        let poke_radius = POKE_RADIUS_CELLS * lx.min(ly);
        // The poking disc touches as the scene's obstacles do by default.
        let poke_settings = PlaneContactSettings {
            damping_ratio: 0.2,
            ..PlaneContactSettings::elastic(model.max_node_stiffness(), 0.5)
        };
        let n = model.num_nodes();
        let mean_mass = model.total_mass() / n.max(1) as f64;
        let omega = model.omega_max_bound();
        let young = model.material().young;
        let drag_stiffness = (young * model.thickness())
            .min(DRAG_FREQUENCY_FRACTION * mean_mass * omega * omega * 4.0);
        let mut node_cell_count = vec![0u32; n];
        let mut triangles = Vec::with_capacity(2 * model.num_cells());
        for c in model.cells() {
            for &i in c {
                node_cell_count[i as usize] += 1;
            }
            triangles.push([c[0], c[1], c[2]]);
            triangles.push([c[0], c[2], c[3]]);
        }
        let rest: Vec<[f64; 3]> = model
            .rest_positions()
            .iter()
            .map(|p| to_page([p.x, p.y]))
            .collect();
        let thickness = model.thickness();
        let scene_contact = problem.contact.clone();
        let info = SceneInfo {
            kind: "scene".into(),
            generation: 0,
            mode: "live".into(),
            name: job.input.name(),
            cells: model.num_cells(),
            nodes: n,
            cell_size: lx.min(ly),
            bounds: crate::bounds_of(rest.iter().copied()),
            surfaces: vec![SurfaceInfo {
                name: "skin".into(),
                vertices: n as u32,
                triangles: triangles.len() as u32,
                has_jacobian: true,
            }],
            obstacles: scene_contact
                .as_ref()
                .map(|c| c.obstacles().iter().map(|o| draw(o, thickness)).collect())
                .unwrap_or_default(),
            poke_radius,
            frame_times: Vec::new(),
            error: None,
        };
        let topology = encode_topology(&[&triangles]);
        let x = model.rest_positions().to_vec();
        let mut body = Self {
            v: vec![Vec3::zeros(); x.len()],
            x,
            time: 0.0,
            dt: 0.0,
            poke_radius,
            poke_at: PARKED,
            poke_target: None,
            poke_active: false,
            drag_stiffness,
            grab: None,
            grab_target: None,
            scene_loads: problem.loads.len(),
            node_cell_count,
            scene_contact,
            poke_settings,
            problem,
        };
        // The step with the disc in the contact (its penalty counts).
        body.place_disc(PARKED, PARKED, 0.0, 1.0)?;
        body.dt = SAFETY * body.problem.stable_time_step(1.0);
        Ok((body, info, topology))
    }

    /// Puts the poking disc in the problem's contact, going from `from` at
    /// time `t` to `to` at `t + dt`.
    fn place_disc(&mut self, from: [f64; 2], to: [f64; 2], t: f64, dt: f64) -> Result<(), String> {
        let (mut obstacles, mut paths, mut settings) = match &self.scene_contact {
            Some(c) => (
                c.obstacles().to_vec(),
                if c.paths().is_empty() {
                    vec![Path::fixed(); c.obstacles().len()]
                } else {
                    c.paths().to_vec()
                },
                c.settings().to_vec(),
            ),
            None => (Vec::new(), Vec::new(), Vec::new()),
        };
        obstacles.push(PlaneObstacle::Disc {
            centre: [0.0, 0.0],
            radius: self.poke_radius,
        });
        let key = |t: f64, p: [f64; 2]| (t, Vec3::new(p[0], p[1], 0.0));
        let path = if from == to {
            Path::new(vec![key(t, to)])
        } else {
            Path::new(vec![key(t, from), key(t + dt, to)])
        }
        .ok_or("the poking disc's path is not finite")?;
        paths.push(path);
        settings.push(self.poke_settings);
        self.problem.contact =
            Some(PlaneContact::new(obstacles, paths, settings).map_err(|e| e.to_string())?);
        Ok(())
    }

    /// The nodes of the rectangle of a picked triangle.
    fn cell_of(&self, triangle: u32) -> Option<[u32; 4]> {
        self.problem
            .model
            .cells()
            .get(triangle as usize / 2)
            .copied()
    }

    fn centroid(&self, nodes: &[u32; 4]) -> [f64; 2] {
        let c = nodes.iter().map(|&n| self.x[n as usize]).sum::<Vec3>() / 4.0;
        [c.x, c.y]
    }

    /// Puts the drag toward `target` in the problem's loads (replacing the
    /// last one), or takes it out.
    fn set_drag(&mut self, target: Option<[f64; 2]>) {
        self.problem.loads.truncate(self.scene_loads);
        self.grab_target = target;
        if let (Some((nodes, _)), Some(t)) = (&self.grab, target) {
            match PlaneDrag::new(&self.problem.model, nodes.to_vec(), t, self.drag_stiffness) {
                Ok(drag) => self.problem.loads.push(Arc::new(drag)),
                Err(e) => log::warn!("viewer: {e}"),
            }
        }
    }
}

/// How the page draws a 2D obstacle (`thickness`: the body's, for the
/// depth of a rectangle).
fn draw(o: &PlaneObstacle, thickness: f64) -> ObstacleDraw {
    match *o {
        PlaneObstacle::HalfPlane { point, normal } => ObstacleDraw::Plane {
            point: to_page(point),
            normal: to_page(normal),
        },
        PlaneObstacle::Disc { centre, radius } => ObstacleDraw::Sphere {
            centre: to_page(centre),
            radius,
        },
        PlaneObstacle::Rect { min, max } => ObstacleDraw::Box {
            min: [min[0], -thickness, min[1]],
            max: [max[0], thickness, max[1]],
        },
    }
}

impl LiveBody for PlaneBody {
    fn handle(&mut self, message: &ClientMessage) {
        match *message {
            ClientMessage::Pick {
                triangle, point, ..
            } => {
                let Some(nodes) = self.cell_of(triangle) else {
                    log::warn!("viewer: pick of triangle {triangle}: no such triangle");
                    return;
                };
                let c = self.centroid(&nodes);
                let p = to_plane(point);
                self.grab = Some((nodes, [c[0] - p[0], c[1] - p[1]]));
                self.set_drag(Some(c));
            }
            ClientMessage::Drag { target } => {
                if let Some((_, offset)) = self.grab {
                    let t = to_plane(target);
                    self.set_drag(Some([t[0] + offset[0], t[1] + offset[1]]));
                }
            }
            ClientMessage::Release => {
                self.grab = None;
                self.set_drag(None);
            }
            ClientMessage::Poke { centre } => {
                let c = to_plane(centre);
                if self.poke_active {
                    self.poke_target = Some(c);
                } else {
                    // Put in place at rest: a parked disc has no speed to
                    // bring into the body.
                    self.poke_at = c;
                    self.poke_active = true;
                    self.poke_target = None;
                }
            }
            ClientMessage::Unpoke => {
                self.poke_at = PARKED;
                self.poke_active = false;
                self.poke_target = None;
            }
            _ => {}
        }
    }

    fn steer(&mut self, dt: f64) {
        let to = self.poke_target.take().unwrap_or(self.poke_at);
        if let Err(e) = self.place_disc(self.poke_at, to, self.time, dt) {
            log::warn!("viewer: {e}");
        }
        self.poke_at = to;
    }

    fn advance(&mut self, dt: f64) -> Result<u32, String> {
        let steps = (dt / self.dt).ceil().max(1.0);
        let sub = dt / steps;
        self.problem
            .step_explicit(self.time, &mut self.x, &mut self.v, sub, steps as usize)
            .map_err(|e| e.to_string())?;
        self.time += dt;
        Ok(steps as u32)
    }

    fn frame(&mut self, generation: u64, seq: u64) -> (Vec<u8>, f64, Option<[f64; 3]>) {
        let model = &self.problem.model;
        let rest = model.rest_positions();
        let [lx, ly] = model.cell_size();
        // The area change of each rectangle (its diagonals' cross product),
        // averaged to its nodes: the page's "J".
        let mut j = vec![0.0; self.x.len()];
        for c in model.cells() {
            let p = |k: usize| self.x[c[k] as usize];
            let (d1, d2) = (p(2) - p(0), p(3) - p(1));
            let area = 0.5 * (d1.x * d2.y - d1.y * d2.x) / (lx * ly);
            for &i in c {
                j[i as usize] += area;
            }
        }
        let mut max_disp: f64 = 0.0;
        let mut frame = SurfaceFrame {
            positions: Vec::with_capacity(self.x.len()),
            displacement: Vec::with_capacity(self.x.len()),
            jacobian: Vec::with_capacity(self.x.len()),
        };
        for (i, (p, r)) in self.x.iter().zip(rest).enumerate() {
            let u = (p - r).norm();
            max_disp = max_disp.max(u);
            let q = to_page([p.x, p.y]);
            frame.positions.push(q.map(|c| c as f32));
            frame.displacement.push(u as f32);
            frame
                .jacobian
                .push((j[i] / self.node_cell_count[i].max(1) as f64) as f32);
        }
        let centroid = self
            .grab
            .as_ref()
            .map(|(nodes, _)| to_page(self.centroid(nodes)));
        (
            encode_frame(generation, seq, self.time, &[frame]),
            max_disp,
            centroid,
        )
    }

    fn time(&self) -> f64 {
        self.time
    }

    fn grab_target(&self) -> Option<[f64; 3]> {
        self.grab_target.map(to_page)
    }

    fn poke_centre(&self) -> Option<[f64; 3]> {
        self.poke_active.then(|| to_page(self.poke_at))
    }

    fn obstacle_offsets(&self) -> Vec<[f64; 3]> {
        let Some(c) = &self.scene_contact else {
            return Vec::new();
        };
        (0..c.obstacles().len())
            .map(|i| {
                let d = c
                    .paths()
                    .get(i)
                    .map_or(Vec3::zeros(), |p| p.offset(self.time));
                to_page([d.x, d.y])
            })
            .collect()
    }
}
