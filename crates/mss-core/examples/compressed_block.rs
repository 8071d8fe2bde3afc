//! A free block compressed along z to a fraction of its height and released
//! (the robustness suite's last scene, docs/robustness.md): every model,
//! explicit, 0.5 s, no supports and no gravity.
//!
//! `cargo run --release -p mss-core --example compressed_block -- [FRACTION [CELLS]]`

use hexmesh::Lattice;
use mss_core::loads::Damping;
use mss_core::solver::{Explicit, ExplicitOptions, Integrator, Problem, State};
use mss_core::{Material, Model, Parameterizations};

fn main() {
    let fraction: f64 = std::env::args()
        .nth(1)
        .map_or(0.3, |a| a.parse().expect("a fraction"));
    let n: u32 = std::env::args()
        .nth(2)
        .map_or(8, |a| a.parse().expect("cells per side"));
    let lattice = Lattice::block([n, n, n], 0.01, [0.0; 3]).unwrap();
    let known = Parameterizations::default();
    for name in [
        "paper",
        "springs",
        "volumetric",
        "volumetric-barrier",
        "paper+hg",
        "volumetric-barrier+hg",
    ] {
        let param = known
            .build(name, name.ends_with("+hg").then_some(1.0))
            .unwrap();
        let material = Material::new(1.0e4, 0.45, 1000.0).unwrap();
        let model = Model::new(&lattice, material, &*param).unwrap();
        let problem = Problem::new(model)
            .with_damping(Damping {
                alpha: 5.0,
                beta: 0.0,
            })
            .unwrap();
        let model = problem.model();
        let mut state = State::at_rest(model);
        for x in &mut state.x {
            x.z *= fraction;
        }
        let mut integ = Explicit::new(&problem, ExplicitOptions::default()).unwrap();
        let mut outcome = "ran to 0.5 s".to_owned();
        let mut max_substeps = 1;
        while state.time < 0.5 - 1e-12 {
            match integ.step(&problem, &mut state) {
                Ok(info) => max_substeps = max_substeps.max(info.substeps),
                Err(e) => {
                    outcome = format!("failed: {e}");
                    break;
                }
            }
        }
        let min_j = model
            .cell_diagnostics(&state.x)
            .iter()
            .map(|d| 1.0 + d.volumetric_strain)
            .fold(f64::MAX, f64::min);
        println!(
            "{name:24} {outcome:.120}; t {:.3} s, min J {min_j:.3}, up to {max_substeps} sub-steps",
            state.time
        );
    }
}
