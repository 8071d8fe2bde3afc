//! Virtual material tests: measure E, nu, G and K of a model on a unit block.
//!
//! All tests use an `n x n x n` block of unit size (h = 1/n), small loads
//! (strain about 1e-6) and the nonlinear static solver, run at `+load` and
//! `-load`: the central difference of the two responses cancels the
//! second-order (geometric) terms, so the measured moduli are the small-strain
//! ones to about 1e-12 relative.
//!
//! - Uniaxial tension (docs/model.md): rollers on x = 0, y = 0, z = 0 (each holds
//!   only the normal component), uniform traction `sigma` on z = 1 (consistent
//!   loads h^2/4 per face node). `eps_zz` = mean `u_z` on z = 1, `eps_xx` = mean
//!   `u_x` on x = 1; `E = sigma / eps_zz`, `nu = -eps_xx / eps_zz`.
//! - Shear: every boundary node is moved by the pure shear
//!   `u = gamma/2 (z, 0, x)` (rotation-free), interior nodes are free. The
//!   work `W = 1/2 sum u . (-f_int)` equals `G gamma^2 V / 2`: `G = 2 W / (gamma^2 V)`.
//! - Pressure: every boundary node is moved by the dilation `u = eps (x, y, z)`;
//!   `W = K (3 eps)^2 V / 2`: `K = 2 W / (9 eps^2 V)`.
//!
//! Prescribing the whole boundary measures the moduli without any edge effect
//! (a homogeneous deformation is an equilibrium of a uniform lattice), and the
//! work needs no choice of where to read a stress.

use hexmesh::Lattice;
use thiserror::Error;

use mss_core::constraints::{
    Axis, ConstraintError, ConstraintSpec, Constraints, Dofs, Face, Keyframe, Motion, NodeSelector,
};
use mss_core::loads::LoadSpec;
use mss_core::solver::{Problem, ProblemError, SolverError, State, StaticOptions, solve_static};
use mss_core::{Material, Model, ModelError, Parameterization, Vec3};

/// Moduli measured by [`measure_material`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredMaterial {
    /// Young's modulus from uniaxial tension (Pa).
    pub young: f64,
    /// Poisson's ratio from uniaxial tension.
    pub poisson: f64,
    /// Shear modulus from pure shear (Pa).
    pub shear: f64,
    /// Bulk modulus from uniform dilation (Pa).
    pub bulk: f64,
}

