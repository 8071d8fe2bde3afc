//! Facts of the model (docs/model.md): stiffnesses, assembly, masses, uniaxial
//! tension, cantilever, Jacobian, energy, determinism, time step.

use hexmesh::Lattice;
use mss_core::model::{HourglassControl, PaperModel, SpringsOnly, Volumetric, VolumetricBarrier};
use mss_core::{
    BlockCsr, CellCoefficients, ForceOperations, Material, MaterialError, Model, Parameterization,
    Precision, Vec3,
};

/// Deterministic pseudo-random numbers in [-1, 1) (xorshift).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

fn mat(e: f64, nu: f64, rho: f64) -> Material {
    Material::with_poisson_range(e, nu, rho, -1.0, 0.5).unwrap()
}

/// A strongly deformed state: stretch, shear and random jitter of 0.15 h.
fn deformed(model: &Model, seed: u64) -> Vec<Vec3> {
    let mut rng = Rng(seed);
    let h = model.h();
    model
        .rest_positions()
        .iter()
        .map(|p| {
            let q = Vec3::new(1.3 * p.x + 0.2 * p.z, 0.8 * p.y, 1.1 * p.z - 0.1 * p.x);
            q + Vec3::new(rng.next(), rng.next(), rng.next()) * (0.15 * h)
        })
        .collect()
}

fn forces(model: &Model, x: &[Vec3]) -> Vec<Vec3> {
    let mut f = vec![Vec3::zeros(); x.len()];
    model.internal_forces(x, &mut f);
    f
}

/// Whether two force fields are equal bit for bit.
fn same_bits(a: &[Vec3], b: &[Vec3]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(p, q)| (0..3).all(|d| p[d].to_bits() == q[d].to_bits()))
}

/// A parameterization with hourglass control (strong, so that its terms show).
fn with_hourglass(inner: Box<dyn Parameterization>) -> HourglassControl {
    HourglassControl::new(inner, 1.0).unwrap()
}

fn max_abs_block(m: &BlockCsr) -> f64 {
    m.blocks.iter().map(|b| b.abs().max()).fold(0.0, f64::max)
}

#[test]
fn single_cube_stiffnesses() {
    let l = Lattice::block([1, 1, 1], 0.5, [0.0; 3]).unwrap();
    let m = Material::new(1000.0, 0.3, 2.0).unwrap();
    let model = Model::new(&l, m, &PaperModel).unwrap();
    let c = model.cell_coefficients(0);
    assert!((c.k_edge - 1000.0 * 0.5 * 2.2 / (8.0 * 1.3)).abs() < 1e-12);
    assert!((c.k_diag - 3.0 * 1000.0 * 0.5 / (8.0 * 1.3)).abs() < 1e-12);
    assert!((c.correction.unwrap() - 0.1).abs() < 1e-15);
    assert_eq!(model.num_springs(), 16);
    let v = Volumetric.coefficients(&m, 0.5);
    assert!((v.k_edge - 1000.0 * 0.5 / (8.0 * 1.3)).abs() < 1e-12);
    assert_eq!(v.k_diag, c.k_diag);
    assert_eq!(v.correction, Some(-0.5));
    assert!((v.volumetric_lambda - m.lambda()).abs() < 1e-12);
    // Springs only, rest tangent: an edge neighbour block is k_edge along the edge,
    // the diagonal neighbour block is k_diag e e^T.
    let s = Model::new(&l, m, &SpringsOnly).unwrap();
    let t = s.tangent(s.rest_positions());
    let cell = s.cells()[0];
    let b = t.blocks[t.find(cell[0] as usize, cell[4] as usize).unwrap()];
    assert!((b[(2, 2)] - c.k_edge).abs() < 1e-12 && b[(0, 0)].abs() < 1e-12);
    let b = t.blocks[t.find(cell[0] as usize, cell[6] as usize).unwrap()];
    assert!((b[(0, 1)] - c.k_diag / 3.0).abs() < 1e-12);
    // Face-diagonal neighbours have no spring.
    let b = t.blocks[t.find(cell[0] as usize, cell[2] as usize).unwrap()];
    assert!(b.abs().max() < 1e-12);
}

#[test]
fn per_cell_assembly_and_masses() {
    let l = Lattice::block([2, 2, 2], 0.25, [1.0, 0.0, 0.0]).unwrap();
    let m = Material::new(10.0, 0.25, 3.0).unwrap();
    let model = Model::new(&l, m, &PaperModel).unwrap();
    // 2x2x2 block: 3*3*3 * 2 edges... count: x-edges 2*3*3 per axis, times 3 axes.
    assert_eq!(model.num_springs(), 3 * 18 + 4 * 8);
    assert!((model.total_mass() - 3.0 * l.volume()).abs() < 1e-14);
    let centre = l.node_at([1, 1, 1]).unwrap() as usize;
    assert!((model.masses()[centre] - 8.0 * 3.0 * 0.25f64.powi(3) / 8.0).abs() < 1e-15);
    let corner = l.node_at([0, 0, 0]).unwrap() as usize;
    assert!((model.masses()[corner] - 3.0 * 0.25f64.powi(3) / 8.0).abs() < 1e-15);
    // The inner edge (1,1,0)-(1,1,1) is shared by 4 cells: stiffness 4 k_x (nu = 0.25:
    // no corrections).
    let below = l.node_at([1, 1, 0]).unwrap() as usize;
    let t = model.tangent(model.rest_positions());
    let b = t.blocks[t.find(below, centre).unwrap()];
    let kx = model.cell_coefficients(0).k_edge;
    assert!((b[(2, 2)] - 4.0 * kx).abs() < 1e-12 * kx, "{b}");
    // An outer edge of the block's side face is shared by 2 cells.
    let a = l.node_at([0, 0, 1]).unwrap() as usize;
    let b = t.blocks[t.find(corner, a).unwrap()];
    assert!((b[(2, 2)] - kx).abs() < 1e-12 * kx);
    let a = l.node_at([1, 0, 1]).unwrap() as usize;
    let b = t.blocks[t.find(l.node_at([1, 0, 0]).unwrap() as usize, a).unwrap()];
    assert!((b[(2, 2)] - 2.0 * kx).abs() < 1e-12 * kx);
}

