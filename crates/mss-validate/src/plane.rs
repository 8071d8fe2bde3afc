//! The 2D element against plane-stress elasticity: a bilinear (Q1) finite
//! element reference on rectangle lattices ([`PlaneFem`]), the paper's
//! virtual elongation and shear tests at several aspect ratios and Poisson
//! ratios ([`virtual_tests`]), and a cantilever convergence study against
//! a converged FEM and Timoshenko's beam ([`cantilever_study`]), reported
//! with the paper's error metric ([`plane_report`], `mss experiment 2d`).
//!
//! ```
//! use hexmesh::plane::RectLattice;
//! use mss_core::Material;
//! use mss_validate::plane::PlaneFem;
//!
//! // A bar in tension: Q1 is exact for a homogeneous strain.
//! let lattice = RectLattice::block([4, 1], [0.25, 0.25], [0.0, 0.0]).unwrap();
//! let fem = PlaneFem::new(&lattice, Material::new(100.0, 0.0, 1.0).unwrap(), 1.0);
//! let mut held = vec![[false; 2]; lattice.num_nodes()];
//! let mut forces = vec![[0.0; 2]; lattice.num_nodes()];
//! for (i, p) in lattice.nodes().iter().enumerate() {
//!     if p[0] == 0.0 { held[i] = [true, p[1] == 0.0]; }
//!     if p[0] == 1.0 { forces[i][0] = 0.5 * 0.25; } // stress 1 over the 0.25 m face
//! }
//! let u = fem.solve(&held, &forces).unwrap();
//! let tip = u.iter().zip(lattice.nodes()).filter(|(_, p)| p[0] == 1.0).map(|(u, _)| u[0]).sum::<f64>() / 2.0;
//! assert!((tip - 0.01).abs() < 1e-12); // strain 1/100 over 1 m
//! ```

use std::fmt::Write as _;

use hexmesh::plane::RectLattice;
use mss_core::plane::{PlaneModel, PlaneModelError, PlaneParameterization, PlaneProblem};
use mss_core::{BlockCsr, LinearSolveError, Mat3, Material, Vec3};

/// Bilinear plane-stress finite elements on a [`RectLattice`] (2 x 2 Gauss
/// points, exact for rectangles), linear, thickness `t`.
#[derive(Debug, Clone)]
pub struct PlaneFem {
    nodes: Vec<[f64; 2]>,
    cells: Vec<[u32; 4]>,
    size: [f64; 2],
    material: Material,
    thickness: f64,
}

/// Corner positions in the reference square, counter-clockwise.
const XI: [[f64; 2]; 4] = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];

impl PlaneFem {
    /// The FEM model of `lattice` (m) in `material`, thickness `t` (m).
    pub fn new(lattice: &RectLattice, material: Material, t: f64) -> Self {
        Self {
            nodes: lattice.nodes().to_vec(),
            cells: lattice.cells().to_vec(),
            size: lattice.cell_size(),
            material,
            thickness: t,
        }
    }

    /// The 8 x 8 stiffness of one cell (dofs `2 corner + axis`).
    pub fn cell_stiffness(&self) -> [[f64; 8]; 8] {
        let [a, b] = self.size;
        let (e, nu) = (self.material.young, self.material.poisson);
        let c = e / (1.0 - nu * nu);
        let d = [
            [c, c * nu, 0.0],
            [c * nu, c, 0.0],
            [0.0, 0.0, c * (1.0 - nu) / 2.0],
        ];
        let g = 1.0 / 3f64.sqrt();
        let mut k = [[0.0; 8]; 8];
        for (gx, gy) in [(-g, -g), (g, -g), (g, g), (-g, g)] {
            // B: strains (xx, yy, 2xy) from the 8 dofs.
            let mut bm = [[0.0; 8]; 3];
            for (n, xi) in XI.iter().enumerate() {
                let dx = 0.25 * xi[0] * (1.0 + xi[1] * gy) * 2.0 / a;
                let dy = 0.25 * xi[1] * (1.0 + xi[0] * gx) * 2.0 / b;
                bm[0][2 * n] = dx;
                bm[1][2 * n + 1] = dy;
                bm[2][2 * n] = dy;
                bm[2][2 * n + 1] = dx;
            }
            let w = a * b / 4.0 * self.thickness;
            for i in 0..8 {
                for j in 0..8 {
                    let mut s = 0.0;
                    for p in 0..3 {
                        for q in 0..3 {
                            s += bm[p][i] * d[p][q] * bm[q][j];
                        }
                    }
                    k[i][j] += w * s;
                }
            }
        }
        k
    }

