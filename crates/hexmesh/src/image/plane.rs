//! A label image of one slice as a 2D body: rectangles of the paper's 2D
//! element, and the chosen pixels' boundary as the outline they carry.
//!
//! The slice must lie in a plane `z = const` once its voxel-to-metre map
//! is applied (its pixels' axes have no z component; a scene's `rotate`
//! brings a sagittal or coronal slice there); the body is placed at
//! `z = 0`. Then, as the 3D resampling does for cubes:
//!
//! 1. each chosen pixel is cut into `m_i x m_j` pieces, `m_a = ceil(2 s_a /
//!    c)` (`s_a` its spacing, `c` the shorter cell side), each giving its
//!    area to the rectangle holding its centre and to that rectangle's
//!    tally of its label;
//! 2. a rectangle is kept when the chosen labels cover at least
//!    `threshold` of it, and takes the label with the largest share (ties:
//!    the smaller label);
//! 3. by default only the largest edge-connected group of rectangles is
//!    kept (stray pixels of a segmentation would be free bodies).
//!
//! The outline is the chosen pixels' boundary: closed loops of pixel sides
//! (collinear runs merged), holes included, which the even-odd rule of
//! [`Outline`] reads as the shape. One sequential pass; no sum depends on
//! threads.

use std::collections::{BTreeMap, HashMap};

use super::LabelImage;
use super::resample::LabelChoice;
use crate::plane::{Outline, PlaneError, RectLattice, fitted_grid};
use crate::voxelize::ComponentPolicy;

/// Why a label image does not make a 2D body.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum PlaneImageError {
    /// The image has more than one slice.
    #[error(
        "the image has {0} slices (dims {1:?}); a 2D body takes a label image of one slice (a 2D NIfTI or NRRD, or a volume of depth 1)"
    )]
    NotASlice(usize, [usize; 3]),
    /// The slice is not parallel to the x-y plane.
    #[error(
        "the slice is not in an x-y plane once placed (its pixel axes reach z by {0:.3e} m); turn it there with [image] rotate (a sagittal slice: rotate = [0, 90, 0] or [90, 0, 0])"
    )]
    NotInPlane(f64),
    /// No pixel carries a chosen label.
    #[error("no pixel carries a chosen label (labels and pixels in the image: {0:?})")]
    NoLabel(Vec<(i32, usize)>),
    /// The threshold is out of range.
    #[error("threshold {0} must be in (0, 1]")]
    Threshold(f64),
    /// The grid or the lattice.
    #[error(transparent)]
    Plane(#[from] PlaneError),
}

/// A one-slice label image as a 2D body.
#[derive(Debug, Clone)]
pub struct PlaneImage {
    /// The chosen pixels' boundary (m, in the plane).
    pub outline: Outline,
    /// Labels chosen and the pixels carrying each.
    pub pixels_per_label: Vec<(i32, usize)>,
}

/// The map of a slice's pixel indices `(i, j)` to the plane (m): rows x and
/// y of `voxel_to_metres` without the k column, checked to stay in a plane
/// of constant z.
pub fn slice_to_plane(
    image: &LabelImage,
    voxel_to_metres: &[[f64; 4]; 3],
) -> Result<[[f64; 3]; 2], PlaneImageError> {
    if image.dims[2] != 1 {
        return Err(PlaneImageError::NotASlice(image.dims[2], image.dims));
    }
    let a = voxel_to_metres;
    let spacing = |c: usize| (0..3).map(|r| a[r][c] * a[r][c]).sum::<f64>().sqrt();
    let reach_z = a[2][0].abs().max(a[2][1].abs());
    if reach_z > 1e-9 * spacing(0).max(spacing(1)) {
        return Err(PlaneImageError::NotInPlane(reach_z));
    }
    Ok([[a[0][0], a[0][1], a[0][3]], [a[1][0], a[1][1], a[1][3]]])
}