/// Measured (E, nu) of an n^3 unit block in uniaxial tension (docs/model.md).
fn tension(param: &dyn Parameterization, nu: f64, n: u32) -> (f64, f64) {
    let l = Lattice::block([n, n, n], 1.0 / n as f64, [0.0; 3]).unwrap();
    let model = Model::new(&l, mat(1.0, nu, 1.0), param).unwrap();
    let k = model.rest_stiffness();
    let coords = l.node_coords();
    let fixed: Vec<[bool; 3]> = coords
        .iter()
        .map(|c| [c[0] == 0, c[1] == 0, c[2] == 0])
        .collect();
    let h = l.h();
    let mut f = vec![Vec3::zeros(); l.num_nodes()];
    for face in l.boundary_faces().iter().filter(|f| f.face == 5) {
        for &v in &face.nodes {
            f[v as usize].z += h * h / 4.0;
        }
    }
    let u = k.solve_dofs(&f, &fixed).unwrap();
    let mean = |sel: &dyn Fn(&[u32; 3]) -> bool, d: usize| {
        let v: Vec<f64> = (0..u.len())
            .filter(|&i| sel(&coords[i]))
            .map(|i| u[i][d])
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    let ezz = mean(&|c| c[2] == n, 2);
    let exx = mean(&|c| c[0] == n, 0);
    (1.0 / ezz, -exx / ezz)
}

#[test]
fn uniaxial_tension_gives_e_and_nu() {
    // Hourglass control acts only on the mechanisms, never on a homogeneous
    // strain: the tension results stay exact with it.
    let paper_hg = with_hourglass(Box::new(PaperModel));
    let volumetric_hg = with_hourglass(Box::new(Volumetric));
    for param in [
        &PaperModel as &dyn Parameterization,
        &Volumetric,
        &paper_hg,
        &volumetric_hg,
    ] {
        for nu in [-0.2, 0.0, 0.25, 0.3, 0.45, 0.49] {
            for n in [1, 2, 4, 8] {
                let (e, nm) = tension(param, nu, n);
                assert!(
                    (e - 1.0).abs() < 1e-8 && (nm - nu).abs() < 1e-8,
                    "{} nu {nu} n {n}: E {e} nu {nm}",
                    param.name()
                );
            }
        }
    }
}

#[test]
fn volumetric_is_exact_for_strongly_negative_nu() {
    // The volumetric variant accepts -1 < nu < 0.5 (its springs and corrections
    // do not depend on lambda); model_slow.rs checks the rest stiffness stays
    // positive definite down to nu = -0.99.
    for nu in [-0.5, -0.9] {
        for n in [1, 2, 4] {
            let (e, nm) = tension(&Volumetric, nu, n);
            assert!(
                (e - 1.0).abs() < 1e-8 && (nm - nu).abs() < 1e-8,
                "nu {nu} n {n}: {e} {nm}"
            );
        }
    }
    let bad = Material {
        young: 1.0,
        poisson: -1.0,
        density: 1.0,
    };
    let l = Lattice::block([1, 1, 1], 1.0, [0.0; 3]).unwrap();
    assert!(Model::new(&l, bad, &Volumetric).is_err());
}

#[test]
fn springs_only_measures_classic_nu() {
    for nu in [0.0, 0.25, 0.3, 0.45] {
        for n in [1, 4] {
            let (_, nm) = tension(&SpringsOnly, nu, n);
            let expect = 1.0 / (4.0 * nu + 3.0);
            assert!(
                (nm - expect).abs() < 1e-8,
                "nu {nu} n {n}: {nm} vs {expect}"
            );
        }
    }
}

#[test]
fn corrections_vanish_at_quarter() {
    let l = Lattice::block([3, 2, 2], 0.1, [0.0; 3]).unwrap();
    let m = Material::new(50.0, 0.25, 1.0).unwrap();
    let p = Model::new(&l, m, &PaperModel).unwrap();
    let s = Model::new(&l, m, &SpringsOnly).unwrap();
    let x = deformed(&p, 7);
    let (fp, fs) = (forces(&p, &x), forces(&s, &x));
    let scale = fs.iter().map(|f| f.amax()).fold(0.0, f64::max);
    for (a, b) in fp.iter().zip(&fs) {
        assert!((a - b).amax() < 1e-13 * scale);
    }
    // And they do not vanish otherwise.
    let p3 = Model::new(&l, Material::new(50.0, 0.3, 1.0).unwrap(), &PaperModel).unwrap();
    let d = p3.cell_diagnostics(&x);
    assert!(d.iter().all(|c| c.correction_force > 0.0));
    assert!(
        p.cell_diagnostics(&x)
            .iter()
            .all(|c| c.correction_force < 1e-12 * scale)
    );
}

#[test]
fn each_cell_measure_is_that_of_the_cells_diagnostics() {
    use mss_core::CellMeasure;
    let l = Lattice::block([3, 2, 2], 0.1, [0.0; 3]).unwrap();
    let m = Model::new(&l, Material::new(50.0, 0.3, 1.0).unwrap(), &PaperModel).unwrap();
    let x = deformed(&m, 11);
    let d = m.cell_diagnostics(&x);
    assert!(
        d.iter()
            .all(|c| c.correction_force > 0.0 && c.shear_strain > 0.0)
    );
    let mut out = vec![f64::NAN; 2];
    for measure in [
        CellMeasure::VolumetricStrain,
        CellMeasure::ShearStrain,
        CellMeasure::CorrectionForce,
    ] {
        let of = |c: &mss_core::CellDiagnostics| match measure {
            CellMeasure::VolumetricStrain => c.volumetric_strain,
            CellMeasure::ShearStrain => c.shear_strain,
            CellMeasure::CorrectionForce => c.correction_force,
        };
        for range in [0..d.len(), 3..7, 5..5] {
            m.cell_measure_of(&x, range.clone(), measure, &mut out);
            let expected: Vec<f64> = d[range].iter().map(of).collect();
            assert_eq!(out, expected, "{measure:?}");
        }
    }
}

/// Mean z-deflection of the x = 0.4 end of the docs/model.md cantilever.
fn cantilever_tip(k: u32) -> f64 {
    let l = Lattice::block([4 * k, k, k], 0.1 / k as f64, [0.0; 3]).unwrap();
    let model = Model::new(&l, Material::new(1000.0, 0.0, 0.01).unwrap(), &PaperModel).unwrap();
    let fixed: Vec<bool> = l.node_coords().iter().map(|c| c[0] == 0).collect();
    let f: Vec<Vec3> = model
        .masses()
        .iter()
        .map(|&m| Vec3::new(0.0, 0.0, -9.81 * m))
        .collect();
    // The 4x1x1 bar keeps 4 mechanisms (hourglass patterns of the single
    // cell row, docs/model.md), which gravity does not excite: the matrix is
    // singular and a factorization succeeds or not by round-off. A shift far
    // below the stiffness (1e-10 of it) makes the solve well posed and
    // changes the deflection by about as much.
    let mut k_rest = model.rest_stiffness();
    k_rest.add_diagonal(1e-10 * k_rest.max_diagonal());
    let u = k_rest.solve_symmetric(&f, &fixed).unwrap();
    let tip: Vec<f64> = (0..u.len())
        .filter(|&i| l.node_coords()[i][0] == 4 * k)
        .map(|i| u[i].z)
        .collect();
    -tip.iter().sum::<f64>() / tip.len() as f64
}

#[test]
fn cantilever_linear_regime() {
    for (k, expect) in [
        (1, 2.6732e-4),
        (2, 3.5060e-4),
        (4, 3.8293e-4),
        (8, 3.9219e-4),
    ] {
        let d = cantilever_tip(k);
        assert!((d / expect - 1.0).abs() < 1e-3, "{k}: {d} vs {expect}");
    }
}

/// Checks tangent(x) against central differences of the forces.
fn check_jacobian(model: &Model, x: &[Vec3]) {
    let t = model.tangent(x);
    let scale = max_abs_block(&t);
    let h = model.h();
    let n = x.len();
    let mut worst = 0.0f64;
    for j in 0..n {
        for d in 0..3 {
            let step = 1e-6 * h;
            let mut xp = x.to_vec();
            xp[j][d] += step;
            let fp = forces(model, &xp);
            xp[j][d] -= 2.0 * step;
            let fm = forces(model, &xp);
            for i in 0..n {
                let col = (fp[i] - fm[i]) / (2.0 * step);
                let blk = t
                    .find(i, j)
                    .map_or(nalgebra::Matrix3::zeros(), |k| t.blocks[k]);
                for e in 0..3 {
                    worst = worst.max((col[e] - blk[(e, d)]).abs());
                }
            }
        }
    }
    assert!(
        worst < 1e-6 * scale,
        "{}: FD mismatch {worst} (scale {scale})",
        model.parameterization_name()
    );
}

#[test]
fn jacobian_matches_finite_differences() {
    let l = Lattice::block([2, 2, 1], 0.1, [0.0; 3]).unwrap();
    let paper_hg = with_hourglass(Box::new(PaperModel));
    let volumetric_hg = with_hourglass(Box::new(Volumetric));
    for (param, nu) in [
        (&SpringsOnly as &dyn Parameterization, 0.3),
        (&paper_hg, 0.3),
        (&volumetric_hg, 0.45),
        (&PaperModel, 0.3),
        (&PaperModel, -0.2),
        (&PaperModel, 0.49),
        (&Volumetric, 0.3),
        (&Volumetric, 0.45),
    ] {
        let model = Model::new(&l, mat(100.0, nu, 1.0), param).unwrap();
        let x = deformed(&model, 11);
        check_jacobian(&model, &x);
        let t = model.tangent(&x);
        if param.name() != "springs" {
            // The correction part makes it non-symmetric at large strain.
            assert!(t.asymmetry() > 1e-6 * max_abs_block(&t));
        } else {
            assert!(t.asymmetry() < 1e-12 * max_abs_block(&t));
        }
    }
}

#[test]
fn rest_tangent_is_symmetric() {
    let l = Lattice::l_shape(2, 1.0).unwrap();
    let volumetric_hg = with_hourglass(Box::new(Volumetric));
    for param in [
        &SpringsOnly as &dyn Parameterization,
        &PaperModel,
        &Volumetric,
        &volumetric_hg,
    ] {
        for nu in [-0.2, 0.3, 0.49] {
            let model = Model::new(&l, mat(100.0, nu, 1.0), param).unwrap();
            let t = model.tangent(model.rest_positions());
            assert!(
                t.asymmetry() < 1e-12 * max_abs_block(&t),
                "{} {nu}",
                param.name()
            );
            let f = forces(&model, model.rest_positions());
            assert!(f.iter().all(|v| v.amax() < 1e-12));
        }
    }
}

/// Springs and a volumetric term, no corrections: conservative, for the energy test.
#[derive(Debug)]
struct Conservative;
impl Parameterization for Conservative {
    fn name(&self) -> String {
        "conservative-test".into()
    }
    fn validate(&self, _: &Material) -> Result<(), MaterialError> {
        Ok(())
    }
    fn coefficients(&self, m: &Material, h: f64) -> CellCoefficients {
        CellCoefficients {
            k_edge: m.young * h * 0.3,
            k_diag: m.young * h * 0.2,
            correction: None,
            volumetric_lambda: m.young * 2.0,
            volumetric_barrier: false,
            hourglass: m.young * h * 0.1,
        }
    }
}

#[test]
fn forces_are_minus_energy_gradient() {
    let l = Lattice::block([2, 1, 2], 0.2, [0.0; 3]).unwrap();
    for param in [&SpringsOnly as &dyn Parameterization, &Conservative] {
        let model = Model::new(&l, mat(100.0, 0.3, 1.0), param).unwrap();
        let x = deformed(&model, 3);
        let f = forces(&model, &x);
        let scale = f.iter().map(|v| v.amax()).fold(0.0, f64::max);
        let step = 1e-6 * model.h();
        for i in 0..x.len() {
            for d in 0..3 {
                let mut xp = x.clone();
                xp[i][d] += step;
                let ep = model.energy(&xp);
                xp[i][d] -= 2.0 * step;
                let em = model.energy(&xp);
                let g = (ep - em) / (2.0 * step);
                assert!(
                    (f[i][d] + g).abs() < 1e-6 * scale,
                    "{} {i} {d}",
                    param.name()
                );
            }
        }
        assert!(model.energy(model.rest_positions()).abs() < 1e-20);
    }
}

#[test]
fn forces_are_bitwise_identical_for_any_thread_count() {
    let l = Lattice::block([22, 22, 22], 0.01, [0.0; 3]).unwrap();
    for param in [&PaperModel as &dyn Parameterization, &Volumetric] {
        let model = Model::new(&l, mat(100.0, 0.3, 1.0), param).unwrap();
        let x = deformed(&model, 5);
        let run = |threads: usize| {
            crate::on_threads(threads, || {
                let mut ws = model.workspace();
                let mut f = vec![Vec3::zeros(); x.len()];
                model.internal_forces_with(&x, &mut ws, &mut f);
                (f, model.energy(&x))
            })
        };
        let one = run(1);
        for threads in [2, 4] {
            let other = run(threads);
            assert!(
                one.0
                    .iter()
                    .zip(&other.0)
                    .all(|(a, b)| { (0..3).all(|d| a[d].to_bits() == b[d].to_bits()) })
            );
            assert_eq!(one.1.to_bits(), other.1.to_bits());
        }
    }
}

#[test]
fn critical_time_step_is_safe_and_tight() {
    let l = Lattice::block([3, 2, 2], 0.1, [0.0; 3]).unwrap();
    for param in [
        &SpringsOnly as &dyn Parameterization,
        &PaperModel,
        &Volumetric,
    ] {
        for nu in [-0.2, 0.0, 0.3, 0.49] {
            let model = Model::new(&l, mat(1000.0, nu, 10.0), param).unwrap();
            let wmax = dense_omega_max(&model);
            let bound = model.omega_max_bound();
            let ratio = bound / wmax;
            eprintln!("{} nu {nu}: omega bound / true = {ratio:.3}", param.name());
            assert!(
                (1.0..3.0).contains(&ratio),
                "{} nu {nu}: {ratio}",
                param.name()
            );
            // The Lanczos estimate: the true value with its 5 % margin on
            // omega^2 (the iteration has converged on so small a model).
            let estimate = model.omega_max() / wmax;
            assert!(
                (1.0..=1.03).contains(&estimate) && model.omega_max() <= bound,
                "{} nu {nu}: estimate / true = {estimate}",
                param.name()
            );
            assert_eq!(model.critical_time_step(), 2.0 / model.omega_max());
        }
    }
}

/// The largest eigenfrequency at rest by dense eigenvalues, `sqrt(max eig M^-1 K)`.
fn dense_omega_max(model: &Model) -> f64 {
    use nalgebra::{DMatrix, SymmetricEigen};
    let k = model.rest_stiffness();
    let n = 3 * model.num_nodes();
    let mut dense = DMatrix::<f64>::zeros(n, n);
    for i in 0..model.num_nodes() {
        for kk in k.row_offsets[i] as usize..k.row_offsets[i + 1] as usize {
            let j = k.col_indices[kk] as usize;
            let s = (model.masses()[i] * model.masses()[j]).sqrt();
            for e in 0..3 {
                for d in 0..3 {
                    dense[(3 * i + e, 3 * j + d)] = k.blocks[kk][(e, d)] / s;
                }
            }
        }
    }
    SymmetricEigen::new(dense).eigenvalues.max().sqrt()
}

#[test]
fn the_frequency_estimate_is_the_true_one_on_rough_lattices() {
    // Blocks with cells removed at random: cells hanging by a face or an
    // edge carry the highest modes, which the Gershgorin bound overstates.
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let hg = HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap();
    let mut worst_gain = f64::INFINITY;
    for trial in 0..12 {
        let dims = [6u32, 5, 4];
        let cells: Vec<[u32; 3]> = (0..dims[2])
            .flat_map(|z| (0..dims[1]).flat_map(move |y| (0..dims[0]).map(move |x| [x, y, z])))
            .filter(|_| next() % 100 < 75)
            .collect();
        let l = Lattice::from_cells([0.0; 3], 0.02, dims, cells).unwrap();
        let param: &dyn Parameterization = if trial % 2 == 0 { &hg } else { &PaperModel };
        let model = Model::new(&l, mat(2e4, 0.45, 1000.0), param).unwrap();
        let truth = dense_omega_max(&model);
        let ratio = model.omega_max() / truth;
        assert!(
            (1.0..=1.03).contains(&ratio),
            "trial {trial} {}: estimate / true {ratio}",
            param.name()
        );
        worst_gain = worst_gain.min(model.omega_max_bound() / model.omega_max());
    }
    // The point of the estimate: a longer step than the bound allows.
    assert!(worst_gain > 1.05, "{worst_gain}");
}

#[test]
fn the_frequency_estimate_does_not_depend_on_the_thread_count() {
    let l = Lattice::block([9, 7, 5], 0.01, [0.0; 3]).unwrap();
    let estimate = |threads: usize| {
        crate::on_threads(threads, || {
            Model::new(&l, mat(1e4, 0.3, 1000.0), &PaperModel)
                .unwrap()
                .omega_max()
        })
    };
    let one = estimate(1);
    assert_eq!(one.to_bits(), estimate(2).to_bits());
    assert_eq!(one.to_bits(), estimate(3).to_bits());
}

#[test]
fn multi_material_and_errors() {
    let l = Lattice::block([2, 1, 1], 1.0, [0.0; 3]).unwrap();
    let mats = [
        Material::new(1.0, 0.3, 1.0).unwrap(),
        Material::new(2.0, 0.3, 5.0).unwrap(),
    ];
    let m = Model::with_cell_materials(&l, &mats, &[0, 1], &PaperModel).unwrap();
    assert!((m.total_mass() - 6.0).abs() < 1e-14);
    assert_eq!(m.cell_material(1), 1);
    assert!(Model::with_cell_materials(&l, &mats, &[0, 2], &PaperModel).is_err());
    assert!(Model::with_cell_materials(&l, &mats, &[0], &PaperModel).is_err());
    let bad = Material {
        young: 1.0,
        poisson: -0.3,
        density: 1.0,
    };
    let err = Model::new(&l, bad, &PaperModel).unwrap_err().to_string();
    assert!(err.contains("-0.3"), "{err}");
    assert!(Model::new(&l, bad, &Volumetric).is_ok());
    let known = mss_core::Parameterizations::default();
    assert_eq!(
        known.names(),
        ["paper", "springs", "volumetric", "volumetric-barrier"]
    );
    for base in known.names() {
        for name in [base.clone(), format!("{base}+hg")] {
            let p = known.get(&name).unwrap();
            assert_eq!(p.name(), name);
        }
    }
    let err = known.get("nope").err().unwrap().to_string();
    assert!(err.contains("paper, springs, volumetric"), "{err}");
    assert!(known.get("paper+hg+hg").is_err());
    assert!(known.build("paper", Some(-1.0)).is_err());
    assert_eq!(known.build("paper", Some(0.5)).unwrap().name(), "paper+hg");
}

#[test]
fn inverted_cells_are_detected() {
    let l = Lattice::block([2, 1, 1], 1.0, [0.0; 3]).unwrap();
    let m = Model::new(&l, Material::new(1.0, 0.3, 1.0).unwrap(), &PaperModel).unwrap();
    assert!(m.inverted_cells(m.rest_positions()).is_empty());
    let mut x = m.rest_positions().to_vec();
    // Mirror the second cell's far face through its near face.
    for (i, c) in l.node_coords().iter().enumerate() {
        if c[0] == 2 {
            x[i].x = 0.5;
        }
    }
    assert_eq!(m.inverted_cells(&x), vec![1]);
    let d = m.cell_diagnostics(&x);
    assert!((d[1].volumetric_strain + 1.5).abs() < 1e-12);
    assert!(d[0].volumetric_strain.abs() < 1e-12 && d[0].shear_strain.abs() < 1e-12);
}

#[test]
fn zero_energy_modes_of_blocks() {
    use mss_core::modes::{zero_energy_modes_dense, zero_energy_modes_subspace};
    let l = Lattice::block([3, 2, 2], 0.1, [0.0; 3]).unwrap();
    for param in [
        &SpringsOnly as &dyn Parameterization,
        &PaperModel,
        &Volumetric,
    ] {
        for nu in [-0.2, 0.3, 0.49] {
            let model = Model::new(&l, mat(100.0, nu, 1.0), param).unwrap();
            let none = vec![[false; 3]; l.num_nodes()];
            let clamped: Vec<[bool; 3]> = l.node_coords().iter().map(|c| [c[0] == 0; 3]).collect();
            let mut one = none.clone();
            one[0] = [true; 3];
            let mut two = one.clone();
            two[l.num_nodes() - 1] = [true; 3];
            for (mask, expect) in [
                (&none, Some(9)),
                (&clamped, Some(0)),
                (&one, Some(6)),
                (&two, None),
            ] {
                let d = zero_energy_modes_dense(&model, mask).unwrap();
                let s = zero_energy_modes_subspace(&model, mask).unwrap();
                assert_eq!(d.count, s.count, "{} {nu}: {d:?} {s:?}", param.name());
                match expect {
                    Some(e) => assert_eq!(d.count, e, "{} {nu}: {d:?}", param.name()),
                    None => assert!(d.count > 0),
                }
            }
        }
    }
}

#[test]
fn simd_and_scalar_paths_agree_bitwise() {
    // Two materials force the per-cell scalar path; one material the batched one.
    // A block, and a lattice with a hole and a notch (edges on many `+`
    // faces that no cell has at its corner 0, and batches cut short).
    let block = Lattice::block([5, 3, 3], 0.1, [0.0; 3]).unwrap();
    let holed = Lattice::from_cells(
        [0.0; 3],
        0.1,
        [6, 5, 4],
        (0..6u32)
            .flat_map(|i| (0..5u32).flat_map(move |j| (0..4u32).map(move |k| [i, j, k])))
            .filter(|&[i, j, k]| !(i == 2 && j == 2 || i >= 4 && k == 3) && (i + j + k) % 7 != 3),
    )
    .unwrap();
    let volumetric_hg = with_hourglass(Box::new(Volumetric));
    for (l, param) in [&block, &holed].into_iter().flat_map(|l| {
        [
            &PaperModel as &dyn Parameterization,
            &Volumetric,
            &SpringsOnly,
            &volumetric_hg,
            &VolumetricBarrier,
        ]
        .map(|p| (l, p))
    }) {
        let m = mat(100.0, 0.3, 1.0);
        let single = Model::new(l, m, param).unwrap();
        let multi = Model::with_cell_materials(l, &[m, m], &vec![1; l.num_cells()], param).unwrap();
        let mut x = deformed(&single, 9);
        if param.name() == VolumetricBarrier.name() {
            // Crushed along z past the barrier's knee (J < 0.1) in some
            // cells and not in others: both sides of its law.
            for (p, r) in x.iter_mut().zip(single.rest_positions()) {
                p.z = r.z * (0.04 + 0.5 * r.x);
            }
        }
        let (a, b) = (forces(&single, &x), forces(&multi, &x));
        assert!(same_bits(&a, &b));
        // The portable scalar path (no SIMD, one cell at a time) gives the
        // same bits as the vector one.
        let mut scalar = vec![Vec3::zeros(); x.len()];
        single.internal_forces_scalar_with(&x, &mut single.workspace(), &mut scalar);
        assert!(same_bits(&a, &scalar), "{}", param.name());
        // And the batch path agrees with the per-cell forces, which divide
        // once per spring (the pass shares divisions: a few ulps apart).
        let mut g = vec![Vec3::zeros(); x.len()];
        for c in 0..l.num_cells() {
            for (k, f) in single.cell_forces(&x, c).iter().enumerate() {
                g[l.cells()[c][k] as usize] += f;
            }
        }
        assert!(a.iter().zip(&g).all(|(p, q)| (p - q).amax() < 1e-12));
    }
}

/// The force pass adds eight cells that lie in one row of the lattice into
/// their nodes as runs of nodes, and its edge pass stores their stretches
/// as one run (on CPUs with AVX-512): the same bits as the
/// portable pass, cell by cell, for rows longer than eight cells, rows cut
/// by holes and groups that straddle two rows, for every model, and for
/// any thread count; in `f64` and in `f32` (sixteen cells per pass, each
/// half of eight in one row or not).
#[test]
fn forces_added_by_rows_are_the_cell_by_cell_bits() {
    let block = Lattice::block([19, 3, 2], 0.1, [0.0; 3]).unwrap();
    let holed = Lattice::from_cells(
        [0.0; 3],
        0.1,
        [21, 4, 3],
        (0..21u32)
            .flat_map(|i| (0..4u32).flat_map(move |j| (0..3u32).map(move |k| [i, j, k])))
            .filter(|&[i, j, k]| !(i == 11 && j == 1) && (i + 2 * j + 5 * k) % 23 != 4),
    )
    .unwrap();
    let volumetric_hg = with_hourglass(Box::new(VolumetricBarrier));
    for (l, param) in [&block, &holed].into_iter().flat_map(|l| {
        [
            &PaperModel as &dyn Parameterization,
            &SpringsOnly,
            &volumetric_hg,
        ]
        .map(|p| (l, p))
    }) {
        let model = Model::new(l, mat(100.0, 0.3, 1.0), param).unwrap();
        let x = deformed(&model, 5);
        for precision in [Precision::F64, Precision::F32] {
            let mut scalar = vec![Vec3::zeros(); x.len()];
            model.internal_forces_scalar_in(precision, &x, &mut model.workspace(), &mut scalar);
            for threads in [1, 2] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut batched = vec![Vec3::zeros(); x.len()];
                pool.install(|| {
                    model.internal_forces_in(precision, &x, &mut model.workspace(), &mut batched)
                });
                assert!(
                    same_bits(&batched, &scalar),
                    "{} on {} cells, {}, {threads} threads",
                    param.name(),
                    l.num_cells(),
                    precision.name()
                );
            }
        }
    }
}

