//! What the benchmark examples share: the cantilever they solve and what
//! they measure about their own process.

// Each example uses only some of these.
#![allow(dead_code)]

pub mod frames;

/// CPU time of this process so far (user + system, seconds), from
/// `/proc/self/stat`; NaN where that file does not exist.
pub fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the command name, which is in parentheses and may hold spaces.
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map_or(vec![], |(_, r)| r.split_whitespace().collect());
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|s| s.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    // utime and stime, in clock ticks of 1/100 s on Linux.
    (ticks(11) + ticks(12)) / 100.0
}

/// Peak resident memory of this process (MiB), from `VmHWM`.
pub fn peak_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// The cantilever of the experiments: 0.4 x 0.1 x 0.1 m along x on 4n x n x n
/// cells, E = 1000 Pa, nu = 0.3, density `rho`, x = 0 clamped, gravity
/// `9.81 * gravity_scale` along -z, with the parameterization called `model`.
pub fn cantilever(n: u32, model: &str, rho: f64, gravity_scale: f64) -> mss_core::solver::Problem {
    use mss_core::constraints::{ConstraintSpec, Face, NodeSelector};
    use mss_core::loads::{Damping, LoadSpec};
    let lattice = hexmesh::Lattice::block([4 * n, n, n], 0.1 / n as f64, [0.0; 3]).unwrap();
    let param = mss_core::Parameterizations::default()
        .get(model)
        .unwrap_or_else(|e| panic!("{e}"));
    let model = mss_core::Model::new(
        &lattice,
        mss_core::Material::new(1000.0, 0.3, rho).unwrap(),
        param.as_ref(),
    )
    .unwrap();
    mss_core::solver::Problem::from_specs(
        model,
        &[ConstraintSpec::fixed(NodeSelector::face(Face::XMin))],
        &[LoadSpec::Gravity {
            g: [0.0, 0.0, -9.81 * gravity_scale],
        }],
        Damping::NONE,
    )
    .unwrap()
}
