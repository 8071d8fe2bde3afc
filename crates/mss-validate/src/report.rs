//! Experiment reports: Markdown sections, CSV tables, SVG line plots and VTU
//! files of the results computed by `crate::experiments`.
//!
//! Every file is written atomically. SVG plots are drawn directly (polylines,
//! axes with ticks, a legend; optional log-log axes), so no font or plotting
//! library is needed.
//!
//! ```
//! use mss_validate::report::{Series, svg_line_plot};
//! let dir = tempfile::tempdir().unwrap();
//! let p = dir.path().join("plot.svg");
//! let s = Series { label: "y = x^2".into(), points: vec![(1.0, 1.0), (2.0, 4.0)], dashed: false };
//! svg_line_plot(&p, "demo", "x", "y", &[s], false).unwrap();
//! assert!(std::fs::read_to_string(&p).unwrap().starts_with("<svg"));
//! ```

use std::fmt::Write as _;
use std::path::Path;

use crate::experiments::{BeamResult, LShapeResult, MaterialRow, Regime, RunResult, SceneResult};

use mss_io::IoError;
use mss_io::atomic::write_atomic;
use mss_io::vtk::{Field, LatticeFrame, VtuEncoding, write_vtu};

/// One curve of a plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// (x, y) points, drawn in order.
    pub points: Vec<(f64, f64)>,
    /// Draw dashed (e.g. theories) instead of solid with markers.
    pub dashed: bool,
}

const COLORS: [&str; 10] = [
    "#000000", "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2",
    "#17becf", "#7f7f7f",
];

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn nice_ticks(lo: f64, hi: f64, log: bool) -> Vec<f64> {
    if log {
        // 1, 2, 5 times powers of ten: short log ranges still get several ticks.
        let (a, b) = (lo.floor() as i32, hi.ceil() as i32);
        return (a..=b)
            .flat_map(|e| [1.0, 2.0, 5.0].map(|m: f64| m.log10() + e as f64))
            .collect();
    }
    let span = (hi - lo).max(1e-300);
    let raw = span / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| span / s <= 6.0)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + 1e-9 * step {
        out.push(t);
        t += step;
    }
    out
}

