//! The replay source: the frames of a folder written by `mss run`, played
//! at their simulated times (times the page's scale), with seeking.
//!
//! The lattice frames listed by `lattice.pvd` are the source of truth (a
//! run of several bodies lists each body's file as a part of its frame:
//! they are shown together): the
//! skin is the boundary of their hexahedra (faces that belong to one cell),
//! coloured by the `displacement` point field and by J = 1 +
//! `volumetric_strain` averaged from the cells to the nodes. A 2D run's
//! quads (its `summary.json` says `dimension` 2) are shown as a thin
//! upright slab, as the live 2D viewer shows them. When every
//! frame also has its embedded surface (`surface_NNNN.vtu`, or `.obj`,
//! beside `lattice_NNNN.vtu`), it is offered as well, coloured by its
//! displacement from the first frame. Frames are read when shown, so a
//! long run costs no memory up front.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use mss_scene::mss_io::vtk::read::{
    LatticeFrameData, QuadFrameData, read_lattice_vtu, read_pvd, read_quads_vtu, read_surface_vtu,
};

use crate::protocol::{
    ClientMessage, SceneInfo, Status, SurfaceFrame, SurfaceInfo, encode_frame, encode_topology,
};
use crate::{RateMeter, SourceContext, ViewError};

/// Largest frame file read (bytes).
const MAX_FRAME_BYTES: u64 = 2 << 30;

/// A run folder, checked when the viewer starts.
#[derive(Debug)]
pub struct RunFolder {
    dir: PathBuf,
    /// Each frame's time and files (one per body).
    frames: Vec<(f64, Vec<String>)>,
    surface_files: Option<Vec<Vec<String>>>,
    /// A 2D run (`summary.json` says `dimension` 2): frames of quads.
    plane: bool,
}

fn not_a_run(dir: &Path, reason: impl Into<String>) -> ViewError {
    ViewError::NotARun {
        path: dir.to_path_buf(),
        reason: reason.into(),
    }
}

impl RunFolder {
    /// Reads the folder's `lattice.pvd` (and notes the surface frames).
    pub fn open(dir: &Path) -> Result<RunFolder, ViewError> {
        // A 2D run's frames are quads: read as a thin slab standing in the
        // page's x-z plane (see `read_frame`).
        let plane = std::fs::read_to_string(dir.join("summary.json"))
            .ok()
            .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
            .is_some_and(|s| s.get("dimension").and_then(|d| d.as_u64()) == Some(2));
        let pvd = dir.join("lattice.pvd");
        if !pvd.is_file() {
            return Err(not_a_run(
                dir,
                "no lattice.pvd: replay needs a folder written by `mss run` with [output] vtu and pvd",
            ));
        }
        let entries = read_pvd(&pvd).map_err(|e| not_a_run(dir, e.to_string()))?;
        // A frame's parts follow each other, numbered from 0.
        let mut frames: Vec<(f64, Vec<String>)> = Vec::new();
        for e in entries {
            match frames.last_mut() {
                Some((time, files)) if e.part > 0 && *time == e.time => files.push(e.file),
                _ => frames.push((e.time, vec![e.file])),
            }
        }
        if frames
            .iter()
            .any(|(_, files)| files.len() != frames[0].1.len())
        {
            return Err(not_a_run(
                dir,
                "lattice.pvd: the frames do not all have the same parts",
            ));
        }
        let surface_files: Option<Vec<Vec<String>>> = frames
            .iter()
            .map(|(_, files)| {
                files
                    .iter()
                    .map(|f| {
                        let s = f.strip_prefix("lattice_")?.strip_suffix(".vtu")?;
                        ["vtu", "obj"]
                            .into_iter()
                            .map(|ext| format!("surface_{s}.{ext}"))
                            .find(|name| dir.join(name).is_file())
                    })
                    .collect()
            })
            .collect();
        Ok(RunFolder {
            dir: dir.to_path_buf(),
            frames,
            surface_files: if plane { None } else { surface_files },
            plane,
        })
    }

    /// The frames' times (s).
    pub fn times(&self) -> Vec<f64> {
        self.frames.iter().map(|f| f.0).collect()
    }
}

