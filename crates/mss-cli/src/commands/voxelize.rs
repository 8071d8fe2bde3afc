//! `mss voxelize`: voxelizes a surface mesh, or resamples a label image,
//! and writes the lattice, its boundary skin, the embedded surface,
//! `stats.json` and, with `--springs`, the springs as lines.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use mss_scene::hexmesh::{Units, UpAxis};
use mss_scene::mss_io::vtk::{Field, LatticeFrame, VtuEncoding, write_lines_vtu, write_vtu};
use mss_scene::scene::{ComponentPolicy, MeshSource, VoxelizeSection, value_from_str};
use mss_scene::{Progress, Registry, stages};
use serde::Serialize;

use crate::GlobalArgs;
use crate::progress::JobBars;

/// Arguments of `mss voxelize`.
#[derive(Debug, Clone, Args)]
pub struct VoxelizeArgs {
    /// Surface mesh (OBJ, STL, PLY, VTK .vtk/.vtu/.vtp), "builtin:critter",
    /// or a label image (NIfTI .nii/.nii.gz/.hdr, NRRD .nrrd/.nhdr).
    #[arg(value_name = "MESH")]
    pub mesh: String,
    /// For an image: the labels that form the body, comma-separated
    /// [default: every non-zero label].
    #[arg(
        long,
        value_name = "L,L,...",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    pub labels: Option<Vec<i32>>,
    /// Cells along the longest axis of the mesh's bounding box [default: 24].
    #[arg(long, value_name = "N", conflicts_with = "size")]
    pub cells: Option<u32>,
    /// Cell edge in metres (instead of --cells).
    #[arg(long, value_name = "H", allow_negative_numbers = true)]
    pub size: Option<f64>,
    /// Occupancy rule: centre (cell centre inside), any (cell overlaps the
    /// solid), fraction (at least --fraction of the cell inside).
    #[arg(long, value_name = "RULE", default_value = "centre")]
    pub rule: String,
    /// Minimum inside fraction for --rule fraction; for an image, the
    /// fraction of a cell the labels must cover.
    #[arg(long, value_name = "F", default_value_t = 0.5)]
    pub fraction: f64,
    /// Keep every connected component (default: only the largest).
    #[arg(long)]
    pub all_components: bool,
    /// Refuse lattices with more cells than this.
    #[arg(long, value_name = "N", default_value_t = VoxelizeSection::default().max_cells)]
    pub max_cells: u64,
    /// Unit of the mesh's coordinates: m, cm or mm (as `[mesh] units`)
    /// [default: m; for an image, the unit its header names, else mm].
    #[arg(long, value_name = "UNIT", value_parser = value_from_str::<Units>)]
    pub units: Option<Units>,
    /// Scale factor after units (as `[mesh] scale`).
    #[arg(long, value_name = "S", default_value_t = 1.0)]
    pub scale: f64,
    /// The mesh's up axis, turned to +z: x, y or z (as `[mesh] up`).
    #[arg(long, value_name = "AXIS", default_value = "z", value_parser = value_from_str::<UpAxis>)]
    pub up: UpAxis,
    /// How the .vtu files store their arrays: zlib (compressed, about 4 times
    /// smaller) or none (uncompressed: no compression work, larger files).
    #[arg(long, value_name = "KIND", default_value = "zlib", value_parser = ["zlib", "none"])]
    pub compression: String,
    /// Also write the springs as lines: springs.vtu (rest_length, diagonal).
    // No strain or stiffness here: those need a material and a deformed
    // state; a scene's `[output] springs` writes them per frame.
    #[arg(long)]
    pub springs: bool,
}

impl VoxelizeArgs {
    /// How the `.vtu` files store their arrays (`--compression`).
    fn encoding(&self) -> VtuEncoding {
        if self.compression == "none" {
            VtuEncoding::Base64
        } else {
            VtuEncoding::Base64Zlib
        }
    }

    /// The files written besides `stats.json`.
    fn files(&self) -> Vec<String> {
        ["lattice.vtu", "skin.obj", "surface.obj"]
            .into_iter()
            .chain(self.springs.then_some("springs.vtu"))
            .map(str::to_owned)
            .collect()
    }
}

/// The folder `mss voxelize MESH` writes into without `--out`: the mesh's
/// file stem and `_lattice`, in the working folder (`bunny.obj` ->
/// `bunny_lattice`, `builtin:critter` -> `critter_lattice`).
pub fn default_folder(mesh: &str) -> String {
    let name = mesh
        .strip_prefix(mss_scene::scene::BUILTIN_PREFIX)
        .unwrap_or(mesh);
    // `seg.nii.gz` -> `seg`: the extensions an image file name stacks.
    let name = name.strip_suffix(".gz").unwrap_or(name);
    let stem = Path::new(name)
        .file_stem()
        .and_then(|s| s.to_str())
        .filter(|s| !s.is_empty())
        .unwrap_or("mesh");
    format!("{stem}_lattice")
}

