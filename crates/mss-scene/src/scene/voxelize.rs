//! `[voxelize]`: how the surface becomes a lattice (resolution, occupancy rule,
//! components, size limit), with the table's own range check.

use hexmesh::voxelize::{ComponentPolicy, OccupancyRule, Resolution, VoxelizeOptions};
use serde::Deserialize;

use super::key::KeyError;

/// Which connected components of the voxelized lattice are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum KeepComponents {
    /// Only the largest face-connected component (default: a body in one piece).
    #[default]
    Largest,
    /// Every component.
    All,
}

/// The occupancy rule of `[voxelize] rule`: which grid cells become lattice
/// cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum OccupancyKind {
    /// The cell's centre is inside the surface (default).
    #[default]
    Centre,
    /// The cell overlaps the solid.
    Any,
    /// At least `fraction` of the cell is inside.
    Fraction,
}

impl OccupancyKind {
    /// Every rule, by its scene name.
    pub const ALL: [(&'static str, OccupancyKind); 3] = [
        ("centre", OccupancyKind::Centre),
        ("any", OccupancyKind::Any),
        ("fraction", OccupancyKind::Fraction),
    ];

    /// The voxelizer's rule; `fraction` is the threshold of [`OccupancyKind::Fraction`].
    pub fn rule(self, fraction: f64) -> OccupancyRule {
        match self {
            OccupancyKind::Centre => OccupancyRule::Centre,
            OccupancyKind::Any => OccupancyRule::AnyOverlap,
            OccupancyKind::Fraction => OccupancyRule::Fraction {
                threshold: fraction,
                samples_per_axis: 4,
            },
        }
    }
}

impl std::str::FromStr for OccupancyKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .iter()
            .find(|(name, _)| *name == s)
            .map(|(_, k)| *k)
            .ok_or_else(|| {
                format!(
                    "unknown occupancy rule \"{s}\"; use one of {}",
                    Self::ALL.map(|(n, _)| n).join(", ")
                )
            })
    }
}

/// `[voxelize]`: how the surface becomes a lattice. Give `cells` or
/// `cell_size`, not both; with neither, `cells = 24` ([`DEFAULT_CELLS`]).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VoxelizeSection {
    /// Number of cells along the longest axis of the mesh's bounding box.
    pub cells: Option<u32>,
    /// Cell edge h (m), instead of `cells`.
    pub cell_size: Option<f64>,
    /// Occupancy rule: `"centre"` (cell centre inside the surface, default),
    /// `"any"` (cell overlaps the solid), `"fraction"` (at least `fraction` of
    /// the cell inside).
    #[serde(default)]
    pub rule: OccupancyKind,
    /// Minimum inside fraction for `rule = "fraction"` (0 < f <= 1, default 0.5).
    #[serde(default = "default_fraction")]
    pub fraction: f64,
    /// Connected components kept: `"largest"` (default) or `"all"`.
    #[serde(default)]
    pub components: KeepComponents,
    /// Refuse lattices with more cells than this (default:
    /// [`VoxelizeOptions::default`]'s).
    #[serde(default = "default_max_cells")]
    pub max_cells: u64,
}

fn default_fraction() -> f64 {
    0.5
}
fn default_max_cells() -> u64 {
    VoxelizeOptions::default().max_cells
}

impl Default for VoxelizeSection {
    fn default() -> Self {
        Self {
            cells: None,
            cell_size: None,
            rule: OccupancyKind::default(),
            fraction: default_fraction(),
            components: KeepComponents::default(),
            max_cells: default_max_cells(),
        }
    }
}

/// The lattice resolution a `[voxelize]` table asks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VoxelResolution {
    /// Cells along the longest axis of the mesh's bounding box.
    Cells(u32),
    /// Cell edge (m).
    CellSize(f64),
}

/// Cells along the longest axis when `[voxelize]` gives neither `cells` nor `cell_size`.
pub const DEFAULT_CELLS: u32 = 24;

impl VoxelizeSection {
    /// The requested resolution (`cell_size` if given, else `cells`, else
    /// [`DEFAULT_CELLS`]).
    pub fn resolution(&self) -> VoxelResolution {
        match (self.cell_size, self.cells) {
            (Some(h), _) => VoxelResolution::CellSize(h),
            (None, Some(n)) => VoxelResolution::Cells(n),
            (None, None) => VoxelResolution::Cells(DEFAULT_CELLS),
        }
    }

    /// Checks the ranges of the keys: `cells` or `cell_size` (not both),
    /// `cells >= 1`, a positive finite `cell_size`, `fraction` in (0, 1],
    /// `max_cells >= 1`. Every front end that fills this table (a scene,
    /// `mss voxelize`, Python's `voxelize`) checks it here and names the
    /// key its own way ([`KeyError::key`]).
    pub fn check(&self) -> Result<(), KeyError> {
        let bad = |key: &'static str, message: String| Err(KeyError { key, message });
        match (self.cells, self.cell_size) {
            (Some(_), Some(_)) => {
                return bad("", "give either `cells` or `cell_size`, not both".into());
            }
            (Some(0), _) => {
                return bad(
                    "cells",
                    "= 0; the number of cells along the longest axis must be at least 1".into(),
                );
            }
            (_, Some(h)) if !(h.is_finite() && h > 0.0) => {
                return bad(
                    "cell_size",
                    format!("= {h}; the cell edge must be a positive length in metres"),
                );
            }
            _ => {}
        }
        if !(self.fraction > 0.0 && self.fraction <= 1.0) {
            return bad(
                "fraction",
                format!("= {}; must be in (0, 1]", self.fraction),
            );
        }
        if self.max_cells == 0 {
            return bad("max_cells", "= 0; must be at least 1".into());
        }
        Ok(())
    }

    /// The voxelizer's options for this table (ranges are checked by
    /// [`VoxelizeSection::check`]).
    pub fn options(&self) -> VoxelizeOptions {
        VoxelizeOptions {
            resolution: match self.resolution() {
                VoxelResolution::Cells(n) => Resolution::CellsAlongLongestAxis(n),
                VoxelResolution::CellSize(h) => Resolution::CellSize(h),
            },
            rule: self.rule.rule(self.fraction),
            max_cells: self.max_cells,
            components: match self.components {
                KeepComponents::Largest => ComponentPolicy::LargestOnly,
                KeepComponents::All => ComponentPolicy::All,
            },
            ..VoxelizeOptions::default()
        }
    }
}