/// Positions and triangles of a surface.
type SurfaceMesh = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// A surface OBJ as written by the run: positions and triangles, as they
/// are in the file. hexmesh's loaders are not used here: they weld and drop
/// vertices, which may differ from frame to frame of a deformed surface,
/// while every frame must keep the first frame's vertex numbering.
fn read_obj(path: &Path) -> Result<SurfaceMesh, String> {
    let size = std::fs::metadata(path)
        .map_err(|e| format!("{}: {e}", path.display()))?
        .len();
    if size > MAX_FRAME_BYTES {
        return Err(format!(
            "{}: {size} bytes is too large for a frame",
            path.display()
        ));
    }
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ..tobj::LoadOptions::default()
    };
    let (models, _) =
        tobj::load_obj(path, &options).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for m in models {
        let base = positions.len() as u32;
        let mesh = m.mesh;
        positions.extend(mesh.positions.chunks_exact(3).map(|p| [p[0], p[1], p[2]]));
        for t in mesh.indices.chunks_exact(3) {
            triangles.push([t[0] + base, t[1] + base, t[2] + base]);
        }
    }
    if triangles
        .iter()
        .flatten()
        .any(|&i| i as usize >= positions.len())
    {
        return Err(format!("{}: a face names a missing vertex", path.display()));
    }
    Ok((positions, triangles))
}

/// The boundary of the frame's hexahedra: the skin vertices (lattice
/// nodes) and triangles.
fn boundary(cells: &[[u32; 8]]) -> (Vec<u32>, Vec<[u32; 3]>) {
    let mut count: HashMap<[u32; 4], (u32, [u32; 4])> = HashMap::new();
    for cell in cells {
        for f in mss_scene::hexmesh::lattice::CELL_FACES {
            let quad = f.map(|k| cell[k]);
            let mut key = quad;
            key.sort_unstable();
            count
                .entry(key)
                .and_modify(|e| e.0 += 1)
                .or_insert((1, quad));
        }
    }
    let mut quads: Vec<[u32; 4]> = count
        .into_values()
        .filter(|(n, _)| *n == 1)
        .map(|(_, q)| q)
        .collect();
    quads.sort_unstable();
    let mut vertex_of: HashMap<u32, u32> = HashMap::new();
    let mut nodes = Vec::new();
    let mut index = |n: u32| {
        *vertex_of.entry(n).or_insert_with(|| {
            nodes.push(n);
            nodes.len() as u32 - 1
        })
    };
    let mut triangles = Vec::with_capacity(2 * quads.len());
    for q in quads {
        let v = q.map(&mut index);
        triangles.push([v[0], v[1], v[2]]);
        triangles.push([v[0], v[2], v[3]]);
    }
    (nodes, triangles)
}

/// Frame `k`'s lattice: its parts' files side by side (nodes and cells
/// in part order).
fn read_frame(run: &RunFolder, k: usize) -> Result<LatticeFrameData, String> {
    let mut joined: Option<LatticeFrameData> = None;
    for file in &run.frames[k].1 {
        let path = run.dir.join(file);
        let data = if run.plane {
            read_quads_vtu(&path, MAX_FRAME_BYTES)
                .map(slab)
                .map_err(|e| e.to_string())?
        } else {
            read_lattice_vtu(&path, MAX_FRAME_BYTES).map_err(|e| e.to_string())?
        };
        match &mut joined {
            None => joined = Some(data),
            Some(all) => append_frame(all, data).map_err(|e| format!("{file}: {e}"))?,
        }
    }
    joined.ok_or_else(|| format!("frame {k} lists no file"))
}

/// A 2D frame as a thin slab of hexahedra standing upright in the page's
/// frame (the live 2D viewer's map: the plane's (x, y) is the page's
/// (x, 0, y)), each quad's nodes twice, a tenth of its shorter side apart
/// across the plane, so that the skin is the body's two faces and its
/// outline's strip. Its displacement comes along (mapped alike); J is not
/// written for 2D frames.
fn slab(frame: QuadFrameData) -> LatticeFrameData {
    let n = frame.points.len() as u32;
    let depth = frame
        .quads
        .first()
        .map(|q| {
            let side = |a: usize, b: usize| {
                let (p, r) = (frame.points[q[a] as usize], frame.points[q[b] as usize]);
                (p[0] - r[0]).hypot(p[1] - r[1])
            };
            0.1 * side(0, 1).min(side(1, 2))
        })
        .unwrap_or(0.0);
    let page = |p: [f64; 3], y: f64| [p[0], y, p[1]];
    let points = frame
        .points
        .iter()
        .map(|&p| page(p, -0.5 * depth))
        .chain(frame.points.iter().map(|&p| page(p, 0.5 * depth)))
        .collect();
    let cells = frame
        .quads
        .iter()
        .map(|q| {
            [
                q[0],
                q[1],
                q[2],
                q[3],
                q[0] + n,
                q[1] + n,
                q[2] + n,
                q[3] + n,
            ]
        })
        .collect();
    let mut point_fields = HashMap::new();
    if let Some((u, 3)) = frame.point_fields.get("displacement") {
        let mapped: Vec<f64> = u.chunks_exact(3).flat_map(|d| [d[0], 0.0, d[1]]).collect();
        let twice = mapped.iter().chain(&mapped).copied().collect();
        point_fields.insert("displacement".to_owned(), (twice, 3));
    }
    LatticeFrameData {
        points,
        cells,
        point_fields,
        cell_fields: frame.cell_fields,
    }
}

