//! Writing the frames of a run: lattice (`.vtu` + `.pvd`, legacy `.vtk`),
//! deformed boundary skin (`.obj`, `.stl`), the embedded input surface and
//! the springs as lines (`.vtu` + `.pvd`).

use std::path::{Path, PathBuf};

use hexmesh::{Embedding, Lattice, Skin, TriMesh};
use mss_core::solver::{Problem, State};
use mss_core::{CellMeasure, SpringSet, Vec3};
use mss_io::IoError;
use mss_io::exporters::{Exporters, SeriesFacts};
use mss_io::pc2::Pc2Writer;
use mss_io::skin::{SkinExporter, SkinFrames};
use mss_io::vtk::{Field, FrameExporter, LatticeFrame, PvdWriter, VtuEncoding, write_lines_vtu};

use crate::error::JobError;
use crate::scene::OutputSection;

/// File name stem of the lattice frames (`lattice_0000.vtu`, `lattice.pvd`).
pub const LATTICE_PREFIX: &str = "lattice";
/// File name stem of the boundary skins (`skin_0000.obj`).
pub const SKIN_PREFIX: &str = "skin";
/// File name stem of the embedded input surface (`surface_0000.obj`).
pub const SURFACE_PREFIX: &str = "surface";
/// File name stem of the springs as lines (`springs_0000.vtu`, `springs.pvd`).
pub const SPRINGS_PREFIX: &str = "springs";

/// Extension of the springs' frames (`springs_NNNN.vtu`): written by
/// [`write_lines_vtu`], not by a registered exporter.
const SPRINGS_EXTENSION: &str = "vtu";

/// One series of files a run writes: `STEM_NNNN.EXT` per frame, an index
/// file `STEM.EXT`, and for a skin a point cache `STEM.pc2` beside its rest
/// shape `STEM_rest.obj`.
struct Series {
    stem: &'static str,
    extensions: Vec<&'static str>,
    index_extensions: Vec<&'static str>,
    point_cache: bool,
}

/// The names of the files a run writes, with the exporters of a registry
/// (their `SeriesFacts`): built once per folder listed.
struct RunFileNames {
    series: [Series; 4],
}

impl RunFileNames {
    fn new(exporters: &Exporters) -> Self {
        let of = |facts: Vec<SeriesFacts>| {
            let extensions = facts.iter().map(|f| f.extension).collect();
            let index = facts.iter().filter_map(|f| f.index_extension).collect();
            (extensions, index)
        };
        let (frames, frame_index) = of(exporters.all_frame_facts());
        let (skins, skin_index): (Vec<_>, Vec<_>) = of(exporters.all_skin_facts());
        let skin = |stem| Series {
            stem,
            extensions: skins.clone(),
            index_extensions: skin_index.clone(),
            point_cache: true,
        };
        RunFileNames {
            series: [
                Series {
                    stem: LATTICE_PREFIX,
                    extensions: frames,
                    index_extensions: frame_index,
                    point_cache: false,
                },
                skin(SKIN_PREFIX),
                skin(SURFACE_PREFIX),
                Series {
                    stem: SPRINGS_PREFIX,
                    extensions: vec![SPRINGS_EXTENSION],
                    index_extensions: vec!["pvd"],
                    point_cache: false,
                },
            ],
        }
    }

    /// Whether `name` is a file a run writes: `STEM_NNNN.EXT` (four or more
    /// digits) of a series, its index file, a point cache and its rest
    /// shape, `summary.json` or the checkpoint.
    fn matches(&self, name: &str) -> bool {
        if name == crate::checkpoint::CHECKPOINT_FILE || name == "summary.json" {
            return true;
        }
        self.series.iter().any(|s| {
            let Some(rest) = name.strip_prefix(s.stem) else {
                return false;
            };
            // A body's series has its name after the stem (`lattice_a_0001.vtu`).
            s.matches_tail(rest)
                || rest.strip_prefix('_').is_some_and(|named| {
                    named.char_indices().any(|(i, c)| {
                        (c == '_' || c == '.')
                            && i > 0
                            && named[..i]
                                .chars()
                                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
                            && s.matches_tail(&named[i..])
                    })
                })
        })
    }
}

impl Series {
    /// Whether `rest`, what follows the stem of a file name (and its body's
    /// name), is one of this series' files: `.EXT` of an index file,
    /// `.pc2` and `_rest.obj` of a point cache, `_NNNN.EXT` of a frame.
    fn matches_tail(&self, rest: &str) -> bool {
        if let Some(ext) = rest.strip_prefix('.') {
            return self.index_extensions.contains(&ext) || (self.point_cache && ext == "pc2");
        }
        if rest == "_rest.obj" {
            return self.point_cache;
        }
        let Some((digits, ext)) = rest.strip_prefix('_').and_then(|r| r.split_once('.')) else {
            return false;
        };
        digits.len() >= 4
            && digits.bytes().all(|b| b.is_ascii_digit())
            && self.extensions.contains(&ext)
    }
}