    /// The assembled stiffness as 3 x 3 blocks (z rows zero).
    pub fn stiffness(&self) -> BlockCsr {
        let hex: Vec<[u32; 8]> = self
            .cells
            .iter()
            .map(|c| [c[0], c[1], c[2], c[3], c[0], c[1], c[2], c[3]])
            .collect();
        let mut m = BlockCsr::lattice_pattern(self.nodes.len(), &hex);
        let ke = self.cell_stiffness();
        for c in &self.cells {
            for (r, &a) in c.iter().enumerate() {
                for (s, &b) in c.iter().enumerate() {
                    let k = m.find(a as usize, b as usize).expect("pair in the pattern");
                    let mut blk = Mat3::zeros();
                    for e in 0..2 {
                        for d in 0..2 {
                            blk[(e, d)] = ke[2 * r + e][2 * s + d];
                        }
                    }
                    m.blocks[k] += blk;
                }
            }
        }
        m
    }

    /// The displacements (m) under nodal `forces` (N) with the `held`
    /// components zero.
    pub fn solve(
        &self,
        held: &[[bool; 2]],
        forces: &[[f64; 2]],
    ) -> Result<Vec<[f64; 2]>, LinearSolveError> {
        let k = self.stiffness();
        let fixed: Vec<[bool; 3]> = held.iter().map(|h| [h[0], h[1], true]).collect();
        let rhs: Vec<Vec3> = forces.iter().map(|f| Vec3::new(f[0], f[1], 0.0)).collect();
        let u = k.solve_symmetric_dofs(&rhs, &fixed)?;
        Ok(u.iter().map(|v| [v.x, v.y]).collect())
    }
}

/// E, nu and G an element's virtual tests measure, relative errors.
#[derive(Debug, Clone, PartialEq)]
pub struct VirtualTest {
    /// The variant (`paper`, `springs`, `areal`).
    pub variant: &'static str,
    /// `l0 / h0`.
    pub aspect: f64,
    /// Poisson's ratio given.
    pub nu: f64,
    /// Young's modulus measured along x and along y, relative to E.
    pub young: [f64; 2],
    /// Poisson's ratio measured in tension along x and along y.
    pub poisson: [f64; 2],
    /// Shear modulus measured, relative to G.
    pub shear: f64,
}