/// Rows of every length from 1 to 17 cells, and layers of one and of two
/// rows: the force pass's groups of eight and sixteen cells then end at
/// every place in a row and in a batch, and its last, partial groups take
/// every size (through the narrower paths). The same bits as the portable
/// pass cell by cell, in `f64` and `f32`, on one and two threads.
#[test]
fn forces_of_rows_of_every_length_are_the_cell_by_cell_bits() {
    let volumetric_hg = with_hourglass(Box::new(VolumetricBarrier));
    for len in 1..=17 {
        for rows in [1, 2] {
            let l = Lattice::block([len, rows, 2], 0.1, [0.0; 3]).unwrap();
            for param in [&PaperModel as &dyn Parameterization, &volumetric_hg] {
                let model = Model::new(&l, mat(100.0, 0.3, 1.0), param).unwrap();
                let x = deformed(&model, u64::from(len));
                for precision in [Precision::F64, Precision::F32] {
                    let mut scalar = vec![Vec3::zeros(); x.len()];
                    model.internal_forces_scalar_in(
                        precision,
                        &x,
                        &mut model.workspace(),
                        &mut scalar,
                    );
                    assert!(scalar.iter().any(|f| f.norm() > 0.0));
                    for threads in [1, 2] {
                        let batched = crate::on_threads(threads, || {
                            let mut f = vec![Vec3::zeros(); x.len()];
                            model.internal_forces_in(precision, &x, &mut model.workspace(), &mut f);
                            f
                        });
                        assert!(
                            same_bits(&batched, &scalar),
                            "{} on rows of {len}, {rows} per layer, {}, {threads} threads",
                            param.name(),
                            precision.name()
                        );
                    }
                }
            }
        }
    }
}