/// For a temporary file of [`mss_io::atomic::write_atomic`]
/// (`.NAME.tmp-PID-N`), the final name and the writing process.
fn temporary_of(name: &str) -> Option<(&str, u32)> {
    let rest = name.strip_prefix('.')?;
    let (target, tail) = rest.rsplit_once(".tmp-")?;
    let (pid, n) = tail.split_once('-')?;
    n.parse::<u64>().ok()?;
    Some((target, pid.parse().ok()?))
}

fn process_is_running(pid: u32) -> bool {
    pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists()
}

/// The files an earlier run left in `dir` that a new run there would mix
/// with its own: the numbered frames of every series the exporters of
/// `exporters` write, the `.pvd` files and `summary.json`, and temporary
/// files of runs that were interrupted (their process is gone). Nothing
/// else is touched. Sorted by name.
pub fn previous_run_files(dir: &Path, exporters: &Exporters) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let names = RunFileNames::new(exporters);
    let mut out: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter_map(|e| {
            let name = e.file_name().to_str()?.to_owned();
            let ours = names.matches(&name)
                || temporary_of(&name)
                    .is_some_and(|(target, pid)| names.matches(target) && !process_is_running(pid));
            ours.then(|| e.path())
        })
        .collect();
    out.sort();
    out
}

/// Removes [`previous_run_files`] from `dir`; returns how many were removed.
pub fn remove_previous_run(dir: &Path, exporters: &Exporters) -> Result<usize, JobError> {
    let files = previous_run_files(dir, exporters);
    for f in &files {
        std::fs::remove_file(f).map_err(|e| IoError::io(f, e))?;
    }
    if !files.is_empty() {
        log::info!(
            "removed {} files of an earlier run in {}",
            files.len(),
            dir.display()
        );
    }
    Ok(files.len())
}

/// The springs output of a run.
struct SpringsOutput {
    /// Built at the first frame, from the model being run.
    set: Option<SpringSet>,
    /// The `.pvd` of the spring frames; `None` when only the last state is written.
    pvd: Option<PvdWriter>,
    /// `[output] compression`.
    encoding: VtuEncoding,
}

/// The input surface carried by the lattice, and its exporter.
struct EmbeddedOutput {
    embedding: Embedding,
    triangles: Vec<[u32; 3]>,
    exporter: Box<dyn SkinExporter>,
    /// Its files' extension.
    extension: &'static str,
    cache: Option<Pc2Writer>,
}

/// Starts `STEM.pc2` in `dir` after writing its rest shape `STEM_rest.obj`.
fn start_cache(
    dir: &Path,
    stem: &str,
    rest: &[[f64; 3]],
    triangles: &[[u32; 3]],
    normals: mss_io::skin::Normals,
) -> Result<Pc2Writer, IoError> {
    mss_io::skin::write_obj_with(
        &dir.join(format!("{stem}_rest.obj")),
        rest,
        triangles,
        normals,
    )?;
    Pc2Writer::create(&dir.join(format!("{stem}.pc2")), rest.len(), 0.0, 1.0)
}

/// The buffers a frame's derived fields are computed into, one field at a
/// time, kept between frames.
#[derive(Default)]
struct FrameScratch {
    /// A derived point field of every node (displacement, a force).
    nodes: Vec<Vec3>,
    /// A derived cell field of one body's cells.
    cells: Vec<f64>,
}

/// What a frame writes that is constant over a run: filled at the first
/// frame.
#[derive(Default)]
struct FrameConstants {
    fixed: Vec<bool>,
    material: Vec<u32>,
}

/// A point or cell field derived from the state when it is written, so that
/// a frame never holds more than one of them (the exporters write one array
/// after the other; [`mss_io::vtk::ComputedValues`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Derived {
    Displacement,
    InternalForce,
    ExternalForce,
    ContactForce,
    Cell(CellMeasure),
}

impl Derived {
    const POINT_FIELDS: [Derived; 3] = [
        Derived::Displacement,
        Derived::InternalForce,
        Derived::ExternalForce,
    ];
    const CELL_FIELDS: [Derived; 3] = [
        Derived::Cell(CellMeasure::VolumetricStrain),
        Derived::Cell(CellMeasure::ShearStrain),
        Derived::Cell(CellMeasure::CorrectionForce),
    ];

    fn name(self) -> &'static str {
        match self {
            Derived::Displacement => "displacement",
            Derived::InternalForce => "internal_force",
            Derived::ExternalForce => "external_force",
            Derived::ContactForce => "contact_force",
            Derived::Cell(CellMeasure::VolumetricStrain) => "volumetric_strain",
            Derived::Cell(CellMeasure::ShearStrain) => "shear_strain",
            Derived::Cell(CellMeasure::CorrectionForce) => "correction_force",
        }
    }

    fn per_cell(self) -> bool {
        matches!(self, Derived::Cell(_))
    }
}

/// The buffers a frame's derived fields are computed into.
struct FrameBuffers<'a> {
    /// One entry per node of the model.
    nodes: &'a mut [Vec3],
    cells: &'a mut Vec<f64>,
}

