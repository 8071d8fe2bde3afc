//! The rigid-cell mode count (`mss_core::modes::zero_energy_modes_rigid_cells`)
//! against the eigenvalues of the assembled rest stiffness, and against the
//! mechanisms of linkages known by hand.

use hexmesh::Lattice;
use mss_core::model::{HourglassControl, PaperModel, SpringsOnly, Volumetric, VolumetricBarrier};
use mss_core::modes::{
    cells_are_rigid, zero_energy_modes, zero_energy_modes_dense, zero_energy_modes_rigid_cells,
};
use mss_core::{Material, Model, Parameterization};

fn hg(inner: Box<dyn Parameterization>, alpha: f64) -> HourglassControl {
    HourglassControl::new(inner, alpha).unwrap()
}

fn model(lattice: &Lattice, param: &dyn Parameterization) -> Model {
    Model::new(lattice, Material::new(1000.0, 0.3, 1.0).unwrap(), param).unwrap()
}

fn lattice(cells: &[[u32; 3]]) -> Lattice {
    Lattice::from_cells([0.0; 3], 0.1, [5, 5, 5], cells.iter().copied()).unwrap()
}

fn rigid_count(model: &Model, held: &[[bool; 3]]) -> usize {
    zero_energy_modes_rigid_cells(model, held).unwrap().count
}

/// xorshift64: deterministic test data without a dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

#[test]
fn only_hourglass_controlled_cells_are_rigid() {
    let l = Lattice::block([2, 1, 1], 0.1, [0.0; 3]).unwrap();
    assert!(cells_are_rigid(&model(
        &l,
        &hg(Box::new(VolumetricBarrier), 1.0)
    )));
    assert!(cells_are_rigid(&model(&l, &hg(Box::new(PaperModel), 0.05))));
    assert!(cells_are_rigid(&model(
        &l,
        &hg(Box::new(SpringsOnly), 0.05)
    )));
    // The M2 cell keeps three mechanisms of its own.
    for param in [
        &PaperModel as &dyn Parameterization,
        &SpringsOnly,
        &Volumetric,
        &VolumetricBarrier,
    ] {
        assert!(!cells_are_rigid(&model(&l, param)), "{}", param.name());
    }
}

#[test]
fn linkages_known_by_hand() {
    let param = hg(Box::new(VolumetricBarrier), 1.0);
    let free = |l: &Lattice| vec![[false; 3]; l.num_nodes()];
    // One body: the 6 rigid motions; a ball joint at a held node leaves the 3
    // rotations; two held nodes leave the rotation about their line.
    let block = Lattice::block([3, 2, 2], 0.1, [0.0; 3]).unwrap();
    let m = model(&block, &param);
    let mut held = free(&block);
    assert_eq!(rigid_count(&m, &held), 6);
    held[0] = [true; 3];
    assert_eq!(rigid_count(&m, &held), 3);
    let last = block.num_nodes() - 1;
    held[last] = [true; 3];
    assert_eq!(rigid_count(&m, &held), 1);
    // A third node off their line holds everything.
    let off = block.node_at([3, 0, 0]).unwrap() as usize;
    held[off] = [true; 3];
    assert_eq!(rigid_count(&m, &held), 0);
    // A roller (only z held) at three nodes of the base leaves the in-plane
    // motions: x, y translations and the rotation about z.
    let mut rollers = free(&block);
    for c in [[0, 0, 0], [3, 0, 0], [0, 2, 0]] {
        rollers[block.node_at(c).unwrap() as usize] = [false, false, true];
    }
    assert_eq!(rigid_count(&m, &rollers), 3);

    // Two cells sharing an edge: a hinge (7); sharing a vertex: a ball joint (9).
    let hinge = lattice(&[[0, 0, 0], [1, 1, 0]]);
    assert_eq!(rigid_count(&model(&hinge, &param), &free(&hinge)), 7);
    let ball = lattice(&[[0, 0, 0], [1, 1, 1]]);
    assert_eq!(rigid_count(&model(&ball, &param), &free(&ball)), 9);
    // A cell on top of an L of three cells, touching two of them along two
    // edges that meet at a node: held rigidly by the pair of edges.
    let corner = lattice(&[[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]]);
    let mc = model(&corner, &param);
    assert_eq!(
        rigid_count(&mc, &free(&corner)),
        zero_energy_modes_dense(&mc, &free(&corner)).unwrap().count
    );
    // A chain of three cells joined by edges at right angles: two hinges.
    let chain = lattice(&[[0, 0, 0], [1, 1, 0], [1, 2, 1]]);
    let mch = model(&chain, &param);
    assert_eq!(rigid_count(&mch, &free(&chain)), 8);
    assert_eq!(
        zero_energy_modes_dense(&mch, &free(&chain)).unwrap().count,
        8
    );
}