/// Writes an SVG line plot; `log_log` uses base-10 logarithmic axes (points
/// with non-positive coordinates are then skipped).
pub fn svg_line_plot(
    path: &Path,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    series: &[Series],
    log_log: bool,
) -> Result<(), IoError> {
    let tr = |v: f64| if log_log { v.log10() } else { v };
    let pts: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|s| {
            s.points
                .iter()
                .filter(|(x, y)| {
                    x.is_finite() && y.is_finite() && (!log_log || (*x > 0.0 && *y > 0.0))
                })
                .map(|&(x, y)| (tr(x), tr(y)))
                .collect()
        })
        .collect();
    let all: Vec<(f64, f64)> = pts.iter().flatten().copied().collect();
    if all.is_empty() {
        return Err(IoError::InvalidData {
            path: path.to_path_buf(),
            reason: "plot has no finite points".into(),
        });
    }
    let (mut x0, mut x1, mut y0, mut y1) = all.iter().fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), &(x, y)| (a.min(x), b.max(x), c.min(y), d.max(y)),
    );
    if !log_log {
        y0 = y0.min(0.0);
    }
    if x1 - x0 < 1e-12 {
        x0 -= 0.5;
        x1 += 0.5;
    }
    if y1 - y0 < 1e-300 {
        y0 -= 0.5;
        y1 += 0.5;
    }
    let pad = 0.05 * (y1 - y0);
    let (y0, y1) = (y0 - if log_log { pad } else { 0.0 }, y1 + pad);
    let (w, h, ml, mr, mt, mb) = (760.0, 480.0, 80.0, 230.0, 40.0, 55.0);
    let pw = w - ml - mr;
    let ph = h - mt - mb;
    let sx = |x: f64| ml + (x - x0) / (x1 - x0) * pw;
    let sy = |y: f64| mt + ph - (y - y0) / (y1 - y0) * ph;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="{w}" height="{h}" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="22" text-anchor="middle" font-size="15">{}</text>"#,
        ml + pw / 2.0,
        esc(title)
    );
    let _ = writeln!(
        s,
        r#"<rect x="{ml}" y="{mt}" width="{pw}" height="{ph}" fill="none" stroke="black"/>"#
    );
    let label = |v: f64| {
        if log_log {
            let x = 10f64.powf(v);
            let r = x.log10().floor();
            let digits = if r < 0.0 { (-r) as usize } else { 0 };
            format!("{x:.digits$}")
        } else {
            let a = v.abs();
            if a != 0.0 && !(1e-3..1e4).contains(&a) {
                format!("{v:.1e}")
            } else {
                format!("{}", (v * 1e6).round() / 1e6)
            }
        }
    };
    for t in nice_ticks(x0, x1, log_log) {
        if t < x0 - 1e-12 || t > x1 + 1e-12 {
            continue;
        }
        let x = sx(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x}" y1="{mt}" x2="{x}" y2="{}" stroke="#ddd"/><text x="{x}" y="{}" text-anchor="middle">{}</text>"##,
            mt + ph,
            mt + ph + 16.0,
            label(t)
        );
    }
    for t in nice_ticks(y0, y1, log_log) {
        if t < y0 - 1e-12 || t > y1 + 1e-12 {
            continue;
        }
        let y = sy(t);
        let _ = writeln!(
            s,
            r##"<line x1="{ml}" y1="{y}" x2="{}" y2="{y}" stroke="#ddd"/><text x="{}" y="{}" text-anchor="end">{}</text>"##,
            ml + pw,
            ml - 6.0,
            y + 4.0,
            label(t)
        );
    }
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
        ml + pw / 2.0,
        h - 12.0,
        esc(xlabel)
    );
    let _ = writeln!(
        s,
        r#"<text x="16" y="{}" text-anchor="middle" transform="rotate(-90 16 {})">{}</text>"#,
        mt + ph / 2.0,
        mt + ph / 2.0,
        esc(ylabel)
    );
    for (i, (ser, p)) in series.iter().zip(&pts).enumerate() {
        let c = COLORS[i % COLORS.len()];
        let poly: Vec<String> = p
            .iter()
            .map(|&(x, y)| format!("{:.2},{:.2}", sx(x), sy(y)))
            .collect();
        let dash = if ser.dashed {
            r#" stroke-dasharray="6,4""#
        } else {
            ""
        };
        let _ = writeln!(
            s,
            r#"<polyline fill="none" stroke="{c}" stroke-width="1.6"{dash} points="{}"/>"#,
            poly.join(" ")
        );
        if !ser.dashed && p.len() <= 80 {
            for &(x, y) in p {
                let _ = writeln!(
                    s,
                    r#"<circle cx="{:.2}" cy="{:.2}" r="2.5" fill="{c}"/>"#,
                    sx(x),
                    sy(y)
                );
            }
        }
        let ly = mt + 10.0 + 18.0 * i as f64;
        let lx = ml + pw + 12.0;
        let _ = writeln!(
            s,
            r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{c}" stroke-width="2"{dash}/><text x="{}" y="{}">{}</text>"#,
            lx + 24.0,
            lx + 30.0,
            ly + 4.0,
            esc(&ser.label)
        );
    }
    s.push_str("</svg>\n");
    write_atomic(path, |w| w.write_all(s.as_bytes()))
}

/// Writes a CSV file (no quoting needed: callers pass plain tokens).
pub fn write_csv(path: &Path, header: &[&str], rows: &[Vec<String>]) -> Result<(), IoError> {
    let mut s = header.join(",");
    s.push('\n');
    for r in rows {
        s.push_str(&r.join(","));
        s.push('\n');
    }
    write_atomic(path, |w| w.write_all(s.as_bytes()))
}

/// Writes a text file (e.g. the Markdown report) atomically.
pub fn write_text(path: &Path, text: &str) -> Result<(), IoError> {
    write_atomic(path, |w| w.write_all(text.as_bytes()))
}

/// Writes a run as `.vtu` on the deformed MSS positions, with the MSS and
/// reference displacements, their difference and the per-node error (%).
pub fn write_run_vtu(path: &Path, run: &RunResult) -> Result<(), IoError> {
    let rest = run.lattice.nodes();
    let u: Vec<[f64; 3]> = run.u.iter().map(|v| [v.x, v.y, v.z]).collect();
    let ur: Vec<[f64; 3]> = run.u_ref.iter().map(|v| [v.x, v.y, v.z]).collect();
    let d: Vec<[f64; 3]> = run
        .u
        .iter()
        .zip(&run.u_ref)
        .map(|(a, b)| [a.x - b.x, a.y - b.y, a.z - b.z])
        .collect();
    let pts: Vec<[f64; 3]> = rest
        .iter()
        .zip(&u)
        .map(|(p, v)| [p[0] + v[0], p[1] + v[1], p[2] + v[2]])
        .collect();
    let frame = LatticeFrame::new(&pts, run.lattice.cells())
        .with_point_field(Field::vectors("u_mss", &u))
        .with_point_field(Field::vectors("u_fem", &ur))
        .with_point_field(Field::vectors("u_mss_minus_fem", &d))
        .with_point_field(Field::scalars("error_percent", &run.node_error));
    write_vtu(path, &frame, VtuEncoding::default())
}