/// The chosen pixels of a one-slice `image` and their boundary as an
/// outline, placed by `map` (from [`slice_to_plane`]).
pub fn pixel_outline(
    image: &LabelImage,
    labels: Option<&[i32]>,
    map: &[[f64; 3]; 2],
) -> Result<PlaneImage, PlaneImageError> {
    let sorted = sorted_labels(labels);
    let choice = LabelChoice(sorted.as_deref());
    let [nx, ny, _] = image.dims;
    let chosen = |i: i64, j: i64| {
        i >= 0
            && j >= 0
            && (i as usize) < nx
            && (j as usize) < ny
            && choice.contains(image.labels[i as usize + nx * j as usize])
    };
    let mut counts: BTreeMap<i32, usize> = BTreeMap::new();
    for &l in &image.labels {
        if choice.contains(l) {
            *counts.entry(l).or_default() += 1;
        }
    }
    if counts.is_empty() {
        return Err(PlaneImageError::NoLabel(
            image.label_counts().into_iter().collect(),
        ));
    }
    // Directed pixel sides with the chosen pixel on their left, between
    // pixel corners (corner (i, j) is pixel (i, j)'s lower-left).
    let mut next: HashMap<(i64, i64), Vec<(i64, i64)>> = HashMap::new();
    let mut starts = Vec::new();
    for j in 0..ny as i64 {
        for i in 0..nx as i64 {
            if !chosen(i, j) {
                continue;
            }
            for (outside, from, to) in [
                ((i, j - 1), (i, j), (i + 1, j)),
                ((i + 1, j), (i + 1, j), (i + 1, j + 1)),
                ((i, j + 1), (i + 1, j + 1), (i, j + 1)),
                ((i - 1, j), (i, j + 1), (i, j)),
            ] {
                if !chosen(outside.0, outside.1) {
                    next.entry(from).or_default().push(to);
                    starts.push(from);
                }
            }
        }
    }
    let mut polygons = Vec::new();
    for start in starts {
        // Each side is used once; a corner where two loops touch keeps two.
        let Some(first) = next.get_mut(&start).and_then(|v| v.pop()) else {
            continue;
        };
        let mut corners = vec![start];
        let (mut prev, mut at) = (start, first);
        while at != start {
            corners.push(at);
            let outs = next
                .get_mut(&at)
                .expect("a side leaves every corner reached");
            // At a corner two loops touch, turn left: each loop stays
            // round its own pixels.
            let dir = (at.0 - prev.0, at.1 - prev.1);
            let pick = outs
                .iter()
                .position(|&n| (n.0 - at.0, n.1 - at.1) == (-dir.1, dir.0))
                .unwrap_or(outs.len() - 1);
            let n = outs.swap_remove(pick);
            (prev, at) = (at, n);
        }
        polygons.push(merge_collinear(&corners));
    }
    let place = |c: (i64, i64)| {
        // Corners sit half a pixel below and left of pixel centres.
        let (u, v) = (c.0 as f64 - 0.5, c.1 as f64 - 0.5);
        [
            map[0][0] * u + map[0][1] * v + map[0][2],
            map[1][0] * u + map[1][1] * v + map[1][2],
        ]
    };
    let polygons = polygons
        .into_iter()
        .map(|loop_| loop_.into_iter().map(place).collect())
        .collect();
    Ok(PlaneImage {
        outline: Outline::new(polygons)?,
        pixels_per_label: counts.into_iter().collect(),
    })
}

fn sorted_labels(labels: Option<&[i32]>) -> Option<Vec<i32>> {
    labels.map(|l| {
        let mut s = l.to_vec();
        s.sort_unstable();
        s.dedup();
        s
    })
}

/// The loop's corners where it turns.
fn merge_collinear(corners: &[(i64, i64)]) -> Vec<(i64, i64)> {
    let n = corners.len();
    (0..n)
        .filter(|&k| {
            let (a, b, c) = (corners[(k + n - 1) % n], corners[k], corners[(k + 1) % n]);
            (b.0 - a.0) * (c.1 - b.1) - (b.1 - a.1) * (c.0 - b.0) != 0
        })
        .map(|k| corners[k])
        .collect()
}