/// What `mss voxelize` measured (printed, and written as `stats.json`).
#[derive(Debug, Clone, Serialize)]
pub struct VoxelizeSummary {
    /// Mesh name.
    pub mesh: String,
    /// Mesh vertices.
    pub mesh_vertices: usize,
    /// Mesh triangles.
    pub mesh_triangles: usize,
    /// Cells.
    pub cells: usize,
    /// Nodes.
    pub nodes: usize,
    /// Springs of the paper's lattice: unique cell edges plus 4 body diagonals per cell.
    pub springs: usize,
    /// Cell edge (m).
    pub cell_size: f64,
    /// Grid dimensions (cells).
    pub grid: [u32; 3],
    /// Connected components kept.
    pub components_kept: usize,
    /// Connected components dropped.
    pub components_dropped: usize,
    /// Lattice volume (m^3).
    pub lattice_volume: f64,
    /// Volume enclosed by the mesh (m^3).
    pub mesh_volume: f64,
    /// Seconds to load the mesh.
    pub load_seconds: f64,
    /// Seconds to voxelize.
    pub voxelize_seconds: f64,
    /// Seconds to write the files.
    pub write_seconds: f64,
    /// Output folder.
    pub output_folder: String,
    /// Files written (besides `stats.json`).
    pub files: Vec<String>,
    /// For an image: its voxels along each axis, their spacing (m), and
    /// each chosen label with its number of voxels.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub image: Option<ImageSummary>,
}

/// What `mss voxelize` read from a label image.
#[derive(Debug, Clone, Serialize)]
pub struct ImageSummary {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// Voxel spacing along i, j, k (m).
    pub spacing: [f64; 3],
    /// The labels forming the body, each with its voxels.
    pub voxels_per_label: Vec<(i32, usize)>,
    /// Lattice cells per label (the label covering most of each cell).
    pub cells_per_label: Vec<(i32, usize)>,
}

/// Runs `mss voxelize`.
pub fn run(args: &VoxelizeArgs, global: &GlobalArgs) -> anyhow::Result<()> {
    // Its own folder, named after the mesh, rather than ./out among a run's
    // frames.
    let out_dir = global
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(default_folder(&args.mesh)));
    // The same table a scene's [voxelize] is, so both mean the same.
    let section = VoxelizeSection {
        cells: args.cells,
        cell_size: args.size,
        cell_sides: None,
        cells_per_axis: None,
        rule: args.rule.clone(),
        fraction: args.fraction,
        components: if args.all_components {
            ComponentPolicy::All
        } else {
            ComponentPolicy::LargestOnly
        },
        max_cells: args.max_cells,
    };
    let mut registry = Registry::default();
    global.limits().bound_loaders(&mut registry.loaders);
    let options = section
        .check()
        .and_then(|()| section.options(&registry.occupancy))
        .map_err(|e| {
            let flag = match e.key.as_str() {
                "cell_size" => "size",
                "max_cells" => "max-cells",
                other => other,
            };
            let value = match flag {
                "rule" => args.rule.clone(),
                "cells" => format!("{}", args.cells.unwrap_or_default()),
                "size" => format!("{}", args.size.unwrap_or_default()),
                "fraction" => format!("{}", args.fraction),
                _ => format!("{}", args.max_cells),
            };
            // The table's message starts with "= VALUE; ": the flag prints it.
            let reason = e
                .message
                .split_once("; ")
                .map_or(e.message.as_str(), |(_, r)| r);
            anyhow::anyhow!("--{flag} {value}: {reason}")
        })?;
    if mss_scene::hexmesh::image::ImageFormat::from_path(Path::new(&args.mesh)).is_some() {
        return run_image(args, global, &options, &out_dir);
    }
    if args.labels.is_some() {
        anyhow::bail!(
            "--labels: {} is a surface mesh; labels choose the body in a label image (.nii, .nii.gz, .nrrd, .nhdr)",
            args.mesh
        );
    }
    let source = match args.mesh.strip_prefix(mss_scene::scene::BUILTIN_PREFIX) {
        Some(name) => MeshSource::Builtin(name.to_owned()),
        None => MeshSource::File(PathBuf::from(&args.mesh)),
    };
    let placement = mss_scene::hexmesh::Placement {
        units: args.units.unwrap_or_default(),
        scale: [args.scale; 3],
        up: args.up,
        ..mss_scene::hexmesh::Placement::default()
    };
    mss_scene::build::prepare_output_folder(&out_dir)?;
    let t0 = Instant::now();
    let placed = stages::load_placed(&source, &placement, &registry.loaders)
        .context("cannot load the mesh (--units, --scale, --up)")?;
    let load_seconds = t0.elapsed().as_secs_f64();
    if let Some(odd) = stages::implausible_size(&placed.mesh) {
        log::warn!("{}: {odd} (--units mm or cm, or --scale)", placed.name);
    }
    let t1 = Instant::now();
    let bars = JobBars::new(&placed.name, global.chatty());
    let hook = |done: u64, total: u64| bars.report(Progress::Voxelizing { done, total });
    // The lattice within the memory limit an explicit run of it needs.
    let vox = stages::lattice_within(
        &placed.mesh,
        &placed.name,
        &options,
        &global.limits(),
        stages::RunNeeds::EXPLICIT,
        &hook,
    );
    bars.clear();
    let vox = vox?;
    let voxelize_seconds = t1.elapsed().as_secs_f64();
    let mesh_name = placed.name.clone();
    let loaded = placed;
    let t2 = Instant::now();
    let lattice = &vox.lattice;
    let encoding = args.encoding();
    write_outputs(
        &out_dir,
        lattice,
        &loaded.mesh,
        None,
        args.springs,
        encoding,
    )?;
    let summary = VoxelizeSummary {
        mesh: mesh_name,
        mesh_vertices: loaded.mesh.vertices.len(),
        mesh_triangles: loaded.mesh.triangles.len(),
        cells: lattice.num_cells(),
        nodes: lattice.num_nodes(),
        springs: lattice.num_unique_edges() + 4 * lattice.num_cells(),
        cell_size: lattice.h(),
        grid: lattice.dims(),
        components_kept: vox.stats.components_kept,
        components_dropped: vox.stats.components_dropped,
        lattice_volume: lattice.volume(),
        mesh_volume: loaded.mesh.signed_volume().abs(),
        load_seconds,
        voxelize_seconds,
        write_seconds: t2.elapsed().as_secs_f64(),
        output_folder: out_dir.display().to_string(),
        files: args.files(),
        image: None,
    };
    finish(&summary, &out_dir, global)
}

