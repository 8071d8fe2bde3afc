//! Times the large-deflection cantilever's nonlinear static MSS solve
//! (0.4 x 0.1 x 0.1 m, total mass 0.0125 kg, x = 0 clamped, gravity):
//! `cargo run --release -p mss-core --example large_static -- N [MODEL]`
//! with N cells across the thickness (4 = 16x4x4, 8 = 32x8x8).

use std::time::Instant;

mod common;

use mss_core::solver::{State, StaticOptions, solve_static};

/// Prints the solver's debug messages when `MSS_LOG` is set.
struct Logger;

impl log::Log for Logger {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::max_level() && m.target().starts_with("mss_core")
    }
    fn log(&self, r: &log::Record) {
        if self.enabled(r.metadata()) {
            eprintln!("{}", r.args());
        }
    }
    fn flush(&self) {}
}

fn main() {
    if let Some(level) = std::env::var_os("MSS_LOG") {
        let _ = log::set_logger(&Logger);
        log::set_max_level(if level == "trace" {
            log::LevelFilter::Trace
        } else {
            log::LevelFilter::Debug
        });
    }
    let mut args = std::env::args().skip(1);
    let n: u32 = args.next().and_then(|s| s.parse().ok()).unwrap_or(4);
    let name = args.next().unwrap_or_else(|| "paper".into());
    let problem = common::cantilever(n, &name, 3.125, 1.0);
    let mut s = State::at_rest(problem.model());
    let opts = StaticOptions {
        rtol: 1e-10,
        ..StaticOptions::default()
    };
    let t = Instant::now();
    let info = solve_static(&problem, &mut s, &opts).unwrap();
    let u = s.displacements(problem.model());
    let tip = u.iter().map(|v| v.z).fold(0.0, f64::min);
    println!(
        "{name} {}x{n}x{n}: {:.2} s, {} Newton iterations (+{} rejected), {} load steps, residual {:.2e}, max downward deflection {:.5} m",
        4 * n,
        t.elapsed().as_secs_f64(),
        info.newton_iterations,
        info.rejected_iterations,
        info.load_steps,
        info.relative_residual,
        -tip
    );
}
