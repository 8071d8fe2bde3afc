//! Loads a mesh, voxelizes it and prints the statistics and phase timings:
//!
//! ```text
//! cargo run --release -p hexmesh --example voxelize_stats -- MESH [CELLS_ALONG_LONGEST_AXIS]
//! ```

use std::time::Instant;

use hexmesh::{Resolution, VoxelizeOptions, load_mesh, voxelize};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: voxelize_stats MESH [CELLS]")?;
    let n: u32 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(64);
    let t = Instant::now();
    let loaded = load_mesh(path.as_ref())?;
    let ms_load = t.elapsed().as_secs_f64() * 1e3;
    let opts = VoxelizeOptions {
        resolution: Resolution::CellsAlongLongestAxis(n),
        max_cells: 200_000_000,
        ..Default::default()
    };
    let t = Instant::now();
    let v = voxelize(&loaded.mesh, &opts)?;
    let ms_vox = t.elapsed().as_secs_f64() * 1e3;
    println!("load {ms_load:.1} ms, voxelize {ms_vox:.1} ms");
    println!("{:#?}", loaded.report);
    println!("{:#?}", v.stats);
    Ok(())
}
