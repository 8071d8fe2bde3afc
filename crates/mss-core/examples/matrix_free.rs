//! Matrix-free or assembled: the cost of the Newton tangent's action on a
//! vector, `cargo run --release -p mss-core --example matrix_free -- N [MODEL] [REPEATS]`.
//!
//! On the 4N x N x N cantilever lattice at a deformed state (stretched,
//! sheared, jittered: every term at work) it times, on the current thread
//! pool (`RAYON_NUM_THREADS=1` for one thread), the minimum over REPEATS
//! (default 5) of:
//! - the assembly of the tangent (`Model::tangent`), once per Newton step;
//! - the assembled product (`BlockCsr::mul_vec`, `f64` blocks), what each
//!   Krylov iteration multiplies by (the V-cycle's smoothing products read
//!   a single-precision copy, half these bytes);
//! - the matrix-free action (`Model::tangent_mul`, the force kernel on dual
//!   numbers), which needs no matrix at all.
//!
//! and prints the matrix's bytes per node. docs/solvers.md ("Matrix-free or
//! assembled") keeps the figures and the choice they led to.

use std::time::Instant;

mod common;
// Only its deformed state is used here.
#[allow(dead_code)]
#[path = "common/baseline.rs"]
mod baseline;
use baseline::perturbed;

use mss_core::Vec3;

fn main() {
    let mut args = std::env::args().skip(1);
    let n: u32 = args.next().and_then(|s| s.parse().ok()).unwrap_or(16);
    let name = args
        .next()
        .unwrap_or_else(|| "volumetric-barrier+hg".into());
    let repeats: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(5);
    let problem = common::cantilever(n, &name, 0.01, 1.0);
    let model = problem.model();
    let nodes = model.num_nodes();
    let x = perturbed(model);
    let v: Vec<Vec3> = (0..nodes)
        .map(|i| {
            let t = i as f64;
            Vec3::new((0.7 * t).sin(), (1.3 * t).cos(), (0.4 * t).sin())
        })
        .collect();
    let best = |f: &mut dyn FnMut()| {
        (0..repeats)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min)
    };
    let mut tangent = model.tangent(&x);
    let assembly = best(&mut || tangent = model.tangent(&x));
    let mut assembled = vec![Vec3::zeros(); nodes];
    let product = best(&mut || tangent.mul_vec(&v, &mut assembled));
    let mut free = vec![Vec3::zeros(); nodes];
    let action = best(&mut || model.tangent_mul(&x, &v, &mut free));
    let scale = assembled.iter().map(|f| f.amax()).fold(0.0, f64::max);
    let gap = assembled
        .iter()
        .zip(&free)
        .map(|(a, b)| (a - b).amax())
        .fold(0.0, f64::max);
    let bytes = tangent.blocks.len() * std::mem::size_of::<mss_core::Mat3>()
        + tangent.col_indices.len() * 4
        + tangent.row_offsets.len() * 4;
    let ns = |s: f64| 1e9 * s / nodes as f64;
    // How many products the assembly's cost buys back, when the action is
    // the slower one; when it is the faster, the matrix never pays.
    let break_even = if action > product {
        format!(
            "{:.1} products pay for an assembly",
            assembly / (action - product)
        )
    } else {
        "no assembly pays".to_string()
    };
    println!(
        "{name} {}x{n}x{n} ({nodes} nodes, {} threads): assembly {:.2} ms ({:.0} ns/node), \
         assembled product {:.3} ms ({:.1} ns/node, matrix {:.0} B/node), \
         matrix-free action {:.3} ms ({:.1} ns/node, {:.1} x the product; {}), \
         largest difference {:.1e} of {:.1e}",
        4 * n,
        rayon::current_num_threads(),
        1e3 * assembly,
        ns(assembly),
        1e3 * product,
        ns(product),
        bytes as f64 / nodes as f64,
        1e3 * action,
        ns(action),
        action / product,
        break_even,
        gap,
        scale
    );
}