#[test]
fn agrees_with_the_eigenvalues_on_random_lattices_and_supports() {
    let mut rng = Rng(0x5DEE_CE66_D1CE_4E5B);
    let params: [HourglassControl; 2] = [
        hg(Box::new(VolumetricBarrier), 1.0),
        hg(Box::new(PaperModel), 0.05),
    ];
    let mut seen_mechanisms = 0;
    for trial in 0..120 {
        let dims = [4u32, 3, 3];
        let cells: Vec<[u32; 3]> = (0..dims[2])
            .flat_map(|z| (0..dims[1]).flat_map(move |y| (0..dims[0]).map(move |x| [x, y, z])))
            .filter(|_| rng.below(100) < 35)
            .collect();
        if cells.is_empty() {
            continue;
        }
        let l = Lattice::from_cells([0.0; 3], 0.05, dims, cells).unwrap();
        let mut held = vec![[false; 3]; l.num_nodes()];
        // From nothing held to a few nodes with random axes.
        for _ in 0..rng.below(5) {
            let n = rng.below(l.num_nodes() as u64) as usize;
            let axes = rng.below(7) + 1;
            held[n] = [axes & 1 != 0, axes & 2 != 0, axes & 4 != 0];
        }
        let param = &params[trial % 2];
        let m = model(&l, param);
        let dense = zero_energy_modes_dense(&m, &held).unwrap();
        let rigid = zero_energy_modes_rigid_cells(&m, &held).unwrap();
        assert_eq!(
            rigid.count,
            dense.count,
            "trial {trial}, {} cells, {}: dense smallest {:?}",
            l.num_cells(),
            param.name(),
            &dense.smallest_relative[..dense.smallest_relative.len().min(12)]
        );
        seen_mechanisms += usize::from(dense.count > 6);
    }
    // The random lattices do produce hinges and ball joints.
    assert!(seen_mechanisms > 10, "{seen_mechanisms}");
}

#[test]
fn large_lattices_are_counted_without_a_matrix() {
    // 48^3 cells, 117,649 nodes: beyond the dense method, and the subspace
    // method would factor the stiffness.
    let n = 48;
    let l = Lattice::block([n; 3], 1.0 / n as f64, [0.0; 3]).unwrap();
    let m = model(&l, &hg(Box::new(VolumetricBarrier), 1.0));
    let free = vec![[false; 3]; l.num_nodes()];
    let z = zero_energy_modes(&m, &free).unwrap();
    assert_eq!((z.count, z.exact, z.method), (6, true, "rigid cells"));
    let clamped: Vec<[bool; 3]> = l.node_coords().iter().map(|c| [c[2] == 0; 3]).collect();
    assert_eq!(zero_energy_modes(&m, &clamped).unwrap().count, 0);
    // Held along one edge of the base only: it turns about that edge.
    let edge: Vec<[bool; 3]> = l
        .node_coords()
        .iter()
        .map(|c| [c[2] == 0 && c[1] == 0; 3])
        .collect();
    assert_eq!(zero_energy_modes(&m, &edge).unwrap().count, 1);
}
