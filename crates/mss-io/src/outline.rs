//! Outlines of 2D bodies: closed polylines in the plane written as SVG (for
//! documents and vector editors) and as OBJ line elements (Blender reads
//! them as edges). Both are written atomically.
//!
//! ```
//! use mss_io::outline::{write_outline_obj, write_outline_svg};
//!
//! let square = vec![vec![[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]]];
//! let dir = tempfile::tempdir().unwrap();
//! write_outline_svg(&dir.path().join("a.svg"), &square).unwrap();
//! write_outline_obj(&dir.path().join("a.obj"), &square).unwrap();
//! let svg = std::fs::read_to_string(dir.path().join("a.svg")).unwrap();
//! assert!(svg.contains("<path d=\"M 0 0 L 0.1 0 L 0.1 -0.1 L 0 -0.1 Z\""), "{svg}");
//! let obj = std::fs::read_to_string(dir.path().join("a.obj")).unwrap();
//! assert!(obj.contains("l 1 2 3 4 1"));
//! ```

use std::path::Path;

use crate::IoError;
use crate::atomic::write_atomic;

fn check(path: &Path, loops: &[Vec<[f64; 2]>]) -> Result<(), IoError> {
    if loops.iter().all(|l| l.is_empty()) {
        return Err(IoError::invalid(path, "the outline has no points"));
    }
    if let Some(p) = loops
        .iter()
        .flatten()
        .find(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(IoError::invalid(
            path,
            format!("an outline point is not finite: {p:?}"),
        ));
    }
    Ok(())
}

/// Writes closed `loops` (m, y up) as an SVG drawing at true size: one
/// `<path>` per loop, y turned down as SVG has it, the view box in metres
/// and the page in millimetres.
pub fn write_outline_svg(path: &Path, loops: &[Vec<[f64; 2]>]) -> Result<(), IoError> {
    check(path, loops)?;
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in loops.iter().flatten() {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let size = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9);
    let margin = 0.05 * size;
    let (x0, y0) = (lo[0] - margin, -hi[1] - margin);
    let (w, h) = (hi[0] - lo[0] + 2.0 * margin, hi[1] - lo[1] + 2.0 * margin);
    let stroke = size / 400.0;
    write_atomic(path, |out| {
        writeln!(
            out,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}mm\" height=\"{}mm\" viewBox=\"{x0} {y0} {w} {h}\">",
            w * 1e3,
            h * 1e3
        )?;
        for l in loops.iter().filter(|l| !l.is_empty()) {
            let mut d = String::new();
            for (i, p) in l.iter().enumerate() {
                let op = if i == 0 { "M" } else { " L" };
                // `-0` would print as "-0": keep zero positive.
                let y = if p[1] == 0.0 { 0.0 } else { -p[1] };
                d.push_str(&format!("{op} {} {y}", p[0]));
            }
            writeln!(
                out,
                "  <path d=\"{d} Z\" fill=\"none\" stroke=\"black\" stroke-width=\"{stroke}\"/>"
            )?;
        }
        writeln!(out, "</svg>")
    })
}

/// Writes closed `loops` (m) as OBJ vertices at z = 0 and one line element
/// (`l`) per loop, closed by repeating its first vertex.
pub fn write_outline_obj(path: &Path, loops: &[Vec<[f64; 2]>]) -> Result<(), IoError> {
    check(path, loops)?;
    write_atomic(path, |out| {
        writeln!(out, "# 2D MSS outline: {} loops", loops.len())?;
        for p in loops.iter().flatten() {
            writeln!(out, "v {} {} 0", p[0], p[1])?;
        }
        let mut first = 1usize;
        for l in loops.iter().filter(|l| !l.is_empty()) {
            let mut line = String::from("l");
            for k in 0..l.len() {
                line.push_str(&format!(" {}", first + k));
            }
            line.push_str(&format!(" {first}"));
            writeln!(out, "{line}")?;
            first += l.len();
        }
        Ok(())
    })
}
