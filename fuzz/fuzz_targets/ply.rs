//! The PLY loader must return Ok or a typed error for any bytes, never
//! panic, abort or allocate without bound.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let format = hexmesh::load::MeshFormat::Ply;
    if let Ok(m) = hexmesh::load::load_mesh_bytes(data, format, "fuzz.ply") {
        let n = m.mesh.vertices.len() as u32;
        assert!(m.mesh.triangles.iter().flatten().all(|&i| i < n));
        assert!(m.mesh.vertices.iter().flatten().all(|v| v.is_finite()));
    }
});