/// docs/model.md, section 3: internal forces exert no net force on the body
/// and turn with it (they depend on the shape, not on its placement).
#[test]
fn internal_forces_are_balanced_and_frame_invariant() {
    let lattice = Lattice::block([3, 2, 2], 0.1, [0.0; 3]).unwrap();
    let params: Vec<Box<dyn Parameterization>> = vec![
        Box::new(PaperModel),
        Box::new(SpringsOnly),
        Box::new(Volumetric),
        Box::new(with_hourglass(Box::new(PaperModel))),
    ];
    // A rotation by 0.7 rad about (1, 2, 3) and a translation.
    let axis = nalgebra::Unit::new_normalize(Vec3::new(1.0, 2.0, 3.0));
    let r = nalgebra::Rotation3::from_axis_angle(&axis, 0.7);
    let shift = Vec3::new(0.3, -1.0, 2.0);
    for param in &params {
        let model = Model::new(&lattice, mat(1e4, 0.3, 1000.0), param.as_ref()).unwrap();
        let x = deformed(&model, 7);
        let f = forces(&model, &x);
        let scale = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
        assert!(scale > 0.0);
        let net: Vec3 = f.iter().sum();
        assert!(net.norm() < 1e-10 * scale, "{}: net {net:?}", param.name());
        let moved: Vec<Vec3> = x.iter().map(|p| r * p + shift).collect();
        let g = forces(&model, &moved);
        for (a, b) in f.iter().zip(&g) {
            assert!((r * a - b).norm() < 1e-9 * scale, "{}", param.name());
        }
    }
}

