//! Slower model checks: the finest docs/model.md cantilever, mechanism detection on
//! a 10^5-node model, and the negative-Poisson range of the volumetric variant.

use hexmesh::Lattice;
use mss_core::model::{PaperModel, Volumetric};
use mss_core::modes::{zero_energy_modes, zero_energy_modes_dense};
use mss_core::{Material, Model, Vec3};

#[test]
fn cantilever_64x16x16() {
    let k = 16;
    let l = Lattice::block([4 * k, k, k], 0.1 / k as f64, [0.0; 3]).unwrap();
    let model = Model::new(&l, Material::new(1000.0, 0.0, 0.01).unwrap(), &PaperModel).unwrap();
    let fixed: Vec<bool> = l.node_coords().iter().map(|c| c[0] == 0).collect();
    let f: Vec<Vec3> = model
        .masses()
        .iter()
        .map(|&m| Vec3::new(0.0, 0.0, -9.81 * m))
        .collect();
    let t = std::time::Instant::now();
    let u = model.rest_stiffness().solve_symmetric(&f, &fixed).unwrap();
    eprintln!("64x16x16 solve: {:.2} s", t.elapsed().as_secs_f64());
    let tip: Vec<f64> = (0..u.len())
        .filter(|&i| l.node_coords()[i][0] == 4 * k)
        .map(|i| u[i].z)
        .collect();
    let d = -tip.iter().sum::<f64>() / tip.len() as f64;
    assert!((d / 3.9459e-4 - 1.0).abs() < 1e-3, "{d}");
}

#[test]
fn mechanisms_of_a_large_model() {
    let n = 20; // 21^3 = 9261 nodes
    let l = Lattice::block([n; 3], 1.0 / n as f64, [0.0; 3]).unwrap();
    let model = Model::new(&l, Material::new(1000.0, 0.3, 1.0).unwrap(), &PaperModel).unwrap();
    let bytes = model
        .rest_stiffness()
        .cholesky_factor_bytes(&vec![[false; 3]; l.num_nodes()]);
    eprintln!("factor bytes {bytes:?}");
    let t = std::time::Instant::now();
    let free = zero_energy_modes(&model, &vec![[false; 3]; l.num_nodes()]).unwrap();
    eprintln!(
        "free block {} nodes: {free:?} in {:.2} s",
        l.num_nodes(),
        t.elapsed().as_secs_f64()
    );
    assert_eq!((free.count, free.exact), (9, true));
    let t = std::time::Instant::now();
    let clamped: Vec<[bool; 3]> = l.node_coords().iter().map(|c| [c[2] == 0; 3]).collect();
    let c = zero_energy_modes(&model, &clamped).unwrap();
    eprintln!("clamped: {c:?} in {:.2} s", t.elapsed().as_secs_f64());
    assert_eq!(c.count, 0);
    let mut two = vec![[false; 3]; l.num_nodes()];
    two[0] = [true; 3];
    two[l.num_nodes() - 1] = [true; 3];
    assert!(zero_energy_modes(&model, &two).unwrap().has_mechanisms());
}

#[test]
fn volumetric_negative_poisson_range() {
    let l = Lattice::block([3, 3, 2], 0.1, [0.0; 3]).unwrap();
    for nu in [-0.2, -0.3, -0.5, -0.7, -0.9, -0.99] {
        let m = Material::with_poisson_range(100.0, nu, 1.0, -1.0, 0.5).unwrap();
        let model = Model::new(&l, m, &Volumetric).unwrap();
        let free = zero_energy_modes_dense(&model, &vec![[false; 3]; l.num_nodes()]).unwrap();
        let clamped: Vec<[bool; 3]> = l.node_coords().iter().map(|c| [c[2] == 0; 3]).collect();
        let c = zero_energy_modes_dense(&model, &clamped).unwrap();
        assert_eq!(free.count, 9, "nu {nu}");
        assert!(c.smallest_relative[0] > 1e-3, "nu {nu}: {c:?}");
        eprintln!(
            "nu {nu}: free zero modes {} smallest {:?}; clamped smallest {:.3e}",
            free.count,
            &free.smallest_relative[..11],
            c.smallest_relative[0]
        );
    }
}