/// The state a frame's derived fields come from.
struct FrameSource<'a> {
    problem: &'a Problem,
    state: &'a State,
    scratch: std::sync::Mutex<FrameBuffers<'a>>,
    /// The contact forces of every node, searched once per frame (they
    /// were searched again for each body's file).
    contact: std::sync::OnceLock<Vec<Vec3>>,
}

/// One body's share of a derived field.
struct DerivedField<'a, 's> {
    which: Derived,
    /// The body's nodes or cells among the model's.
    range: std::ops::Range<usize>,
    source: &'a FrameSource<'s>,
}

impl DerivedField<'_, '_> {
    fn field(&self) -> Field<'_> {
        Field::computed(self.which.name(), self)
    }
}

impl mss_io::vtk::ComputedValues for DerivedField<'_, '_> {
    /// Cell measures are computed cell by cell: a `.vtu` writer asks for
    /// them a block at a time, and no array of them is held.
    fn values_of(&self, entries: std::ops::Range<usize>, out: &mut Vec<f64>) -> bool {
        let Derived::Cell(measure) = self.which else {
            return false;
        };
        let start = self.range.start;
        let FrameSource { state, problem, .. } = self.source;
        let cells = start + entries.start..start + entries.end;
        problem
            .model()
            .cell_measure_of(&state.x, cells, measure, out);
        true
    }

    fn len(&self) -> usize {
        self.range.len()
    }

    fn num_components(&self) -> usize {
        if self.which.per_cell() { 1 } else { 3 }
    }

    fn with_values(
        &self,
        write: &mut dyn FnMut(&[f64]) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        let FrameSource { problem, state, .. } = self.source;
        let model = problem.model();
        let mut guard = self
            .source
            .scratch
            .lock()
            .map_err(|_| std::io::Error::other("a frame field's computation panicked"))?;
        let sc = &mut *guard;
        let range = self.range.clone();
        match self.which {
            Derived::Displacement => {
                let rest = &model.rest_positions()[range.clone()];
                let out = &mut sc.nodes[..range.len()];
                for ((o, x), r) in out.iter_mut().zip(&state.x[range]).zip(rest) {
                    *o = x - r;
                }
                write(mss_core::as_arrays(out).as_flattened())
            }
            Derived::InternalForce | Derived::ExternalForce => {
                // Forces gather over cells and loads: computed for every
                // node, written for the body's (again for each body of a
                // scene of several: one node array, not one per field).
                sc.nodes.fill(Vec3::zeros());
                if self.which == Derived::InternalForce {
                    model.internal_forces(&state.x, sc.nodes);
                } else {
                    problem.external_forces(state.time, &state.x, 1.0, sc.nodes);
                }
                write(mss_core::as_arrays(&sc.nodes[range]).as_flattened())
            }
            Derived::ContactForce => {
                let f = self
                    .source
                    .contact
                    .get_or_init(|| problem.contact_forces(state));
                write(mss_core::as_arrays(&f[range]).as_flattened())
            }
            Derived::Cell(measure) => {
                model.cell_measure_of(&state.x, range, measure, sc.cells);
                write(sc.cells)
            }
        }
    }
}

/// The point and cell arrays of the frame being written.
struct FrameArrays<'a, 's> {
    points: &'a [[f64; 3]],
    velocity: &'a [[f64; 3]],
    fixed: &'a [bool],
    material: &'a [u32],
    source: &'a FrameSource<'s>,
    has_contact: bool,
}

/// Where each body's nodes start among the nodes of the bodies side by side
/// (`bodies`: each one's lattice and input surface, in the model's node
/// order, as in [`mss_core::Model::union`]).
fn node_offsets(bodies: &[(&Lattice, &TriMesh)]) -> Vec<u32> {
    bodies
        .iter()
        .scan(0u32, |start, (l, _)| {
            let at = *start;
            *start += l.num_nodes() as u32;
            Some(at)
        })
        .collect()
}

/// The bodies' lattice skins as one skin over the nodes of their union.
pub fn joined_skin(bodies: &[(&Lattice, &TriMesh)]) -> Skin {
    let mut skin = Skin::default();
    for ((lattice, _), offset) in bodies.iter().zip(node_offsets(bodies)) {
        skin.append(&hexmesh::boundary_skin(lattice), offset);
    }
    skin
}

/// The bodies' input surfaces embedded in their lattices, as one embedding
/// over the nodes of their union (vertices and triangles in body order).
/// Panics without a body.
pub fn joined_embedding(bodies: &[(&Lattice, &TriMesh)]) -> Embedding {
    let mut all = Embedding::new(bodies[0].0, bodies[0].1);
    for ((lattice, surface), offset) in bodies.iter().zip(node_offsets(bodies)).skip(1) {
        all.append(&Embedding::new(lattice, surface), offset);
    }
    all
}

/// One body of a run, for its output.
#[derive(Clone, Copy)]
pub struct OutputBody<'a> {
    /// Its name: in the names of its files when a run has several bodies.
    pub name: &'a str,
    /// Its lattice.
    pub lattice: &'a Lattice,
    /// Its input surface, placed.
    pub surface: &'a TriMesh,
    /// The image label of each of its cells (written as the cell field
    /// `label`), for a body made from an image.
    pub cell_labels: Option<&'a [i32]>,
}