/// The single-precision force pass: the same bits on the AVX2 and portable
/// paths and for any thread count; within `1e-7 / strain` of the `f64`
/// forces (relative to the largest force), also for a body far from the
/// origin (each cell is rounded relative to its corner 0).
#[test]
fn single_precision_forces_are_close_and_reproducible() {
    let l = Lattice::from_cells(
        [0.0; 3],
        0.05,
        [9, 7, 6],
        (0..9u32)
            .flat_map(|i| (0..7u32).flat_map(move |j| (0..6u32).map(move |k| [i, j, k])))
            .filter(|&[i, j, k]| (i * 3 + j * 5 + k) % 11 != 4),
    )
    .unwrap();
    let volumetric_hg = with_hourglass(Box::new(VolumetricBarrier));
    for param in [
        &PaperModel as &dyn Parameterization,
        &SpringsOnly,
        &volumetric_hg,
    ] {
        let model = Model::new(&l, mat(1.0e5, 0.3, 1000.0), param).unwrap();
        // A homogeneous strain of about 1 % and a little noise.
        let x: Vec<Vec3> = model
            .rest_positions()
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let s = ((i as f64) * 0.618).fract() - 0.5;
                Vec3::new(1.01 * p.x + 0.002 * p.y, 0.995 * p.y, p.z + 0.01 * p.x)
                    + Vec3::new(s, -s, 0.5 * s) * 0.002 * model.h()
            })
            .collect();
        let run = |x: &[Vec3], precision: Precision, threads: usize, scalar: bool| {
            crate::on_threads(threads, || {
                let mut ws = model.workspace();
                let mut f = vec![Vec3::zeros(); x.len()];
                if scalar {
                    model.internal_forces_scalar_in(precision, x, &mut ws, &mut f);
                } else {
                    model.internal_forces_in(precision, x, &mut ws, &mut f);
                }
                f
            })
        };
        let exact = run(&x, Precision::F64, 1, false);
        let single = run(&x, Precision::F32, 1, false);
        assert!(
            same_bits(&single, &run(&x, Precision::F32, 1, true)),
            "{}",
            param.name()
        );
        assert!(
            same_bits(&single, &run(&x, Precision::F32, 3, false)),
            "{}",
            param.name()
        );
        let scale = exact.iter().map(|f| f.norm()).fold(0.0, f64::max);
        let err = |f: &[Vec3]| {
            exact
                .iter()
                .zip(f)
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max)
                / scale
        };
        // f32 rounds at 6e-8; the strains here are about 0.5 %.
        assert!(
            err(&single) < 1e-7 / 5e-3 * 4.0,
            "{}: {:e}",
            param.name(),
            err(&single)
        );
        assert!(err(&single) > 0.0, "the f32 path ran in f64");
        // Far from the origin the f64 forces lose a little to the
        // placement, the f32 ones nothing more.
        let far: Vec<Vec3> = x
            .iter()
            .map(|p| p + Vec3::new(1.0e3, -2.0e3, 5.0e2))
            .collect();
        let far_single = run(&far, Precision::F32, 1, false);
        assert!(
            err(&far_single) < 1e-7 / 5e-3 * 4.0,
            "{}: {:e}",
            param.name(),
            err(&far_single)
        );
    }
}