fn dims(d: [u32; 3]) -> String {
    format!("{}x{}x{}", d[0], d[1], d[2])
}

/// Table of M / SD / MAX per model and resolution (Markdown).
pub fn stats_table(runs: &[RunResult], resolution_label: &dyn Fn(&RunResult) -> String) -> String {
    let mut s = String::from(
        "| model | lattice | h (m) | M % | SD % | MAX % | MSS solve (s) |\n|---|---|---|---|---|---|---|\n",
    );
    for r in runs {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} |",
            r.model,
            resolution_label(r),
            r.h,
            r.stats.mean,
            r.stats.sd,
            r.stats.max,
            r.seconds
        );
    }
    s
}

fn stats_rows(runs: &[RunResult], label: &dyn Fn(&RunResult) -> String) -> Vec<Vec<String>> {
    runs.iter()
        .map(|r| {
            vec![
                r.model.clone(),
                label(r),
                format!("{}", r.h),
                format!("{:.6}", r.stats.mean),
                format!("{:.6}", r.stats.sd),
                format!("{:.6}", r.stats.max),
                format!("{:.6e}", r.monitor.x),
                format!("{:.6e}", r.monitor.y),
                format!("{:.6e}", r.monitor.z),
            ]
        })
        .collect()
}

const STATS_HEADER: [&str; 9] = [
    "model",
    "lattice",
    "h_m",
    "mean_pct",
    "sd_pct",
    "max_pct",
    "monitor_ux",
    "monitor_uy",
    "monitor_uz",
];

/// How a reference was computed, for the reports: law, grid, extrapolation
/// (from the half `halved`, "resolution" or "refinement") and time.
fn reference_phrase(info: &crate::experiments::ReferenceInfo, halved: &str) -> String {
    format!(
        "Q1 FEM ({:?}) on {} cells{}, {:.1} s",
        info.law,
        dims(info.fine_dims),
        if info.richardson {
            format!(", Richardson-extrapolated with the half {halved}")
        } else {
            String::new()
        },
        info.seconds
    )
}

fn error_plot(path: &Path, title: &str, runs: &[RunResult]) -> Result<(), IoError> {
    let mut models: Vec<&str> = runs.iter().map(|r| r.model.as_str()).collect();
    models.dedup();
    let mut series = Vec::new();
    for m in models {
        for (what, f) in [("M", 0usize), ("MAX", 1)] {
            series.push(Series {
                label: format!("{m} {what}"),
                points: runs
                    .iter()
                    .filter(|r| r.model == m)
                    .map(|r| (r.h, if f == 0 { r.stats.mean } else { r.stats.max }))
                    .collect(),
                dashed: f == 1,
            });
        }
    }
    svg_line_plot(
        path,
        title,
        "cell edge h (m)",
        "error (% of max |u_ref|)",
        &series,
        true,
    )
}