/// One body's files: its lattice frames, skin and surface.
struct PartWriter {
    /// The body's name, `None` for the one body of a scene without
    /// `[[bodies]]` (its files keep the plain stems: `lattice_0000.vtu`).
    name: Option<String>,
    /// Its nodes and cells among the model's.
    nodes: std::ops::Range<usize>,
    cells: std::ops::Range<usize>,
    /// Its cells over its own nodes (the lattice's, shared: not a copy).
    local_cells: std::sync::Arc<[[u32; 8]]>,
    /// Its cells' image labels (a body made from an image).
    cell_labels: Option<Vec<i32>>,
    /// Lattice frame exporters with the extension of the files they write
    /// (`None` for custom exporters, whose files are not counted).
    lattice: Vec<(Box<dyn FrameExporter>, Option<&'static str>)>,
    skin: Option<Skin>,
    skin_exporters: Vec<(Box<dyn SkinExporter>, &'static str)>,
    skin_cache: Option<Pc2Writer>,
    embedded: Option<EmbeddedOutput>,
}

impl PartWriter {
    /// The stem of this body's files of the series `prefix`.
    fn stem(&self, prefix: &str) -> String {
        match &self.name {
            Some(name) => format!("{prefix}_{name}"),
            None => prefix.to_owned(),
        }
    }

    fn new(
        dir: &Path,
        out: &OutputSection,
        exporters: &Exporters,
        body: &OutputBody<'_>,
        name: Option<String>,
        nodes: std::ops::Range<usize>,
        cells: std::ops::Range<usize>,
    ) -> Result<Self, JobError> {
        let mut part = PartWriter {
            name,
            nodes,
            cells,
            local_cells: body.lattice.shared_cells(),
            cell_labels: body.cell_labels.map(<[i32]>::to_vec),
            lattice: Vec::new(),
            skin: None,
            skin_exporters: Vec::new(),
            skin_cache: None,
            embedded: None,
        };
        let lattice_stem = part.stem(LATTICE_PREFIX);
        for name in frame_exporter_names(out) {
            let extension = exporters.frame_facts(name).map(|f| f.extension);
            part.lattice
                .push((exporters.frames(name, dir, &lattice_stem)?, extension));
        }
        let rest = body.lattice.nodes();
        let skin_stem = part.stem(SKIN_PREFIX);
        let skin =
            (out.skin_obj || out.skin_stl || out.pc2).then(|| hexmesh::boundary_skin(body.lattice));
        for name in skin_exporter_names(out) {
            let e = exporters.skins(name, dir, &skin_stem, SkinFrames::Every)?;
            let extension = exporters.skin_facts(name).map_or("", |f| f.extension);
            part.skin_exporters.push((e, extension));
        }
        if let (Some(skin), true) = (&skin, out.pc2) {
            part.skin_cache = Some(start_cache(
                dir,
                &skin_stem,
                &skin.positions(rest),
                &skin.triangles,
                out.skin_normals,
            )?);
        }
        part.skin = skin;
        if out.embedded {
            let surface_stem = part.stem(SURFACE_PREFIX);
            let mesh = body.surface;
            part.embedded = Some(EmbeddedOutput {
                embedding: Embedding::new(body.lattice, mesh),
                triangles: mesh.triangles.clone(),
                exporter: exporters.skins(
                    out.surface_exporter(),
                    dir,
                    &surface_stem,
                    SkinFrames::Every,
                )?,
                extension: exporters
                    .skin_facts(out.surface_exporter())
                    .map_or("", |f| f.extension),
                cache: if out.pc2 {
                    Some(start_cache(
                        dir,
                        &surface_stem,
                        &mesh.vertices,
                        &mesh.triangles,
                        out.surface_normals,
                    )?)
                } else {
                    None
                },
            });
        }
        Ok(part)
    }
}

/// Writes the frames of one run into one folder.
pub struct FrameWriter {
    dir: PathBuf,
    /// Each body's files (one part for a scene without `[[bodies]]`).
    parts: Vec<PartWriter>,
    /// Whether the `.vtu` series keeps `.pvd` files (`[output] pvd`).
    lattice_pvd: bool,
    /// With several bodies, `lattice.pvd` listing every body's `.vtu` of
    /// each frame as a part (ParaView opens it as one multiblock series);
    /// each body's `lattice_NAME.pvd` lists its own.
    parts_pvd: Option<PvdWriter>,
    springs: Option<SpringsOutput>,
    /// Times of the frames written, in order (a checkpoint keeps them).
    times: Vec<f64>,
    /// The frame arrays, reused from frame to frame.
    scratch: FrameScratch,
    constants: FrameConstants,
    files: usize,
    bytes: u64,
}

impl FrameWriter {
    /// Prepares the writers the `[output]` table asks for, from `exporters`
    /// (the folder must exist), for the bodies `bodies`, in the model's
    /// node order (see [`mss_core::Model::union`]). One body's files have
    /// the plain stems (`lattice_0000.vtu`, `skin_0000.obj`); with several,
    /// each body has its own, its name after the stem (`lattice_ball_0000.vtu`,
    /// `skin_ball_0000.obj`, `surface_ball.pc2`), and `lattice.pvd` lists
    /// them all, a part per body.
    pub fn new(
        dir: &Path,
        out: &OutputSection,
        exporters: &Exporters,
        bodies: &[OutputBody<'_>],
    ) -> Result<Self, JobError> {
        let several = bodies.len() > 1;
        let mut parts = Vec::with_capacity(bodies.len());
        let (mut node, mut cell) = (0, 0);
        for body in bodies {
            let nodes = node..node + body.lattice.num_nodes();
            let cells = cell..cell + body.lattice.num_cells();
            (node, cell) = (nodes.end, cells.end);
            let name = several.then(|| body.name.to_owned());
            parts.push(PartWriter::new(
                dir, out, exporters, body, name, nodes, cells,
            )?);
        }
        // One frame is not a series: a .pvd would only repeat the file name.
        let springs = out.springs.then(|| SpringsOutput {
            set: None,
            pvd: (out.pvd && !out.last_only)
                .then(|| PvdWriter::new(dir.join(format!("{SPRINGS_PREFIX}.pvd")))),
            encoding: out.compression.encoding(),
        });
        let series = out.vtu && out.pvd && !out.last_only;
        Ok(Self {
            dir: dir.to_path_buf(),
            parts,
            lattice_pvd: out.vtu && out.pvd,
            parts_pvd: (several && series)
                .then(|| PvdWriter::new(dir.join(format!("{LATTICE_PREFIX}.pvd")))),
            springs,
            times: Vec::new(),
            scratch: FrameScratch::default(),
            constants: FrameConstants::default(),
            files: 0,
            bytes: 0,
        })
    }

    /// Frame times are round numbers to `decimals` decimals: the `.pvd`
    /// collections print them so (`0.02`, not `0.019999999999999987`, the
    /// sum of the steps); see [`mss_io::vtk::time_decimals`].
    pub fn with_time_decimals(mut self, decimals: Option<usize>) -> Self {
        let Some(decimals) = decimals else {
            return self;
        };
        for part in &mut self.parts {
            for (exporter, _) in &mut part.lattice {
                exporter.set_time_decimals(decimals);
            }
            for (exporter, _) in &mut part.skin_exporters {
                exporter.set_time_decimals(decimals);
            }
            if let Some(e) = &mut part.embedded {
                e.exporter.set_time_decimals(decimals);
            }
        }
        if let Some(pvd) = &mut self.parts_pvd {
            pvd.set_time_decimals(Some(decimals));
        }
        if let Some(pvd) = self.springs.as_mut().and_then(|s| s.pvd.as_mut()) {
            pvd.set_time_decimals(Some(decimals));
        }
        self
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.times.len()
    }

    /// Time of the last frame written (s), if any.
    pub fn last_time(&self) -> Option<f64> {
        self.times.last().copied()
    }

    /// Times of the frames written so far (s).
    pub fn frame_times(&self) -> &[f64] {
        &self.times
    }

    /// The `.vtu` of each body for frame `index`, with the body's name.
    fn part_files(&self, index: usize) -> Vec<(String, String)> {
        self.parts
            .iter()
            .map(|p| {
                (
                    p.name.clone().unwrap_or_default(),
                    format!("{}_{index:04}.vtu", p.stem(LATTICE_PREFIX)),
                )
            })
            .collect()
    }

    /// Continues the series of a run resumed from a checkpoint: frames at
    /// `frame_times` are on disk, and `files` files of `bytes` bytes were
    /// written. Every exporter resumes after them; point caches keep their
    /// first `frame_times.len()` samples (they must be in the folder: a run
    /// that stopped cleanly leaves them).
    pub fn resume(
        &mut self,
        frame_times: &[f64],
        files: usize,
        bytes: u64,
    ) -> Result<(), JobError> {
        let samples = u32::try_from(frame_times.len())
            .map_err(|_| IoError::invalid(&self.dir, "too many frames for a point cache"))?;
        for part in &mut self.parts {
            for (exporter, _) in &mut part.lattice {
                exporter.resume(frame_times)?;
            }
            for (exporter, _) in &mut part.skin_exporters {
                exporter.resume(frame_times)?;
            }
            if let Some(cache) = &mut part.skin_cache {
                *cache = Pc2Writer::resume(
                    cache.path(),
                    part.skin.as_ref().map_or(0, |s| s.vertex_nodes.len()),
                    samples,
                )?;
            }
            if let Some(e) = &mut part.embedded {
                e.exporter.resume(frame_times)?;
                if let Some(cache) = &mut e.cache {
                    let points = e.embedding.vertex_coords().len();
                    *cache = Pc2Writer::resume(cache.path(), points, samples)?;
                }
            }
        }
        if self.parts_pvd.is_some() {
            let mut entries = Vec::new();
            for (i, &time) in frame_times.iter().enumerate() {
                for (k, (name, file)) in self.part_files(i).into_iter().enumerate() {
                    entries.push(mss_io::vtk::PvdEntry {
                        time,
                        part: k as u32,
                        name: Some(name),
                        file,
                    });
                }
            }
            if let Some(pvd) = &mut self.parts_pvd {
                pvd.set_entries(entries)?;
            }
        }
        if let Some(pvd) = self.springs.as_mut().and_then(|s| s.pvd.as_mut()) {
            let entries = frame_times
                .iter()
                .enumerate()
                .map(|(i, &t)| (t, format!("{SPRINGS_PREFIX}_{i:04}.vtu")))
                .collect();
            pvd.set_frames(entries)?;
        }
        self.times = frame_times.to_vec();
        self.files = files;
        self.bytes = bytes;
        Ok(())
    }

    /// Files written so far and their total size (bytes).
    pub fn files_and_bytes(&self) -> (usize, u64) {
        (self.files, self.bytes)
    }

    fn count(&mut self, path: &Path) {
        self.files += 1;
        self.bytes += std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    }

    /// Writes one frame of `state` (time `state.time`).
    pub fn write(&mut self, problem: &Problem, state: &State) -> Result<(), JobError> {
        self.write_with_scratch(problem, state, None)
    }

    /// [`FrameWriter::write`], computing the frame's derived point fields
    /// into `lent` (one entry per node; see
    /// [`mss_core::solver::Integrator::lend_scratch`]) instead of an array
    /// the writer keeps; one of another length is not used.
    pub fn write_with_scratch(
        &mut self,
        problem: &Problem,
        state: &State,
        lent: Option<&mut [Vec3]>,
    ) -> Result<(), JobError> {
        let model = problem.model();
        let n = model.num_nodes();
        let index = self.times.len();
        let constants = &mut self.constants;
        if constants.fixed.len() != n {
            let constraints = problem.constraints();
            constants.fixed = (0..n)
                .map(|i| constraints.mask(i).iter().any(|&h| h))
                .collect();
            constants.material = if model.materials().len() > 1 {
                (0..model.num_cells())
                    .map(|c| model.cell_material(c))
                    .collect()
            } else {
                Vec::new()
            };
        }
        // The derived fields are computed as each is written, into buffers
        // kept between frames: one node array and one cell array at a
        // time, not one per field.
        let mut scratch = std::mem::take(&mut self.scratch);
        let constants = std::mem::take(&mut self.constants);
        let nodes = match lent {
            Some(lent) if lent.len() == n => lent,
            _ => {
                scratch.nodes.resize(n, Vec3::zeros());
                &mut scratch.nodes[..]
            }
        };
        let source = FrameSource {
            problem,
            state,
            scratch: std::sync::Mutex::new(FrameBuffers {
                nodes,
                cells: &mut scratch.cells,
            }),
            contact: std::sync::OnceLock::new(),
        };
        let result = self.write_frame(
            problem,
            state,
            index,
            FrameArrays {
                points: mss_core::as_arrays(&state.x),
                velocity: mss_core::as_arrays(&state.v),
                fixed: &constants.fixed,
                material: &constants.material,
                source: &source,
                has_contact: problem.contact().is_some(),
            },
        );
        self.scratch = scratch;
        self.constants = constants;
        result
    }

    fn write_frame(
        &mut self,
        problem: &Problem,
        state: &State,
        index: usize,
        a: FrameArrays<'_, '_>,
    ) -> Result<(), JobError> {
        let mut written = Vec::new();
        for part in &mut self.parts {
            Self::write_part(&self.dir, part, state.time, index, &a, &mut written)?;
        }
        if self.parts_pvd.is_some() {
            let files = self.part_files(index);
            let refs: Vec<(&str, &str)> = files
                .iter()
                .map(|(n, f)| (n.as_str(), f.as_str()))
                .collect();
            if let Some(pvd) = &mut self.parts_pvd {
                pvd.add_parts(state.time, &refs)?;
            }
        }
        for p in written {
            self.count(&p);
        }
        if self.springs.is_some() {
            self.write_springs(index, problem, state, a.points)?;
        }
        self.times.push(state.time);
        Ok(())
    }

    /// Writes one body's files of frame `index`, noting their paths in
    /// `written`.
    fn write_part(
        dir: &Path,
        part: &mut PartWriter,
        time: f64,
        index: usize,
        a: &FrameArrays<'_, '_>,
        written: &mut Vec<PathBuf>,
    ) -> Result<(), JobError> {
        let (n, c) = (part.nodes.clone(), part.cells.clone());
        let points = &a.points[n.clone()];
        if !part.lattice.is_empty() {
            let derived = |which: Derived| DerivedField {
                which,
                range: if which.per_cell() {
                    c.clone()
                } else {
                    n.clone()
                },
                source: a.source,
            };
            let [displacement, f_int, f_ext] = Derived::POINT_FIELDS.map(derived);
            let [vol, shear, corr] = Derived::CELL_FIELDS.map(derived);
            let contact_force = derived(Derived::ContactForce);
            let mut frame = LatticeFrame::new(points, &part.local_cells)
                .with_point_field(displacement.field())
                .with_point_field(Field::vectors("velocity", &a.velocity[n.clone()]))
                .with_point_field(f_int.field())
                .with_point_field(f_ext.field())
                .with_point_field(Field::flags("fixed", &a.fixed[n.clone()]))
                .with_cell_field(vol.field())
                .with_cell_field(shear.field())
                .with_cell_field(corr.field());
            if !a.material.is_empty() {
                frame = frame.with_cell_field(Field::ids("material", &a.material[c.clone()]));
            }
            if let Some(labels) = &part.cell_labels {
                frame = frame.with_cell_field(Field::labels("label", labels));
            }
            if a.has_contact {
                frame = frame.with_point_field(contact_force.field());
            }
            let stem = part.stem(LATTICE_PREFIX);
            for (exporter, ext) in &mut part.lattice {
                exporter.write_frame(index, time, &frame)?;
                if let Some(ext) = ext {
                    written.push(dir.join(format!("{stem}_{index:04}.{ext}")));
                }
            }
        }
        if let Some(skin) = &part.skin {
            let pos = skin.positions(points);
            let stem = part.stem(SKIN_PREFIX);
            for (exporter, ext) in &mut part.skin_exporters {
                exporter.write_skin(index, time, &pos, &skin.triangles)?;
                written.push(dir.join(format!("{stem}_{index:04}.{ext}")));
            }
            if let Some(cache) = &mut part.skin_cache {
                cache.append(&pos)?;
            }
        }
        let surface_stem = part.stem(SURFACE_PREFIX);
        if let Some(e) = &mut part.embedded {
            let pos = e.embedding.deform(points);
            e.exporter.write_skin(index, time, &pos, &e.triangles)?;
            if let Some(cache) = &mut e.cache {
                cache.append(&pos)?;
            }
            let ext = &e.extension;
            written.push(dir.join(format!("{surface_stem}_{index:04}.{ext}")));
        }
        Ok(())
    }

    /// Writes `springs_NNNN.vtu` (and rewrites `springs.pvd`) for one frame.
    fn write_springs(
        &mut self,
        index: usize,
        problem: &Problem,
        state: &State,
        points: &[[f64; 3]],
    ) -> Result<(), JobError> {
        let Some(out) = self.springs.as_mut() else {
            return Ok(());
        };
        let set = out
            .set
            .get_or_insert_with(|| SpringSet::new(problem.model()));
        let file = format!("{SPRINGS_PREFIX}_{index:04}.vtu");
        let path = self.dir.join(&file);
        let strain = set
            .strains(&state.x)
            .map_err(|e| IoError::invalid(&path, format!("frame {index}: springs: {e}")))?;
        write_lines_vtu(
            &path,
            points,
            &set.topology.nodes,
            &[
                Field::scalars("strain", &strain),
                Field::scalars("stiffness", &set.stiffness),
                Field::scalars("rest_length", &set.rest_length),
                Field::flags("diagonal", &set.topology.diagonal),
            ],
            out.encoding,
        )?;
        // `add_frame` rewrites the .pvd, like the lattice's, so that an
        // interrupted run still has a collection of what it wrote.
        if let Some(pvd) = out.pvd.as_mut() {
            pvd.add_frame(state.time, &file)?;
        }
        self.count(&path);
        Ok(())
    }

    /// Completes the series (final `.pvd`).
    pub fn finish(&mut self) -> Result<(), JobError> {
        let mut finished = Vec::new();
        for part in &mut self.parts {
            for (exporter, _) in &mut part.lattice {
                exporter.finish()?;
            }
            for (exporter, _) in &mut part.skin_exporters {
                exporter.finish()?;
            }
            if let Some(e) = &mut part.embedded {
                e.exporter.finish()?;
            }
            let caches = [
                part.skin_cache.as_mut(),
                part.embedded.as_mut().and_then(|e| e.cache.as_mut()),
            ];
            // Each cache and its rest shape are counted when the cache is published.
            for cache in caches.into_iter().flatten() {
                if cache.is_finished() {
                    continue;
                }
                cache.finish()?;
                let path = cache.path().to_path_buf();
                let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
                finished.push(path.with_file_name(format!("{stem}_rest.obj")));
                finished.push(path);
            }
            let p = self.dir.join(format!("{}.pvd", part.stem(LATTICE_PREFIX)));
            if self.lattice_pvd && p.exists() {
                finished.push(p);
            }
        }
        if let Some(pvd) = &self.parts_pvd
            && !pvd.entries().is_empty()
        {
            finished.push(pvd.path().to_path_buf());
        }
        if let Some(pvd) = self.springs.as_ref().and_then(|s| s.pvd.as_ref())
            && !pvd.entries().is_empty()
        {
            finished.push(pvd.path().to_path_buf());
        }
        for p in finished {
            self.count(&p);
        }
        Ok(())
    }
}

/// Sizes of what one frame writes, for [`frame_size_estimate`].
#[derive(Debug, Clone, Copy, Default)]
pub struct FrameCounts {
    /// Lattice nodes.
    pub nodes: usize,
    /// Lattice cells.
    pub cells: usize,
    /// Springs.
    pub springs: usize,
    /// Boundary skin vertices.
    pub skin_vertices: usize,
    /// Boundary skin triangles.
    pub skin_triangles: usize,
    /// Input surface vertices.
    pub surface_vertices: usize,
    /// Input surface triangles.
    pub surface_triangles: usize,
}

/// The lattice frame exporters `[output]` asks for, by name.
fn frame_exporter_names(out: &OutputSection) -> Vec<&str> {
    let mut names = Vec::new();
    if out.vtu {
        names.push(out.compression.vtu_exporter(out.pvd));
    }
    if out.vtk {
        names.push("vtk");
    }
    names.extend(out.exporters.iter().map(String::as_str));
    names
}

/// The boundary skin exporters `[output]` asks for, by name.
fn skin_exporter_names(out: &OutputSection) -> Vec<&'static str> {
    let mut names = Vec::new();
    if out.skin_obj {
        names.push(crate::scene::obj_exporter(out.skin_normals));
    }
    if out.skin_stl {
        names.push("stl");
    }
    names
}

/// Estimated bytes of one frame, for `mss check` and the disk check: the
/// size estimate of every exporter `out` asks for (see
/// [`SeriesFacts::bytes`]; a registered exporter without facts counts
/// nothing), the point caches and the springs.
pub fn frame_size_estimate(out: &OutputSection, exporters: &Exporters, n: &FrameCounts) -> u64 {
    let mut total = 0;
    for name in frame_exporter_names(out) {
        if let Some(facts) = exporters.frame_facts(name) {
            total += (facts.bytes)(n.nodes, n.cells);
        }
    }
    for name in skin_exporter_names(out) {
        if let Some(facts) = exporters.skin_facts(name) {
            total += (facts.bytes)(n.skin_vertices, n.skin_triangles);
        }
    }
    if out.embedded
        && let Some(facts) = exporters.skin_facts(out.surface_exporter())
    {
        total += (facts.bytes)(n.surface_vertices, n.surface_triangles);
    }
    if out.pc2 {
        // One f32 triple per vertex per frame.
        total += 12 * n.skin_vertices as u64;
        if out.embedded {
            total += 12 * n.surface_vertices as u64;
        }
    }
    if out.springs {
        // Points, then per spring: 2 Int64 node ids, an offset, a type,
        // three Float64 fields and a flag; base64 adds a third.
        let springs = (n.nodes * 24 + n.springs * (16 + 8 + 1 + 3 * 8 + 1)) as u64;
        total += springs * 4 / 3;
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_files_are_recognised_by_name() {
        let builtin = RunFileNames::new(&Exporters::default());
        for yes in [
            "lattice_0000.vtu",
            "lattice_12345.vtk",
            "skin_0003.stl",
            "surface_0040.obj",
            "springs_0001.vtu",
            "lattice.pvd",
            "springs.pvd",
            "skin.pc2",
            "surface_rest.obj",
            "surface_0003.vtu",
            "surface.pvd",
            "summary.json",
            crate::checkpoint::CHECKPOINT_FILE,
        ] {
            assert!(builtin.matches(yes), "{yes}");
        }
        for no in [
            "lattice_01.vtu",
            "lattice_000a.vtu",
            "lattice_0000.obj",
            "notes.txt",
            "mesh.obj",
            "skin.obj",
            "lattice.vtu",
            "surface.vtu",
            "lattice_rest.obj",
            "lattice_0001.vtp",
        ] {
            assert!(!builtin.matches(no), "{no}");
        }
        // A program's exporter registered with its facts: its files are the
        // run's too.
        let mut exporters = Exporters::default();
        exporters.register_frames_with(
            "vtp",
            SeriesFacts {
                extension: "vtp",
                index_extension: None,
                bytes: |nodes, _| 24 * nodes as u64,
            },
            std::sync::Arc::new(|_, _| unreachable!()),
        );
        let names = RunFileNames::new(&exporters);
        assert!(names.matches("lattice_0001.vtp"));
        assert!(!names.matches("skin_0001.vtp"));
        assert_eq!(
            temporary_of(".lattice_0003.vtu.tmp-123-7"),
            Some(("lattice_0003.vtu", 123))
        );
        assert_eq!(temporary_of("lattice_0003.vtu"), None);
    }

    #[test]
    fn only_an_earlier_runs_files_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        // A pid that cannot be a running process.
        let dead = u32::MAX - 1;
        for name in [
            "lattice_0000.vtu".to_owned(),
            "lattice_0001.vtu".to_owned(),
            "lattice.pvd".to_owned(),
            "summary.json".to_owned(),
            format!(".lattice_0002.vtu.tmp-{dead}-0"),
            format!(".lattice_0002.vtu.tmp-{}-0", std::process::id()),
            "mesh.obj".to_owned(),
            "notes.txt".to_owned(),
        ] {
            std::fs::write(d.join(name), b"x").unwrap();
        }
        assert_eq!(remove_previous_run(d, &Exporters::default()).unwrap(), 5);
        let mut left: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        left.sort();
        assert_eq!(
            left,
            vec![
                format!(".lattice_0002.vtu.tmp-{}-0", std::process::id()),
                "mesh.obj".to_owned(),
                "notes.txt".to_owned()
            ]
        );
    }
}