/// Rectangles of `cell` (m) covered at least `threshold` by the chosen
/// pixels of a one-slice `image` placed by `map`, on the grid
/// [`fitted_grid`] lays over `outline` (the chosen pixels' boundary), with
/// each rectangle's label; `components` says which groups are kept.
pub fn resample_plane(
    image: &LabelImage,
    labels: Option<&[i32]>,
    map: &[[f64; 3]; 2],
    outline: &Outline,
    cell: [f64; 2],
    threshold: f64,
    components: ComponentPolicy,
) -> Result<(RectLattice, Vec<i32>), PlaneImageError> {
    if !(threshold > 0.0 && threshold <= 1.0) {
        return Err(PlaneImageError::Threshold(threshold));
    }
    let (origin, dims) = fitted_grid(outline, cell)?;
    let (gx, gy) = (dims[0] as usize, dims[1] as usize);
    let sorted = sorted_labels(labels);
    let choice = LabelChoice(sorted.as_deref());
    let spacing = |c: usize| map[0][c].hypot(map[1][c]);
    let shorter = cell[0].min(cell[1]);
    let m: [usize; 2] = [0, 1].map(|c| ((2.0 * spacing(c) / shorter).ceil() as usize).clamp(1, 64));
    let det = (map[0][0] * map[1][1] - map[0][1] * map[1][0]).abs();
    let piece = det / (m[0] * m[1]) as f64 / (cell[0] * cell[1]);
    let mut covered = vec![0.0f64; gx * gy];
    let mut shares: HashMap<(usize, i32), f64> = HashMap::new();
    let [nx, ny, _] = image.dims;
    for j in 0..ny {
        for i in 0..nx {
            let label = image.labels[i + nx * j];
            if !choice.contains(label) {
                continue;
            }
            for pj in 0..m[1] {
                for pi in 0..m[0] {
                    let u = i as f64 + (pi as f64 + 0.5) / m[0] as f64 - 0.5;
                    let v = j as f64 + (pj as f64 + 0.5) / m[1] as f64 - 0.5;
                    let x = map[0][0] * u + map[0][1] * v + map[0][2];
                    let y = map[1][0] * u + map[1][1] * v + map[1][2];
                    let cx = ((x - origin[0]) / cell[0]).floor();
                    let cy = ((y - origin[1]) / cell[1]).floor();
                    if cx < 0.0 || cy < 0.0 || cx >= gx as f64 || cy >= gy as f64 {
                        continue; // only rounding at the outermost edge can do this
                    }
                    let c = cx as usize + gx * cy as usize;
                    covered[c] += piece;
                    *shares.entry((c, label)).or_default() += piece;
                }
            }
        }
    }
    // A cell no chosen pixel reaches is never kept, however small the
    // threshold (it would have no label).
    let mut occupied: Vec<bool> = covered
        .iter()
        .map(|&a| a > 0.0 && a >= threshold - 1e-9)
        .collect();
    if components == ComponentPolicy::LargestOnly {
        keep_largest_group(&mut occupied, gx, gy);
    }
    let lattice = RectLattice::from_occupancy(origin, cell, dims, &occupied)?;
    let mut best: HashMap<usize, (i32, f64)> = HashMap::new();
    let mut ordered: Vec<((usize, i32), f64)> = shares.into_iter().collect();
    ordered.sort_unstable_by_key(|&(key, _)| key);
    for ((c, label), share) in ordered {
        let slot = best.entry(c).or_insert((label, share));
        if share > slot.1 {
            *slot = (label, share);
        }
    }
    let cell_labels = lattice
        .cell_coords()
        .iter()
        .map(|&[x, y]| best[&(x as usize + gx * y as usize)].0)
        .collect();
    Ok((lattice, cell_labels))
}

/// Clears every occupied cell outside the largest edge-connected group
/// (ties: the group whose first cell in grid order comes first).
fn keep_largest_group(occupied: &mut [bool], gx: usize, gy: usize) {
    let mut group = vec![u32::MAX; occupied.len()];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for seed in 0..occupied.len() {
        if !occupied[seed] || group[seed] != u32::MAX {
            continue;
        }
        let id = sizes.len() as u32;
        let mut size = 0usize;
        group[seed] = id;
        stack.push(seed);
        while let Some(c) = stack.pop() {
            size += 1;
            let (x, y) = (c % gx, c / gx);
            let mut visit = |n: usize| {
                if occupied[n] && group[n] == u32::MAX {
                    group[n] = id;
                    stack.push(n);
                }
            };
            if x > 0 {
                visit(c - 1);
            }
            if x + 1 < gx {
                visit(c + 1);
            }
            if y > 0 {
                visit(c - gx);
            }
            if y + 1 < gy {
                visit(c + gx);
            }
        }
        sizes.push(size);
    }
    let Some(largest) = (0..sizes.len()).max_by_key(|&g| (sizes[g], std::cmp::Reverse(g))) else {
        return;
    };
    for (o, g) in occupied.iter_mut().zip(&group) {
        *o = *o && *g == largest as u32;
    }
}