/// Writes the beam experiment's CSV, SVG and VTU files into `dir` (names
/// starting with `prefix`) and returns its Markdown section; images are linked
/// as `link_prefix` + file name.
pub fn beam_section(
    r: &BeamResult,
    dir: &Path,
    prefix: &str,
    link_prefix: &str,
    title: &str,
) -> Result<String, IoError> {
    let st = &r.settings;
    let label = |x: &RunResult| dims(x.dims);
    write_csv(
        &dir.join(format!("{prefix}_errors.csv")),
        &STATS_HEADER,
        &stats_rows(&r.runs, &label),
    )?;
    let mut curve_rows = Vec::new();
    for c in &r.curves {
        for &(x, w) in &c.points {
            curve_rows.push(vec![
                c.label.replace(',', ";"),
                format!("{x}"),
                format!("{w:.8e}"),
            ]);
        }
    }
    write_csv(
        &dir.join(format!("{prefix}_deflection.csv")),
        &["curve", "x_m", "w_m"],
        &curve_rows,
    )?;
    // One deflection figure per model: all resolutions of one model against
    // the reference and the beam theories (all models in one would be a tangle).
    let mut models: Vec<&str> = r.runs.iter().map(|run| run.model.as_str()).collect();
    models.dedup();
    let mut curve_svgs = Vec::new();
    for model in models {
        let own = format!("{model} ");
        let series: Vec<Series> = r
            .curves
            .iter()
            .filter(|c| {
                c.label.starts_with(&own)
                    || !r.runs.iter().any(|run| c.label.starts_with(&run.model))
            })
            .map(|c| Series {
                label: c.label.clone(),
                points: c.points.clone(),
                dashed: c.label.starts_with("Euler") || c.label.starts_with("Timoshenko"),
            })
            .collect();
        let curve_svg = format!("{prefix}_deflection_{}.svg", model.replace('+', "_"));
        svg_line_plot(
            &dir.join(&curve_svg),
            &format!("{title}: neutral-axis deflection ({model})"),
            "x (m)",
            "deflection w (m, downwards)",
            &series,
            false,
        )?;
        curve_svgs.push(curve_svg);
    }
    let err_svg = format!("{prefix}_errors.svg");
    error_plot(
        &dir.join(&err_svg),
        &format!("{title}: error vs cell size"),
        &r.runs,
    )?;
    let mut vtus = Vec::new();
    for run in &r.runs {
        let name = format!("{prefix}_{}_{}.vtu", run.model, dims(run.dims));
        write_run_vtu(&dir.join(&name), run)?;
        vtus.push(name);
    }
    let info = &r.reference;
    let mut s = String::new();
    let _ = writeln!(s, "## {title}\n");
    let _ = writeln!(
        s,
        "Cantilever 0.4 x 0.1 x 0.1 m along x, x = 0 clamped, gravity 9.81 m/s^2 along -z, {}, nu = {}, rho = {} kg/m^3 ({}).\n",
        match st.second_half_young {
            None => "E = 1000 Pa".to_owned(),
            Some(e) => format!(
                "E = 1000 Pa for x < 0.2 m and {e} Pa for x > 0.2 m (per-cell materials in the MSS \
                 and in the FEM; the beam theories integrate the stepped stiffness)"
            ),
        },
        st.poisson,
        st.density,
        st.regime.label()
    );
    let _ = writeln!(
        s,
        "Reference: {}. Mean tip deflection: FEM fine {:.5e} m, reference {:.5e} m; Euler-Bernoulli {:.5e} m, Timoshenko (kappa = 5/6) {:.5e} m (linear theories).\n",
        reference_phrase(info, "resolution"),
        -info.monitor_fine.z,
        -info.monitor_ref.z,
        r.euler_bernoulli_tip,
        r.timoshenko_tip
    );
    s.push_str(&stats_table(&r.runs, &label));
    s.push('\n');
    let _ = writeln!(
        s,
        "| model | lattice | mean tip deflection (m) | vs reference |\n|---|---|---|---|"
    );
    for run in &r.runs {
        let _ = writeln!(
            s,
            "| {} | {} | {:.5e} | {:+.2} % |",
            run.model,
            dims(run.dims),
            -run.monitor.z,
            (run.monitor.z / info.monitor_ref.z - 1.0) * 100.0
        );
    }
    s.push('\n');
    for curve_svg in &curve_svgs {
        let _ = writeln!(s, "![deflection]({link_prefix}{curve_svg})\n");
    }
    let _ = writeln!(s, "![errors]({link_prefix}{err_svg})\n");
    let _ = writeln!(
        s,
        "Files: `{prefix}_errors.csv`, `{prefix}_deflection.csv`, VTU (MSS and FEM displacements and their difference): {}.\n",
        vtus.iter()
            .map(|v| format!("`{v}`"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(s)
}

/// Writes the L-shape experiment's files and returns its Markdown section.
pub fn lshape_section(
    r: &LShapeResult,
    dir: &Path,
    prefix: &str,
    link_prefix: &str,
) -> Result<String, IoError> {
    let label = |x: &RunResult| format!("{} per 2 m (h = {} m)", x.dims[0] / 2, x.h);
    write_csv(
        &dir.join(format!("{prefix}_errors.csv")),
        &STATS_HEADER,
        &stats_rows(&r.runs, &|x: &RunResult| format!("{}", x.dims[0] / 2)),
    )?;
    let err_svg = format!("{prefix}_errors.svg");
    error_plot(&dir.join(&err_svg), "L-shape: error vs cell size", &r.runs)?;
    for run in &r.runs {
        let name = format!("{prefix}_{}_{}.vtu", run.model, run.dims[0] / 2);
        write_run_vtu(&dir.join(&name), run)?;
    }
    let info = &r.reference;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Load: {} ({} Pa). Reference: {}; mean displacement of the top face: {:.4e}, {:.4e}, {:.4e} m.\n",
        r.settings.load.describe(),
        r.settings.traction,
        reference_phrase(info, "resolution"),
        info.monitor_ref.x,
        info.monitor_ref.y,
        info.monitor_ref.z
    );
    s.push_str(&stats_table(&r.runs, &label));
    let _ = writeln!(s, "\n![L errors]({link_prefix}{err_svg})\n");
    Ok(s)
}

/// Writes the material table as CSV and returns it as Markdown.
pub fn material_section(rows: &[MaterialRow], dir: &Path, file: &str) -> Result<String, IoError> {
    let csv: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                r.model.clone(),
                format!("{}", r.poisson),
                format!("{:.9}", r.measured.young),
                format!("{:.9}", r.measured.poisson),
                format!("{:.9}", r.measured.shear),
                format!("{:.9}", r.measured.bulk),
                format!("{:.9}", r.exact_shear),
                format!("{:.9}", r.exact_bulk),
            ]
        })
        .collect();
    write_csv(
        &dir.join(file),
        &[
            "model",
            "nu_input",
            "E_measured",
            "nu_measured",
            "G_measured",
            "K_measured",
            "G_exact",
            "K_exact",
        ],
        &csv,
    )?;
    let mut s = String::from(
        "| model | nu input | E measured (Pa) | nu measured | G measured / exact | K measured / exact |\n|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {:.4} | {:.4} | {:.4} / {:.4} | {:.4} / {:.4} |",
            r.model,
            r.poisson,
            r.measured.young,
            r.measured.poisson,
            r.measured.shear,
            r.exact_shear,
            r.measured.bulk,
            r.exact_bulk
        );
    }
    Ok(s)
}

