//! Writes the default mesh `data/meshes/critter.obj` (workspace root) from
//! [`hexmesh::generate::critter`]:
//!
//! ```text
//! cargo run --release -p hexmesh --example generate_default_mesh
//! ```

use std::path::PathBuf;

fn main() -> std::io::Result<()> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/meshes");
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("critter.obj");
    // Write to a temporary file first so a failed run never leaves half a mesh.
    let tmp = dir.join("critter.obj.tmp");
    std::fs::write(&tmp, hexmesh::generate::critter_obj())?;
    std::fs::rename(&tmp, &path)?;
    println!("wrote {}", path.display());
    Ok(())
}