/// Writes `stats.json` and prints the summary.
fn finish(summary: &VoxelizeSummary, out_dir: &Path, global: &GlobalArgs) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(summary).context("cannot encode the statistics")?;
    mss_scene::mss_io::atomic::write_atomic(&out_dir.join("stats.json"), |w| {
        w.write_all(json.as_bytes())?;
        w.write_all(b"\n")
    })?;
    if global.chatty() {
        print_summary(summary)?;
    }
    Ok(())
}

/// `mss voxelize IMAGE`: the chosen labels resampled to cubes.
fn run_image(
    args: &VoxelizeArgs,
    global: &GlobalArgs,
    options: &mss_scene::hexmesh::VoxelizeOptions,
    out_dir: &Path,
) -> anyhow::Result<()> {
    if args.rule != "centre" {
        anyhow::bail!(
            "--rule {}: an image's cells are kept by the fraction the labels cover (--fraction), not by a rule",
            args.rule
        );
    }
    if args.scale != 1.0 || args.up != UpAxis::Z {
        anyhow::bail!(
            "--scale and --up place surface meshes; an image is placed by its own transform (and --units)"
        );
    }
    mss_scene::build::prepare_output_folder(out_dir)?;
    let t0 = Instant::now();
    let choice = stages::ImageChoice {
        labels: args.labels.as_deref(),
        threshold: args.fraction,
        unit_metres: args.units.map(Units::factor),
        space: None,
        placement: mss_scene::hexmesh::Placement::default(),
    };
    let placed = stages::image_lattice_within(
        Path::new(&args.mesh),
        &choice,
        options,
        &global.limits(),
        stages::RunNeeds::EXPLICIT,
    )?;
    let voxelize_seconds = t0.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let encoding = args.encoding();
    let image = &placed.lattice;
    let lattice = &image.lattice;
    write_outputs(
        out_dir,
        lattice,
        &image.surface,
        Some(&image.cell_labels),
        args.springs,
        encoding,
    )?;
    let mut cells_per_label = std::collections::BTreeMap::new();
    for &l in &image.cell_labels {
        *cells_per_label.entry(l).or_insert(0usize) += 1;
    }
    let summary = VoxelizeSummary {
        mesh: placed.name.clone(),
        mesh_vertices: image.surface.vertices.len(),
        mesh_triangles: image.surface.triangles.len(),
        cells: lattice.num_cells(),
        nodes: lattice.num_nodes(),
        springs: lattice.num_unique_edges() + 4 * lattice.num_cells(),
        cell_size: lattice.h(),
        grid: lattice.dims(),
        components_kept: image.stats.components_kept,
        components_dropped: image.stats.components_dropped,
        lattice_volume: lattice.volume(),
        mesh_volume: image.stats.mesh_volume,
        load_seconds: 0.0,
        voxelize_seconds,
        write_seconds: t2.elapsed().as_secs_f64(),
        output_folder: out_dir.display().to_string(),
        files: args.files(),
        image: Some(ImageSummary {
            dims: placed.dims,
            spacing: placed.spacing,
            voxels_per_label: image.voxels_per_label.clone(),
            cells_per_label: cells_per_label.into_iter().collect(),
        }),
    };
    finish(&summary, out_dir, global)
}