/// The corner barrier is the barrier law's, not a correction force: on a
/// cell with a corner pushed into it (corner Jacobian 0.1), the correction
/// diagnostic of `volumetric-barrier` equals that of `volumetric` (the same
/// corrections, without either barrier), and their forces differ.
#[test]
fn the_corner_barrier_is_not_counted_as_a_correction() {
    let l = Lattice::block([1, 1, 1], 0.1, [0.0; 3]).unwrap();
    let m = Material::new(50.0, 0.3, 1.0).unwrap();
    let plain = Model::new(&l, m, &Volumetric).unwrap();
    let barrier = Model::new(&l, m, &VolumetricBarrier).unwrap();
    let mut x = plain.rest_positions().to_vec();
    // Corner 0 along the diagonal by 0.3 h: J_0 = 1 - 3 * 0.3.
    x[0] += Vec3::new(0.03, 0.03, 0.03);
    assert!((barrier.corner_jacobians(&x)[0] - 0.1).abs() < 1e-12);
    let (dp, db) = (plain.cell_diagnostics(&x), barrier.cell_diagnostics(&x));
    assert!(dp[0].correction_force > 0.0);
    assert!(
        (dp[0].correction_force - db[0].correction_force).abs() < 1e-12 * dp[0].correction_force
    );
    let gap = forces(&barrier, &x)[0] - forces(&plain, &x)[0];
    assert!(gap.norm() > 1e-3 * forces(&plain, &x)[0].norm(), "{gap:?}");
}

