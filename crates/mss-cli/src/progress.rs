//! Progress bars, timing and memory figures for the summaries.

use std::time::Duration;

use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use mss_scene::Progress;

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

/// Turns a job's [`Progress`] reports into progress bars on stderr: a bar of
/// rows while voxelizing, a spinner during a static solve, a bar of steps
/// while time stepping (with rate and ETA). Each bar is cleared when its
/// stage ends, and [`JobBars::clear`] clears whatever is shown (before an
/// error is printed).
pub struct JobBars {
    label: String,
    show: bool,
    current: Mutex<Option<(Stage, ProgressBar)>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    Voxelizing,
    Solving,
    Stepping,
}

impl JobBars {
    /// Bars labelled with the mesh or scene `label`; hidden unless `show`.
    pub fn new(label: &str, show: bool) -> Self {
        Self {
            label: label.to_owned(),
            show,
            current: Mutex::new(None),
        }
    }

    /// Shows one report.
    pub fn report(&self, p: Progress) {
        let mut current = self.current.lock().unwrap_or_else(|e| e.into_inner());
        let stage = match p {
            Progress::Voxelizing { .. } => Stage::Voxelizing,
            Progress::Solving => Stage::Solving,
            Progress::Stepping { .. } => Stage::Stepping,
            Progress::StageDone => {
                if let Some((_, bar)) = current.take() {
                    bar.finish_and_clear();
                }
                return;
            }
        };
        if current.as_ref().map(|(s, _)| *s) != Some(stage) {
            if let Some((_, bar)) = current.take() {
                bar.finish_and_clear();
            }
            let bar = match stage {
                Stage::Voxelizing => {
                    bar_of(0, &format!("voxelizing {}", self.label), "rows", self.show)
                }
                Stage::Solving => spinner("static solve", self.show),
                Stage::Stepping => bar(0, "steps", self.show),
            };
            *current = Some((stage, bar));
        }
        if let Some((_, bar)) = current.as_ref() {
            match p {
                Progress::Voxelizing { done, total } | Progress::Stepping { done, total } => {
                    bar.set_length(total);
                    bar.set_position(done);
                }
                _ => {}
            }
        }
    }

    /// Clears the bar being shown, if any.
    pub fn clear(&self) {
        self.report(Progress::StageDone);
    }
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

/// A length with 4 significant digits in m or mm, and in exponent form
/// below a millimetre (a 1e-12 m cell is not "0.0000 m").
pub fn human_length(metres: f64) -> String {
    let a = metres.abs();
    if a == 0.0 || !a.is_finite() {
        format!("{metres} m")
    } else if a >= 1.0 {
        format!("{metres:.4} m")
    } else if a >= 1e-3 {
        format!("{:.3} mm", metres * 1e3)
    } else {
        format!("{metres:.3e} m")
    }
}

/// Bytes as a short human-readable size (binary units), as the library's
/// messages write them.
pub fn human_bytes(bytes: u64) -> String {
    mss_scene::error::human(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hidden_bars_follow_the_stages() {
        let bars = JobBars::new("mesh", false);
        bars.report(Progress::Voxelizing { done: 1, total: 4 });
        bars.report(Progress::Stepping { done: 3, total: 10 });
        {
            let current = bars.current.lock().unwrap();
            let (stage, bar) = current.as_ref().unwrap();
            assert_eq!(*stage, Stage::Stepping);
            assert_eq!((bar.position(), bar.length()), (3, Some(10)));
        }
        bars.clear();
        assert!(bars.current.lock().unwrap().is_none());
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
        assert_eq!(human_length(0.0087), "8.700 mm");
        assert_eq!(human_length(1e-12), "1.000e-12 m");
        assert_eq!(human_length(2.5), "2.5000 m");
        assert_eq!(human_bytes(1536), "1.5 KiB");
        assert_eq!(human_bytes(3 << 20), "3.0 MiB");
    }
}