/// Why an experiment failed.
#[derive(Debug, thiserror::Error)]
pub enum PlaneExperimentError {
    /// The model could not be built.
    #[error(transparent)]
    Model(#[from] PlaneModelError),
    /// The MSS static solve failed.
    #[error(transparent)]
    Solve(#[from] mss_core::plane::PlaneSolveError),
    /// The FEM solve failed.
    #[error("FEM: {0}")]
    Fem(#[from] LinearSolveError),
    /// A lattice could not be built.
    #[error(transparent)]
    Lattice(#[from] hexmesh::plane::PlaneError),
}

fn variant_model(
    lattice: &RectLattice,
    material: Material,
    t: f64,
    name: &str,
) -> Result<PlaneModel, PlaneModelError> {
    let (base, hg) = match name.strip_suffix("+hg") {
        Some(b) => (b, Some(1.0)),
        None => (name, None),
    };
    let variant = PlaneParameterization::from_name(base).expect("a built-in 2D variant");
    PlaneModel::new(lattice, material, t, variant, hg)
}

/// Uniaxial tension along `axis` of a 4 x 3 block with rollers; returns
/// (E, nu) measured.
fn tension(model: PlaneModel, axis: usize) -> Result<(f64, f64), PlaneExperimentError> {
    let other = 1 - axis;
    let rest = model.rest_positions().to_vec();
    let hi = |d: usize| rest.iter().map(|p| p[d]).fold(f64::MIN, f64::max);
    let face = [model.cell_size()[1], model.cell_size()[0]][axis];
    // Small enough that the geometric non-linearity stays below 1e-6.
    let stress = 1e-7 * model.material().young;
    let t = model.thickness();
    let (len, width) = (hi(axis), hi(other));
    let mut p = PlaneProblem::new(model);
    for (i, x) in rest.iter().enumerate() {
        for d in 0..2 {
            p.held[i][d] = x[d].abs() < 1e-12;
        }
        if (x[axis] - len).abs() < 1e-12 {
            let edge = x[other].abs() < 1e-12 || (x[other] - width).abs() < 1e-12;
            p.forces[i][axis] = stress * face * t * if edge { 0.5 } else { 1.0 };
        }
    }
    let mut x = rest.clone();
    p.solve_static(0.0, &mut x)?;
    let mean = |d: usize, at: f64, along: usize| {
        let sel: Vec<f64> = rest
            .iter()
            .zip(&x)
            .filter(|(r, _)| (r[along] - at).abs() < 1e-12)
            .map(|(r, x)| x[d] - r[d])
            .collect();
        sel.iter().sum::<f64>() / sel.len() as f64
    };
    let eps = mean(axis, len, axis) / len;
    let lateral = mean(other, width, other) / width;
    Ok((stress / eps, -lateral / eps))
}

/// G from simple shear `gamma` of every node: the shear force the top row
/// carries.
fn shear(model: &PlaneModel) -> f64 {
    let gamma = 1e-7;
    let rest = model.rest_positions();
    let x: Vec<Vec3> = rest
        .iter()
        .map(|p| p + Vec3::new(gamma * p.y, 0.0, 0.0))
        .collect();
    let mut f = vec![Vec3::zeros(); x.len()];
    model.internal_forces(&x, &mut f);
    let top = rest.iter().map(|p| p.y).fold(f64::MIN, f64::max);
    let width = rest.iter().map(|p| p.x).fold(f64::MIN, f64::max);
    let carried: f64 = rest
        .iter()
        .zip(&f)
        .filter(|(r, _)| (r.y - top).abs() < 1e-12)
        .map(|(_, f)| -f.x)
        .sum();
    carried / (width * model.thickness()) / gamma
}

/// The paper's virtual elongation (along x and along y) and shear tests of
/// `variants` at cell aspect ratios `aspects` and Poisson ratios `nus`, on
/// 4 x 3 blocks.
pub fn virtual_tests(
    variants: &[&'static str],
    aspects: &[f64],
    nus: &[f64],
) -> Result<Vec<VirtualTest>, PlaneExperimentError> {
    let mut out = Vec::new();
    for &variant in variants {
        for &aspect in aspects {
            for &nu in nus {
                let material = Material::with_poisson_range(1.0e4, nu, 1000.0, -1.0, 0.5)
                    .expect("a valid material");
                let lattice = RectLattice::block([4, 3], [0.01 * aspect, 0.01], [0.0, 0.0])?;
                let m = || variant_model(&lattice, material, 0.01, variant);
                let (ex, nux) = tension(m()?, 0)?;
                let (ey, nuy) = tension(m()?, 1)?;
                let g = shear(&m()?) / (1.0e4 / (2.0 * (1.0 + nu)));
                out.push(VirtualTest {
                    variant,
                    aspect,
                    nu,
                    young: [ex / 1.0e4, ey / 1.0e4],
                    poisson: [nux, nuy],
                    shear: g,
                });
            }
        }
    }
    Ok(out)
}

/// One model's cantilever against the reference.
#[derive(Debug, Clone, PartialEq)]
pub struct BeamRun {
    /// The model (`paper`, `paper+hg`, ..., or `Q1 FEM` on the same lattice).
    pub model: String,
    /// `l0 / h0` of the cells.
    pub aspect: f64,
    /// Cells through the height.
    pub through: u32,
    /// The paper's metric: mean, standard deviation and maximum of the
    /// nodal error, percent of the largest reference displacement.
    pub mean: f64,
    /// Standard deviation (%).
    pub sd: f64,
    /// Maximum (%).
    pub max: f64,
    /// Mean tip deflection over Timoshenko's.
    pub tip_over_timoshenko: f64,
}

impl BeamRun {
    /// Whether the static solve found an equilibrium.
    pub fn solved(&self) -> bool {
        self.mean.is_finite()
    }
}

/// The cantilever of [`cantilever_study`]: length, height, thickness (m),
/// E (Pa), nu, density (kg/m^3).
pub const BEAM: (f64, f64, f64, f64, f64, f64) = (0.8, 0.1, 0.01, 1.0e6, 0.3, 1.0);

/// Timoshenko's tip deflection of [`BEAM`] under its own weight (shear
/// coefficient 5/6).
pub fn timoshenko_tip() -> f64 {
    let (len, height, t, e, nu, rho) = BEAM;
    let w = rho * 9.81 * height * t;
    let i = t * height.powi(3) / 12.0;
    let g = e / (2.0 * (1.0 + nu));
    w * len.powi(4) / (8.0 * e * i) + w * len * len / (2.0 * 5.0 / 6.0 * g * height * t)
}

/// The beam as `[along, through]` cells of aspect `aspect`, refined `r`
/// times, with its clamped nodes and its weight as nodal forces.
fn beam_setup(aspect: f64, through: u32, r: u32) -> Result<BeamSetup, PlaneExperimentError> {
    let (len, height, t, _, _, rho) = BEAM;
    let h0 = height / through as f64;
    let l0 = h0 * aspect;
    let along = (len / l0).round() as u32;
    let lattice = RectLattice::block(
        [along * r, through * r],
        [l0 / r as f64, h0 / r as f64],
        [0.0, 0.0],
    )?;
    let corner = rho * 9.81 * l0 * h0 * t / (4.0 * (r * r) as f64);
    let mut forces = vec![[0.0; 2]; lattice.num_nodes()];
    for c in lattice.cells() {
        for &a in c {
            forces[a as usize][1] -= corner;
        }
    }
    let held = lattice
        .nodes()
        .iter()
        .map(|p| [p[0].abs() < 1e-12; 2])
        .collect();
    Ok(BeamSetup {
        lattice,
        held,
        forces,
    })
}

struct BeamSetup {
    lattice: RectLattice,
    held: Vec<[bool; 2]>,
    forces: Vec<[f64; 2]>,
}

fn fem_beam(aspect: f64, through: u32, r: u32) -> Result<BeamSetupSolved, PlaneExperimentError> {
    let (_, _, t, e, nu, rho) = BEAM;
    let s = beam_setup(aspect, through, r)?;
    let material = Material::new(e, nu, rho).expect("valid");
    let u = PlaneFem::new(&s.lattice, material, t).solve(&s.held, &s.forces)?;
    Ok(BeamSetupSolved { setup: s, u })
}

struct BeamSetupSolved {
    setup: BeamSetup,
    u: Vec<[f64; 2]>,
}

impl BeamSetupSolved {
    /// The displacement at grid point `(i, j)` of the unrefined lattice.
    fn at(&self, i: u32, j: u32, r: u32) -> [f64; 2] {
        let dims = self.setup.lattice.dims();
        let node = (i * r + (dims[0] + 1) * j * r) as usize;
        debug_assert_eq!(self.setup.lattice.node_coords()[node], [i * r, j * r]);
        self.u[node]
    }
}

fn tip_of(lattice: &RectLattice, u: &[[f64; 2]]) -> f64 {
    let len = lattice
        .nodes()
        .iter()
        .map(|p| p[0])
        .fold(f64::MIN, f64::max);
    let tips: Vec<f64> = lattice
        .nodes()
        .iter()
        .zip(u)
        .filter(|(p, _)| (p[0] - len).abs() < 1e-9)
        .map(|(_, u)| -u[1])
        .collect();
    tips.iter().sum::<f64>() / tips.len() as f64
}

/// The cantilever [`BEAM`] clamped at x = 0 under its own weight, with
/// cells of each aspect ratio and 1, 2, 4, ... cells through the height,
/// for each model and for Q1 FEM on the same lattice, against Q1 FEM
/// refined `refine` times (and Richardson-extrapolated from `refine / 2`).
pub fn cantilever_study(
    models: &[&str],
    aspects: &[f64],
    throughs: &[u32],
    refine: u32,
) -> Result<Vec<BeamRun>, PlaneExperimentError> {
    let (_, _, t, e, nu, rho) = BEAM;
    let material = Material::new(e, nu, rho).expect("valid");
    let timoshenko = timoshenko_tip();
    let mut runs = Vec::new();
    for &aspect in aspects {
        for &through in throughs {
            let fine = fem_beam(aspect, through, refine)?;
            let half = fem_beam(aspect, through, refine / 2)?;
            let coarse = beam_setup(aspect, through, 1)?;
            let reference: Vec<[f64; 2]> = coarse
                .lattice
                .node_coords()
                .iter()
                .map(|&[i, j]| {
                    let (a, b) = (fine.at(i, j, refine), half.at(i, j, refine / 2));
                    [(4.0 * a[0] - b[0]) / 3.0, (4.0 * a[1] - b[1]) / 3.0]
                })
                .collect();
            let scale = reference
                .iter()
                .map(|u| u[0].hypot(u[1]))
                .fold(0.0, f64::max);
            let mut record = |model: String, u: &[[f64; 2]]| {
                let errors: Vec<f64> = u
                    .iter()
                    .zip(&reference)
                    .map(|(a, b)| 100.0 * (a[0] - b[0]).hypot(a[1] - b[1]) / scale)
                    .collect();
                let n = errors.len() as f64;
                let mean = errors.iter().sum::<f64>() / n;
                let sd = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
                runs.push(BeamRun {
                    model,
                    aspect,
                    through,
                    mean,
                    sd,
                    max: errors.iter().fold(0.0, |m, e| m.max(*e)),
                    tip_over_timoshenko: tip_of(&coarse.lattice, u) / timoshenko,
                });
            };
            for &name in models {
                let model = variant_model(&coarse.lattice, material, t, name)?;
                let mut p = PlaneProblem::new(model);
                p.held = coarse.held.clone();
                p.forces = coarse.forces.clone();
                let rest = p.model.rest_positions().to_vec();
                if p.model.unstable_in_bending() {
                    // Negative edge springs: the bending modes have negative
                    // stiffness, and whatever equilibrium Newton's method
                    // may find is unstable; a result of the study.
                    record(name.to_owned(), &vec![[f64::NAN; 2]; rest.len()]);
                    continue;
                }
                let mut x = rest.clone();
                match p.solve_static(0.0, &mut x) {
                    Ok(_) => {
                        let u: Vec<[f64; 2]> = x
                            .iter()
                            .zip(&rest)
                            .map(|(x, r)| [x.x - r.x, x.y - r.y])
                            .collect();
                        record(name.to_owned(), &u);
                    }
                    // A lattice unstable in bending has no equilibrium to
                    // find: a result of the study, reported as such.
                    Err(mss_core::plane::PlaneSolveError::Newton(_)) => {
                        record(name.to_owned(), &vec![[f64::NAN; 2]; rest.len()]);
                    }
                    Err(e) => return Err(e.into()),
                }
            }
            let same =
                PlaneFem::new(&coarse.lattice, material, t).solve(&coarse.held, &coarse.forces)?;
            record("Q1 FEM".into(), &same);
        }
    }
    Ok(runs)
}

/// The 2D variants the report compares.
pub const REPORT_MODELS: [&str; 5] = ["paper", "paper+hg", "springs", "areal", "areal+hg"];

/// The Markdown section of the 2D experiments (`quick`: fewer
/// resolutions and a coarser reference).
pub fn plane_report(quick: bool) -> Result<String, PlaneExperimentError> {
    let aspects = [1.0, 2.0, 4.0];
    let nus = [0.0, 0.25, 0.3, 0.45, 0.49];
    let tests = virtual_tests(&["paper", "springs", "areal"], &aspects, &nus)?;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "## The 2D element (plane stress)\n\n\
         Generated by `mss experiment 2d{}`. The paper's section 3.1 element, rectangles `l0 x h0` \
         (docs/model.md section 9). Variants: `paper` (springs and corrections), `springs` \
         (the springs alone), `areal` (springs exact in shear and an areal energy); `+hg`: \
         hourglass control that gives the cell's bending modes the stiffness of pure bending.\n\n\
         ### Virtual elongation and shear tests\n\n\
         4 x 3 blocks: tension along x and along y with rollers, and simple shear. Measured \
         E / E_given (x, y), measured nu (x, y) and G / G_given.\n",
        if quick { " --quick" } else { "" }
    );
    let _ = writeln!(md, "| variant | l0/h0 | nu | E_x | E_y | nu_x | nu_y | G |");
    let _ = writeln!(md, "|---|---|---|---|---|---|---|---|");
    for r in &tests {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {:.6} | {:.6} | {:.6} | {:.6} | {:.6} |",
            r.variant, r.aspect, r.nu, r.young[0], r.young[1], r.poisson[0], r.poisson[1], r.shear
        );
    }
    let (throughs, refine): (&[u32], u32) = if quick { (&[1, 2], 4) } else { (&[1, 2, 4], 8) };
    let runs = cantilever_study(&REPORT_MODELS, &aspects, throughs, refine)?;
    let (len, height, t, e, nu, rho) = BEAM;
    let _ = writeln!(
        md,
        "\n### Cantilever convergence\n\n\
         A {len} x {height} m beam, thickness {t} m, E = {e:e} Pa, nu = {nu}, rho = {rho} kg/m^3, \
         clamped at x = 0, under its own weight (linear regime). Reference: Q1 FEM refined {refine} \
         times per cell, Richardson-extrapolated from {}. Error metric as in 3D: per node \
         `|u - u_ref| / max |u_ref|` in percent (M, SD, MAX); `tip / T`: the mean tip deflection \
         over Timoshenko's ({:.4e} m). `Q1 FEM` is the same lattice's finite elements.\n",
        refine / 2,
        timoshenko_tip()
    );
    let _ = writeln!(
        md,
        "| model | l0/h0 | cells through | M % | SD % | MAX % | tip / T |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|");
    for r in &runs {
        if r.solved() {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.4} |",
                r.model, r.aspect, r.through, r.mean, r.sd, r.max, r.tip_over_timoshenko
            );
        } else {
            let _ = writeln!(
                md,
                "| {} | {} | {} | unstable in bending: no stable equilibrium | | | |",
                r.model, r.aspect, r.through
            );
        }
    }
    let _ = writeln!(
        md,
        "\nWithout hourglass control, cells longer than `sqrt(2 + 3 nu)` times their height have \
         `k_l < 0` and the lattice is unstable in bending (negative tip deflections, or no \
         equilibrium); square cells bend about twice too stiffly one cell thick. With it \
         (`+hg`), the tip deflection is within a few percent of Timoshenko's from one cell \
         through the height, where bilinear elements lock in shear."
    );
    Ok(md)
}