/// The force pass's operations per cell of the springs-only model, counted
/// by hand from docs/model.md: the three edge stretches at corner 0 (three
/// differences, squared lengths and square roots, one division for the three
/// inverses and `1 - L0 / l`), the cell's 12 edge springs (difference, axis
/// sum, `k w d` added to one end and subtracted from the other), its 4
/// diagonals (with one division for the four inverses) and the 24 additions
/// into the node sums. The richer models only add to it, and the
/// single-precision pass adds its conversions.
#[test]
fn the_force_pass_counts_the_operations_of_the_model() {
    let lattice = Lattice::block([2, 2, 2], 0.1, [0.0; 3]).unwrap();
    let material = Material::new(1.0e5, 0.3, 1000.0).unwrap();
    let springs = Model::new(&lattice, material, &SpringsOnly).unwrap();
    let ops = springs.force_operations(Precision::F64);
    let edges = ForceOperations {
        add: 9 + 6 + 3,
        mul: 9 + 7 + 3,
        div: 1,
        sqrt: 3,
        other: 0,
    };
    let cell = ForceOperations {
        add: 4 * 36 + 12 + 8 + 4 + 24,
        mul: 12 + 36 + 12 + 9 + 4 + 4 + 12,
        div: 1,
        sqrt: 4,
        other: 0,
    };
    assert_eq!(
        ops,
        ForceOperations {
            add: edges.add + cell.add + 24,
            mul: edges.mul + cell.mul,
            div: edges.div + cell.div,
            sqrt: edges.sqrt + cell.sqrt,
            other: 0,
        }
    );
    let paper = Model::new(&lattice, material, &PaperModel).unwrap();
    let default = Model::new(
        &lattice,
        material,
        &HourglassControl::new(Box::new(VolumetricBarrier), 1.0).unwrap(),
    )
    .unwrap();
    let (p, d) = (
        paper.force_operations(Precision::F64),
        default.force_operations(Precision::F64),
    );
    // The corrections: the cell axes (three square roots, one division).
    assert_eq!((p.sqrt, p.div), (ops.sqrt + 3, ops.div + 1));
    assert!(p.pipelined() > ops.pipelined());
    // The barrier's logarithm divides once more, twice with its slope.
    assert!(d.pipelined() > ops.pipelined() && d.div > ops.div);
    let single = paper.force_operations(Precision::F32);
    // In single precision: the corners' differences in `f64`, their
    // narrowing and the forces' widening; each edge's seed (a square root and
    // a division in `f32`, two conversions) and its Newton step in place of
    // one third of the shared division.
    assert_eq!(single.other, p.other + 21 + 24 + 2 * 3);
    assert_eq!(single.add, p.add + 21 + 3);
    assert_eq!((single.sqrt, single.div), (p.sqrt, p.div + 2));
}