/// Appends `part` to `all`: its nodes after `all`'s, its cells renumbered,
/// the fields both have joined (the others dropped).
fn append_frame(all: &mut LatticeFrameData, part: LatticeFrameData) -> Result<(), String> {
    let first = u32::try_from(all.points.len()).map_err(|_| "too many points".to_string())?;
    let (points, cells) = (all.points.len(), all.cells.len());
    all.points.extend(part.points);
    all.cells
        .extend(part.cells.into_iter().map(|c| c.map(|i| i + first)));
    let join = |fields: &mut HashMap<String, (Vec<f64>, usize)>,
                mut more: HashMap<String, (Vec<f64>, usize)>,
                had: usize| {
        fields.retain(|name, (values, components)| match more.remove(name) {
            Some((extra, c)) if c == *components && values.len() == had * c => {
                values.extend(extra);
                true
            }
            _ => false,
        });
    };
    join(&mut all.point_fields, part.point_fields, points);
    join(&mut all.cell_fields, part.cell_fields, cells);
    Ok(())
}

/// Frame `k`'s embedded surfaces, side by side.
fn read_surface(run: &RunFolder, files: &[String]) -> Result<SurfaceMesh, String> {
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for file in files {
        let path = run.dir.join(file);
        let (p, t) = if file.ends_with(".vtu") {
            let frame = read_surface_vtu(&path, MAX_FRAME_BYTES).map_err(|e| e.to_string())?;
            (frame.points, frame.triangles)
        } else {
            read_obj(&path)?
        };
        let first = positions.len() as u32;
        positions.extend(p);
        triangles.extend(t.into_iter().map(|t| t.map(|v| v + first)));
    }
    Ok((positions, triangles))
}

struct Loaded {
    skin_nodes: Vec<u32>,
    node_cell_count: Vec<u32>,
    surface_rest: Option<Vec<[f64; 3]>>,
}

fn skin_frame(data: &LatticeFrameData, loaded: &Loaded) -> SurfaceFrame {
    let n = data.points.len();
    let disp = data.point_field("displacement", 3);
    let mut j = vec![0.0; n];
    if let Some(vol) = data.cell_field("volumetric_strain", 1) {
        for (cell, e) in data.cells.iter().zip(vol) {
            for &i in cell {
                j[i as usize] += 1.0 + e;
            }
        }
        for (j, &c) in j.iter_mut().zip(&loaded.node_cell_count) {
            *j /= c.max(1) as f64;
        }
    } else {
        j.fill(1.0);
    }
    let nodes = &loaded.skin_nodes;
    SurfaceFrame {
        positions: nodes
            .iter()
            .map(|&i| data.points[i as usize].map(|c| c as f32))
            .collect(),
        displacement: nodes
            .iter()
            .map(|&i| {
                disp.map_or(0.0, |d| {
                    let i = 3 * i as usize;
                    (d[i] * d[i] + d[i + 1] * d[i + 1] + d[i + 2] * d[i + 2]).sqrt() as f32
                })
            })
            .collect(),
        jacobian: nodes.iter().map(|&i| j[i as usize] as f32).collect(),
    }
}

fn surface_frame(positions: &[[f64; 3]], rest: &[[f64; 3]]) -> SurfaceFrame {
    SurfaceFrame {
        positions: positions.iter().map(|p| p.map(|c| c as f32)).collect(),
        displacement: positions
            .iter()
            .zip(rest)
            .map(|(p, r)| {
                ((p[0] - r[0]).powi(2) + (p[1] - r[1]).powi(2) + (p[2] - r[2]).powi(2)).sqrt()
                    as f32
            })
            .collect(),
        jacobian: vec![1.0; positions.len()],
    }
}

