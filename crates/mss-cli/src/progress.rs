//! Progress bars, timing and memory figures for the summaries.

use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A progress bar of `len` steps on stderr (hidden when `show` is false or
/// stderr is not a terminal), with rate and ETA.
pub fn bar(len: u64, what: &str, show: bool) -> ProgressBar {
    bar_of(len, what, "steps", show)
}

/// Like [`bar`], counting `unit` (e.g. "rows") in the rate.
pub fn bar_of(len: u64, what: &str, unit: &'static str, show: bool) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    let style = ProgressStyle::with_template(
        "{msg:>10} [{elapsed_precise}] {wide_bar} {pos}/{len} ({rate}, ETA {eta})",
    )
    .map(|s| {
        // indicatif's own {per_sec} prints four decimals; whole units read better.
        s.with_key(
            "rate",
            move |state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = write!(w, "{} {unit}/s", rate_text(state.per_sec()));
            },
        )
    })
    .unwrap_or_else(|_| ProgressStyle::default_bar());
    pb.set_style(style);
    pb.set_message(what.to_owned());
    pb
}

/// Voxelizes `mesh` behind a progress bar of the rows classified (with rate
/// and ETA), labelled `what`; the bar is cleared when voxelization ends.
/// The bar's length comes from the voxelizer's first report.
pub fn voxelize_with_bar(
    mesh: &hexmesh::TriMesh,
    opts: &hexmesh::VoxelizeOptions,
    what: &str,
    show: bool,
) -> Result<hexmesh::Voxelized, hexmesh::VoxelizeError> {
    let pb = bar_of(0, what, "rows", show);
    let hook = |done: u64, total: u64| {
        pb.set_length(total);
        pb.set_position(done);
    };
    let result = hexmesh::voxelize_with_progress(mesh, opts, &hook);
    pb.finish_and_clear();
    result
}

/// A rate as whole units, or with 2 significant digits below 10.
fn rate_text(per_sec: f64) -> String {
    if !per_sec.is_finite() {
        "-".to_owned()
    } else if per_sec >= 10.0 {
        format!("{per_sec:.0}")
    } else {
        format!("{per_sec:.2}")
    }
}

/// A spinner with elapsed time for work of unknown length.
pub fn spinner(what: &str, show: bool) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
    let style = ProgressStyle::with_template("{spinner} {msg} [{elapsed_precise}]")
        .unwrap_or_else(|_| ProgressStyle::default_spinner());
    pb.set_style(style);
    pb.set_message(what.to_owned());
    pb.enable_steady_tick(Duration::from_millis(100));
    pb
}

/// Peak resident memory of this process (bytes), from `VmHWM` in
/// `/proc/self/status`; `None` where that file does not exist.
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    parse_vm_hwm(&status)
}

fn parse_vm_hwm(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line
        .trim_start_matches("VmHWM:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb * 1024)
}

/// Bytes as a short human-readable size (binary units).
pub fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_vm_hwm() {
        let s = "Name:\tmss\nVmPeak:\t  2000 kB\nVmHWM:\t    1234 kB\nVmRSS:\t 1000 kB\n";
        assert_eq!(parse_vm_hwm(s), Some(1234 * 1024));
        assert_eq!(parse_vm_hwm("Name: x\n"), None);
        if cfg!(target_os = "linux") {
            assert!(peak_memory_bytes().unwrap() > 0);
        }
    }

    #[test]
    fn hidden_bar_voxelizes_like_the_library() {
        let mesh = hexmesh::generate::critter();
        let opts = hexmesh::VoxelizeOptions::default();
        let with_bar = voxelize_with_bar(&mesh, &opts, "voxelizing", false).unwrap();
        let plain = hexmesh::voxelize(&mesh, &opts).unwrap();
        assert_eq!(with_bar.lattice, plain.lattice);
    }

    #[test]
    fn rates_are_short() {
        assert_eq!(rate_text(5868.9112), "5869");
        assert_eq!(rate_text(2.3456), "2.35");
        assert_eq!(rate_text(f64::INFINITY), "-");
    }

    #[test]
    fn human_sizes() {
        assert_eq!(human_bytes(512), "512 B");
        assert_eq!(human_bytes(1536), "1.5 KiB");
        assert_eq!(human_bytes(3 << 20), "3.0 MiB");
    }
}
