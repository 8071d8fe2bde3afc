//! The OBJ loader must return Ok or a typed error for any bytes, never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = hexmesh::load::load_mesh_bytes(data, hexmesh::load::MeshFormat::Obj, "fuzz.obj")
    {
        // A loaded mesh is usable: every index is in range, every coordinate finite.
        let n = m.mesh.vertices.len() as u32;
        assert!(m.mesh.triangles.iter().flatten().all(|&i| i < n));
        assert!(m.mesh.vertices.iter().flatten().all(|v| v.is_finite()));
    }
});