fn load_first(run: &RunFolder) -> Result<(Loaded, SceneInfo, Vec<u8>), String> {
    let data = read_frame(run, 0)?;
    let (skin_nodes, skin_tris) = boundary(&data.cells);
    let mut node_cell_count = vec![0u32; data.points.len()];
    for cell in &data.cells {
        for &i in cell {
            node_cell_count[i as usize] += 1;
        }
    }
    // The rest shape: the first frame less its displacement.
    let rest: Vec<[f64; 3]> = match data.point_field("displacement", 3) {
        Some(d) => data
            .points
            .iter()
            .zip(d.chunks_exact(3))
            .map(|(p, u)| [p[0] - u[0], p[1] - u[1], p[2] - u[2]])
            .collect(),
        None => data.points.clone(),
    };
    let bounds = crate::bounds_of(rest.iter().copied());
    let cell_size = data
        .cells
        .first()
        .map(|c| {
            let (a, b) = (rest[c[0] as usize], rest[c[1] as usize]);
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        })
        .unwrap_or(0.0);
    let mut surfaces = Vec::new();
    let mut topology: Vec<Vec<[u32; 3]>> = Vec::new();
    let mut surface_rest = None;
    if let Some(files) = &run.surface_files {
        match read_surface(run, &files[0]) {
            Ok((positions, triangles)) => {
                surfaces.push(SurfaceInfo {
                    name: "surface".into(),
                    vertices: positions.len() as u32,
                    triangles: triangles.len() as u32,
                    has_jacobian: false,
                });
                topology.push(triangles);
                surface_rest = Some(positions);
            }
            Err(e) => log::warn!("viewer: the embedded surface is not shown: {e}"),
        }
    }
    surfaces.push(SurfaceInfo {
        name: "skin".into(),
        vertices: skin_nodes.len() as u32,
        triangles: skin_tris.len() as u32,
        has_jacobian: data.cell_field("volumetric_strain", 1).is_some(),
    });
    topology.push(skin_tris);
    let info = SceneInfo {
        kind: "scene".into(),
        generation: 1,
        mode: "replay".into(),
        name: run.dir.display().to_string(),
        cells: data.cells.len(),
        nodes: data.points.len(),
        cell_size,
        bounds,
        surfaces,
        obstacles: Vec::new(),
        poke_radius: 0.0,
        frame_times: run.times(),
        error: None,
    };
    let refs: Vec<&[[u32; 3]]> = topology.iter().map(|t| t.as_slice()).collect();
    Ok((
        Loaded {
            skin_nodes,
            node_cell_count,
            surface_rest,
        },
        info,
        encode_topology(&refs),
    ))
}