fn write_outputs(
    dir: &Path,
    lattice: &mss_scene::hexmesh::Lattice,
    mesh: &mss_scene::hexmesh::TriMesh,
    cell_labels: Option<&[i32]>,
    springs: bool,
    encoding: VtuEncoding,
) -> anyhow::Result<()> {
    let coords: Vec<f64> = lattice.cell_coords().iter().map(|c| c[2] as f64).collect();
    let mut frame = LatticeFrame::new(lattice.nodes(), lattice.cells())
        .with_cell_field(Field::scalars("layer", &coords));
    if let Some(labels) = cell_labels {
        frame = frame.with_cell_field(Field::labels("label", labels));
    }
    write_vtu(&dir.join("lattice.vtu"), &frame, encoding)?;
    let skin = mss_scene::hexmesh::boundary_skin(lattice);
    let skin_pos = skin.positions(lattice.nodes());
    mss_scene::mss_io::skin::write_obj(&dir.join("skin.obj"), &skin_pos, &skin.triangles)?;
    let embedding = mss_scene::hexmesh::Embedding::new(lattice, mesh);
    let surface = embedding.deform(lattice.nodes());
    mss_scene::mss_io::skin::write_obj(&dir.join("surface.obj"), &surface, &mesh.triangles)?;
    if springs {
        let topology = mss_scene::hexmesh::SpringTopology::new(lattice.cells());
        let rest_length = topology
            .lengths(lattice.nodes())
            .context("the lattice's springs refer to missing nodes")?;
        write_lines_vtu(
            &dir.join("springs.vtu"),
            lattice.nodes(),
            &topology.nodes,
            &[
                Field::scalars("rest_length", &rest_length),
                Field::flags("diagonal", &topology.diagonal),
            ],
            encoding,
        )?;
    }
    Ok(())
}

fn print_summary(s: &VoxelizeSummary) -> Result<(), crate::StdoutError> {
    crate::outln!(
        "mesh         {}: {} vertices, {} triangles, volume {:.4e} m^3",
        s.mesh,
        s.mesh_vertices,
        s.mesh_triangles,
        s.mesh_volume
    );
    crate::outln!(
        "lattice      {} cells, {} nodes, {} springs, cell size {}, grid {:?}",
        s.cells,
        s.nodes,
        s.springs,
        crate::progress::human_length(s.cell_size),
        s.grid
    );
    let of = if s.image.is_some() {
        "the labelled voxels"
    } else {
        "the mesh"
    };
    crate::outln!(
        "volume       {:.4e} m^3 ({:+.1}% of {of})",
        s.lattice_volume,
        100.0 * (s.lattice_volume / s.mesh_volume - 1.0)
    );
    if let Some(image) = &s.image {
        crate::outln!(
            "image        {:?} voxels of {} x {} x {}; voxels per label {:?}; cells per label {:?}",
            image.dims,
            crate::progress::human_length(image.spacing[0]),
            crate::progress::human_length(image.spacing[1]),
            crate::progress::human_length(image.spacing[2]),
            image.voxels_per_label,
            image.cells_per_label
        );
    }
    crate::outln!(
        "components   {} kept, {} dropped",
        s.components_kept,
        s.components_dropped
    );
    crate::outln!(
        "timings      load {:.3} s, voxelize {:.3} s, write {:.3} s",
        s.load_seconds,
        s.voxelize_seconds,
        s.write_seconds
    );
    crate::outln!(
        "output       {}: {}, stats.json",
        s.output_folder,
        s.files.join(", ")
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::default_folder;

    #[test]
    fn the_default_folder_is_named_after_the_mesh() {
        assert_eq!(default_folder("data/meshes/bunny.obj"), "bunny_lattice");
        assert_eq!(default_folder("builtin:critter"), "critter_lattice");
        assert_eq!(default_folder("scan.vtu"), "scan_lattice");
        assert_eq!(default_folder("/"), "mesh_lattice");
        assert_eq!(default_folder("scans/seg.nii.gz"), "seg_lattice");
        assert_eq!(default_folder("seg.nrrd"), "seg_lattice");
    }
}