/// Why a material test failed.
#[derive(Debug, Error)]
pub enum MaterialTestError {
    /// The block size is zero.
    #[error("block of {0} cells per side: use at least 1")]
    BlockSize(u32),
    /// The model could not be built.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A boundary condition or load was refused (a bug of the test set-up).
    #[error(transparent)]
    Problem(#[from] ProblemError),
    /// Constraint set-up failed.
    #[error(transparent)]
    Constraint(#[from] ConstraintError),
    /// The static solve failed.
    #[error(transparent)]
    Solver(#[from] SolverError),
}

/// Relative strain used by the tests.
const STRAIN: f64 = 1e-6;

fn static_opts() -> StaticOptions {
    StaticOptions {
        rtol: 1e-12,
        ..StaticOptions::default()
    }
}

fn block_model(
    material: Material,
    param: &dyn Parameterization,
    n: u32,
) -> Result<Model, MaterialTestError> {
    if n == 0 {
        return Err(MaterialTestError::BlockSize(n));
    }
    let lattice = Lattice::block([n; 3], 1.0 / n as f64, [0.0; 3])
        .expect("a unit block with n >= 1 is a valid lattice");
    Ok(Model::new(&lattice, material, param)?)
}

fn mean_component(u: &[Vec3], nodes: &[u32], d: usize) -> f64 {
    nodes.iter().map(|&i| u[i as usize][d]).sum::<f64>() / nodes.len() as f64
}

/// Uniaxial tension: returns `(E, nu)`.
pub fn uniaxial_tension(
    material: Material,
    param: &dyn Parameterization,
    n: u32,
) -> Result<(f64, f64), MaterialTestError> {
    let model = block_model(material, param, n)?;
    let rollers = [Axis::X, Axis::Y, Axis::Z].map(|a| {
        ConstraintSpec::roller(
            NodeSelector::Plane {
                axis: a,
                value: 0.0,
                side: mss_core::constraints::Side::Below,
            },
            a,
        )
    });
    let sigma = material.young * STRAIN;
    let rest = model.rest_positions();
    let top = NodeSelector::face(Face::ZMax).select(rest, model.h());
    let right = NodeSelector::face(Face::XMax).select(rest, model.h());
    let mut u = [Vec::new(), Vec::new()];
    for (k, sign) in [1.0, -1.0].into_iter().enumerate() {
        let m = model.clone();
        let load = LoadSpec::Traction {
            min: [-1.0, -1.0, 1.0],
            max: [2.0, 2.0, 1.0],
            traction: [0.0, 0.0, sign * sigma],
        };
        let problem = Problem::from_specs(m, &rollers, &[load], mss_core::loads::Damping::NONE)?;
        let mut state = State::at_rest(problem.model());
        solve_static(&problem, &mut state, &static_opts())?;
        u[k] = state.displacements(problem.model());
    }
    let du: Vec<Vec3> = u[0].iter().zip(&u[1]).map(|(a, b)| (a - b) * 0.5).collect();
    let eps_zz = mean_component(&du, &top, 2);
    let eps_xx = mean_component(&du, &right, 0);
    Ok((sigma / eps_zz, -eps_xx / eps_zz))
}

/// Work `1/2 u^T K u` (J) of the linear response to the displacement field
/// `field(rest position)` prescribed on the boundary nodes.
fn boundary_work(
    material: Material,
    param: &dyn Parameterization,
    n: u32,
    field: impl Fn(&Vec3) -> Vec3,
) -> Result<f64, MaterialTestError> {
    let mut results = Vec::new();
    for sign in [1.0, -1.0] {
        let model = block_model(material, param, n)?;
        let rest = model.rest_positions().to_vec();
        let mut c = Constraints::none(model.num_nodes());
        // Boundary nodes of a block: on some face of its bounding box.
        let on_boundary =
            |p: &Vec3| (0..3).any(|d| p[d].abs() < 1e-12 || (p[d] - 1.0).abs() < 1e-12);
        for (i, p) in rest.iter().enumerate() {
            if on_boundary(p) {
                let u = field(p) * sign;
                c.hold(
                    &[i as u32],
                    Dofs::ALL,
                    Motion::Keyframes(vec![Keyframe {
                        time: 0.0,
                        displacement: [u.x, u.y, u.z],
                    }]),
                )?;
            }
        }
        let problem = Problem::new(model).with_constraints(c)?;
        let mut state = State::at_rest(problem.model());
        solve_static(&problem, &mut state, &static_opts())?;
        let mut f = vec![Vec3::zeros(); rest.len()];
        problem.model().internal_forces(&state.x, &mut f);
        results.push((state.displacements(problem.model()), f));
    }
    let (u_p, f_p) = &results[0];
    let (u_m, f_m) = &results[1];
    let mut w = 0.0;
    for i in 0..u_p.len() {
        let u = (u_p[i] - u_m[i]) * 0.5;
        let f = (f_p[i] - f_m[i]) * 0.5;
        w -= 0.5 * u.dot(&f);
    }
    Ok(w)
}

/// Pure shear: returns G (Pa).
pub fn shear_modulus(
    material: Material,
    param: &dyn Parameterization,
    n: u32,
) -> Result<f64, MaterialTestError> {
    let gamma = STRAIN;
    let w = boundary_work(material, param, n, |p| {
        Vec3::new(0.5 * gamma * p.z, 0.0, 0.5 * gamma * p.x)
    })?;
    Ok(2.0 * w / (gamma * gamma))
}

/// Uniform dilation: returns K (Pa).
pub fn bulk_modulus(
    material: Material,
    param: &dyn Parameterization,
    n: u32,
) -> Result<f64, MaterialTestError> {
    let eps = STRAIN;
    let w = boundary_work(material, param, n, |p| p * eps)?;
    Ok(2.0 * w / (9.0 * eps * eps))
}

/// Runs the three virtual tests on an `n^3` unit block.
///
/// ```
/// use mss_validate::material_test::measure_material;
/// use mss_core::model::PaperModel;
/// use mss_core::Material;
/// let m = Material::new(1000.0, 0.3, 1.0).unwrap();
/// let r = measure_material(m, &PaperModel, 2).unwrap();
/// assert!((r.young / 1000.0 - 1.0).abs() < 1e-6);
/// assert!((r.poisson - 0.3).abs() < 1e-6);
/// ```
pub fn measure_material(
    material: Material,
    param: &dyn Parameterization,
    n: u32,
) -> Result<MeasuredMaterial, MaterialTestError> {
    let (young, poisson) = uniaxial_tension(material, param, n)?;
    Ok(MeasuredMaterial {
        young,
        poisson,
        shear: shear_modulus(material, param, n)?,
        bulk: bulk_modulus(material, param, n)?,
    })
}