/// Reads frame `k` and encodes it; an error names the file.
fn encode(run: &RunFolder, loaded: &Loaded, k: usize, seq: u64) -> Result<(Vec<u8>, f64), String> {
    let data = read_frame(run, k)?;
    if data.points.len() != loaded.node_cell_count.len() {
        return Err(format!(
            "{}: {} points where the first frame has {}",
            run.frames[k].1.join(", "),
            data.points.len(),
            loaded.node_cell_count.len()
        ));
    }
    let max_disp = data.point_field("displacement", 3).map_or(0.0, |d| {
        d.chunks_exact(3)
            .map(|u| (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt())
            .fold(0.0, f64::max)
    });
    let mut surfaces = Vec::new();
    if let (Some(rest), Some(files)) = (&loaded.surface_rest, &run.surface_files) {
        let (positions, _) = read_surface(run, &files[k])?;
        if positions.len() != rest.len() {
            return Err(format!(
                "{}: {} vertices where the first frame has {}",
                files[k].join(", "),
                positions.len(),
                rest.len()
            ));
        }
        surfaces.push(surface_frame(&positions, rest));
    }
    surfaces.push(skin_frame(&data, loaded));
    Ok((encode_frame(1, seq, run.frames[k].0, &surfaces), max_disp))
}

/// Runs the replay until the viewer stops.
pub(crate) fn run(run: RunFolder, ctx: SourceContext) {
    let frame_period = Duration::from_secs_f64(1.0 / ctx.options.frame_rate);
    let (loaded, info, topology) = match load_first(&run) {
        Ok(x) => x,
        Err(e) => {
            log::error!("viewer: {e}");
            ctx.publish_scene(
                SceneInfo {
                    frame_times: run.times(),
                    ..SceneInfo::failed(1, "replay", run.dir.display().to_string(), e)
                },
                encode_topology(&[]),
            );
            while !ctx.stopped() {
                let _ = ctx.next_command(frame_period);
            }
            return;
        }
    };
    ctx.publish_scene(info, topology);
    let times = run.times();
    let last = times.len() - 1;
    let mut playing = !ctx.options.paused;
    let mut time_scale = 1.0;
    let mut playhead = times[0];
    let mut shown: Option<usize> = None;
    let mut seq = 0u64;
    let mut meter = RateMeter::default();
    let mut error: Option<String> = None;
    let mut clock = Instant::now();
    while !ctx.stopped() {
        let mut target: Option<usize> = None;
        let wait = if playing {
            frame_period
        } else {
            frame_period * 4
        };
        let mut first = true;
        while let Some(m) = ctx.next_command(if first { wait } else { Duration::ZERO }) {
            first = false;
            match m {
                ClientMessage::Play => {
                    if shown == Some(last) {
                        playhead = times[0];
                    }
                    playing = true;
                    clock = Instant::now();
                    meter.reset();
                }
                ClientMessage::Pause => playing = false,
                ClientMessage::Step => {
                    playing = false;
                    let k = shown.map_or(0, |k| (k + 1).min(last));
                    target = Some(k);
                }
                ClientMessage::Reset => {
                    playing = false;
                    target = Some(0);
                }
                ClientMessage::Seek { frame } => {
                    playing = false;
                    target = Some((frame as usize).min(last));
                }
                ClientMessage::TimeScale { value } => {
                    time_scale = value;
                    meter.reset();
                }
                _ => {}
            }
        }
        if let Some(k) = target {
            playhead = times[k];
        } else if playing {
            let now = Instant::now();
            playhead += now.duration_since(clock).as_secs_f64() * time_scale;
        }
        clock = Instant::now();
        // The latest frame whose time has come.
        let k = times.partition_point(|&t| t <= playhead).saturating_sub(1);
        if playing && k == last {
            playing = false;
        }
        let needs = shown != Some(k) || target.is_some() || seq == 0;
        if !needs {
            continue;
        }
        match encode(&run, &loaded, k, seq + 1) {
            Ok((binary, max_displacement)) => {
                seq += 1;
                shown = Some(k);
                error = None;
                let status = Status {
                    kind: "status".into(),
                    generation: 1,
                    seq,
                    time: times[k],
                    playing,
                    time_scale,
                    real_time_factor: if playing { meter.record(playhead) } else { 0.0 },
                    frame: k as u32,
                    max_displacement,
                    ..Status::default()
                };
                ctx.publish_frame(status, binary);
            }
            Err(e) => {
                if error.as_deref() != Some(e.as_str()) {
                    log::error!("viewer: {e}");
                }
                error = Some(e.clone());
                playing = false;
                shown = Some(k);
                ctx.publish_frame(
                    Status {
                        kind: "status".into(),
                        generation: 1,
                        seq,
                        time: times[k],
                        frame: k as u32,
                        time_scale,
                        error: Some(e),
                        ..Status::default()
                    },
                    Vec::new(),
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_boundary_of_a_block_is_its_outside() {
        let lattice = mss_scene::hexmesh::Lattice::block([3, 2, 2], 0.1, [0.0; 3]).unwrap();
        let (nodes, tris) = boundary(lattice.cells());
        // A 3x2x2 block: 2 * (3*2 + 3*2 + 2*2) = 32 quads, and every node
        // but none inside (a 3x2x2 block has one interior... none: 4x3x3 = 36
        // nodes, interior (2x1x1) = 2).
        assert_eq!(tris.len(), 64);
        assert_eq!(nodes.len(), 36 - 2);
        // Outward: the signed volume of the closed skin is the block's.
        let p = lattice.nodes();
        let vol: f64 = tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| p[nodes[v as usize] as usize]);
                let cross = [
                    b[1] * c[2] - b[2] * c[1],
                    b[2] * c[0] - b[0] * c[2],
                    b[0] * c[1] - b[1] * c[0],
                ];
                (a[0] * cross[0] + a[1] * cross[1] + a[2] * cross[2]) / 6.0
            })
            .sum();
        assert!((vol - 0.3 * 0.2 * 0.2).abs() < 1e-12, "{vol}");
    }
}
