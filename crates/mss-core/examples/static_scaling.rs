//! Cost of the static solve against lattice size: the small-load cantilever
//! 0.4 x 0.1 x 0.1 m (E = 1000 Pa, nu = 0.3, rho = 0.01 kg/m^3, gravity,
//! x = 0 clamped) on 4n x n x n cells, nonlinear static solve:
//!
//! `cargo run --release -p mss-core --example static_scaling -- N [MODEL] [auto|direct|iterative]`
//!
//! Prints CPU time (user + system, of this process), Newton and Krylov
//! iterations, peak memory and the tip deflection, one line per run. Run one
//! size per process so that the peak memory is that size's.
//!
//! `cargo run --release -p mss-core --example static_scaling -- sweep [MODEL...]`
//! runs 32x8x8, 64x16x16 and 128x32x32 for each model (default: all four)
//! in child processes, the two smaller sizes three times (the least CPU time
//! counts: they are short and the machine is noisy), and prints a table
//! with the cost exponent `ln(t / t0) / ln(nodes / nodes0)` against 32x8x8.

use std::time::Instant;

mod common;
use common::{cpu_seconds, peak_mib};

use mss_core::solver::{LinearSolverKind, State, StaticOptions, solve_static};

/// The CPU seconds and the whole line of one child run of `n` and `model`.
fn child_run(n: u32, model: &str) -> (f64, String) {
    let exe = std::env::current_exe().expect("the example's own path");
    let out = std::process::Command::new(exe)
        .args([n.to_string(), model.to_string()])
        .output()
        .expect("the example runs itself");
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    let line = text
        .lines()
        .find(|l| l.contains(" cpu "))
        .unwrap_or("no result")
        .to_string();
    let cpu = line
        .split(" cpu ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN);
    (cpu, line)
}

fn sweep(models: Vec<String>) {
    let models = if models.is_empty() {
        ["volumetric-barrier+hg", "paper", "springs", "volumetric"]
            .map(String::from)
            .to_vec()
    } else {
        models
    };
    println!("| model | 32x8x8 s | 64x16x16 s | 128x32x32 s | exponent 8->16 | 8->32 |");
    println!("|---|---|---|---|---|---|");
    for model in &models {
        let nodes = |n: u32| f64::from((4 * n + 1) * (n + 1) * (n + 1));
        let times: Vec<f64> = [8u32, 16, 32]
            .iter()
            .map(|&n| {
                let repeats = if n < 32 { 3 } else { 1 };
                (0..repeats)
                    .map(|_| {
                        let (cpu, line) = child_run(n, model);
                        eprintln!("{line}");
                        cpu
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        let exponent =
            |k: usize| (times[k] / times[0]).ln() / (nodes([8, 16, 32][k]) / nodes(8)).ln();
        println!(
            "| {model} | {:.2} | {:.2} | {:.2} | {:.3} | {:.3} |",
            times[0],
            times[1],
            times[2],
            exponent(1),
            exponent(2)
        );
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let first = args.next();
    if first.as_deref() == Some("sweep") {
        sweep(args.collect());
        return;
    }
    let n: u32 = first.and_then(|s| s.parse().ok()).unwrap_or(8);
    let name = args.next().unwrap_or_else(|| "paper".into());
    let kind = match args.next().as_deref() {
        Some("direct") => LinearSolverKind::Direct,
        Some("iterative") => LinearSolverKind::Iterative,
        _ => LinearSolverKind::Auto,
    };
    let gravity_scale: f64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let problem = common::cantilever(n, &name, 0.01, gravity_scale);
    let nodes = problem.model().num_nodes();
    let mut s = State::at_rest(problem.model());
    let opts = StaticOptions {
        linear_solver: kind,
        ..StaticOptions::default()
    };
    let (c0, t0) = (cpu_seconds(), Instant::now());
    let result = solve_static(&problem, &mut s, &opts);
    let (cpu, wall) = (cpu_seconds() - c0, t0.elapsed().as_secs_f64());
    let info = match result {
        Ok(info) => info,
        Err(e) => {
            // An answer too (the paper model's equilibrium is unstable on
            // fine lattices of this cantilever): say it with the cost.
            eprintln!(
                "{name} {}x{n}x{n} ({nodes} nodes, {kind:?}): cpu {cpu:.2} s, wall {wall:.2} s, peak {:.0} MiB: {e}",
                4 * n,
                peak_mib()
            );
            std::process::exit(1);
        }
    };
    let u = s.displacements(problem.model());
    let tip: f64 = {
        let tip_nodes: Vec<_> = (0..nodes)
            .filter(|&i| (problem.model().rest_positions()[i].x - 0.4).abs() < 1e-9)
            .collect();
        tip_nodes.iter().map(|&i| u[i].z).sum::<f64>() / tip_nodes.len() as f64
    };
    println!(
        "{name} {}x{n}x{n} ({nodes} nodes, {kind:?}): cpu {cpu:.3} s, wall {wall:.2} s, {} Newton iterations, {} linear solves ({} iterative, {} Krylov iterations), peak {:.0} MiB, tip {tip:.6e} m",
        4 * n,
        info.newton_iterations,
        info.linear.solves,
        info.linear.iterative_solves,
        info.linear.krylov_iterations,
        peak_mib()
    );
}