/// Label of a regime for report headings.
pub fn regime_title(r: Regime) -> &'static str {
    r.label()
}

/// The section of a scene comparison (`mss experiment scene`): writes
/// `{prefix}_errors.csv` and one `{prefix}_{model}.vtu` per model (MSS and FEM
/// displacements and their difference) into `dir` and returns the Markdown.
pub fn scene_section(
    r: &SceneResult,
    dir: &Path,
    prefix: &str,
    title: &str,
) -> Result<String, IoError> {
    let label = |x: &RunResult| dims(x.dims);
    let csv = format!("{prefix}_errors.csv");
    write_csv(&dir.join(&csv), &STATS_HEADER, &stats_rows(&r.runs, &label))?;
    let mut files = Vec::new();
    for run in &r.runs {
        let name = format!("{prefix}_{}.vtu", run.model);
        write_run_vtu(&dir.join(&name), run)?;
        files.push(format!("`{name}`"));
    }
    let info = &r.reference;
    let mut s = String::new();
    let _ = writeln!(s, "## {title}\n");
    let regime = match r.auto_ratio {
        Some(q) => format!(
            "{} (chosen automatically: the linear reference's largest displacement is {:.3} % of the body's diagonal)",
            r.regime.label(),
            100.0 * q
        ),
        None => r.regime.label().to_string(),
    };
    let _ = writeln!(
        s,
        "Regime: {regime}. Reference: {}. Mean displacement over the lattice nodes: FEM fine {:.5e}, {:.5e}, {:.5e} m; reference {:.5e}, {:.5e}, {:.5e} m.\n",
        reference_phrase(info, "refinement"),
        info.monitor_fine.x,
        info.monitor_fine.y,
        info.monitor_fine.z,
        info.monitor_ref.x,
        info.monitor_ref.y,
        info.monitor_ref.z
    );
    s.push_str(&stats_table(&r.runs, &label));
    let _ = writeln!(
        s,
        "\nFiles: `{csv}` (monitor = mean displacement over all nodes), VTU (MSS and FEM displacements and their difference): {}.\n",
        files.join(", ")
    );
    Ok(s)
}
