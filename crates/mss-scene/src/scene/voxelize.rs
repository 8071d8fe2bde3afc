//! `[voxelize]`: how the surface becomes a lattice (resolution, occupancy rule,
//! components, size limit), with the table's own range check.

use std::sync::Arc;

use hexmesh::voxelize::VoxelizeOptions;
pub use hexmesh::voxelize::{ComponentPolicy, OccupancyRule, Resolution};
use mss_registry::Named;
use serde::Deserialize;

use super::key::KeyError;

/// Builds the voxelizer's rule from `[voxelize] fraction` (the threshold a
/// rule may use): one entry of [`OccupancyRules`].
pub type OccupancyFactory = Arc<dyn Fn(f64) -> OccupancyRule + Send + Sync>;

/// The occupancy rules a scene can name in `[voxelize] rule` (and `mss
/// voxelize --rule`, Python's `voxelize(rule=...)`): the built-ins `centre`
/// (the cell's centre inside, default), `any` (the cell overlaps the solid)
/// and `fraction` (at least `fraction` of the cell inside, sampled 4 x 4 x
/// 4), and any a program registers, usually an
/// [`OccupancyRule::Custom`] around its own [`hexmesh::voxelize::Occupancy`].
///
/// ```
/// use std::sync::Arc;
/// use hexmesh::voxelize::OccupancyRule;
/// use mss_scene::scene::{OccupancyRules, VoxelizeSection};
///
/// let mut rules = OccupancyRules::default();
/// // A finer-sampled fraction rule, under its own name.
/// rules.register("fraction-fine", Arc::new(|f| OccupancyRule::Fraction {
///     threshold: f,
///     samples_per_axis: 8,
/// }));
/// let section = VoxelizeSection { rule: "fraction-fine".into(), ..Default::default() };
/// let options = section.options(&rules).unwrap();
/// assert!(matches!(options.rule, OccupancyRule::Fraction { samples_per_axis: 8, .. }));
/// let unknown = VoxelizeSection { rule: "most".into(), ..Default::default() };
/// let err = unknown.options(&rules).unwrap_err();
/// assert_eq!(err.key, "rule");
/// assert!(err.message.contains("known: centre, any, fraction, fraction-fine"), "{}", err.message);
/// ```
#[derive(Clone, Debug)]
pub struct OccupancyRules {
    entries: Named<OccupancyFactory>,
}

impl Default for OccupancyRules {
    fn default() -> Self {
        let mut rules = OccupancyRules {
            entries: Named::new(),
        };
        rules.register("centre", Arc::new(|_| OccupancyRule::Centre));
        rules.register("any", Arc::new(|_| OccupancyRule::AnyOverlap));
        rules.register(
            "fraction",
            Arc::new(|threshold| OccupancyRule::Fraction {
                threshold,
                samples_per_axis: 4,
            }),
        );
        rules
    }
}

impl OccupancyRules {
    /// Registers (or replaces) the rule called `name`.
    pub fn register(&mut self, name: &str, factory: OccupancyFactory) {
        self.entries.register(name, factory);
    }

    /// The registered names, in registration order.
    pub fn names(&self) -> Vec<String> {
        self.entries.names()
    }

    /// The rule called `name` with the threshold `fraction`, or the key
    /// error naming the known rules.
    pub fn rule(&self, name: &str, fraction: f64) -> Result<OccupancyRule, KeyError> {
        let factory = self.entries.lookup(name).map_err(|u| KeyError {
            key: "rule".into(),
            message: format!(
                "= {:?}; unknown occupancy rule (known: {})",
                u.name, u.known
            ),
        })?;
        Ok(factory(fraction))
    }
}

/// `[voxelize]`: how the surface becomes a lattice. Give `cells` or
/// `cell_size`, not both; with neither, `cells = 24` ([`DEFAULT_CELLS`]).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(from = "RawVoxelizeSection")]
pub struct VoxelizeSection {
    /// Number of cells along the longest axis of the mesh's bounding box.
    pub cells: Option<u32>,
    /// Cell edge h (m), instead of `cells`.
    pub cell_size: Option<f64>,
    /// A 2D body's cell sides `[lx, ly]` (m): `cell_size = [lx, ly]` in a
    /// scene (rectangles of any aspect ratio; the 3D model needs cubes).
    pub cell_sides: Option<[f64; 2]>,
    /// A 2D body's cells along x and along y of its outline's bounding box:
    /// `cells = [nx, ny]` in a scene (rectangles of the box's width / nx by
    /// its height / ny; the 3D model needs cubes).
    pub cells_per_axis: Option<[u32; 2]>,
    /// Occupancy rule, by its name in [`OccupancyRules`]: `"centre"` (cell
    /// centre inside the surface, default), `"any"` (cell overlaps the
    /// solid), `"fraction"` (at least `fraction` of the cell inside), or one a
    /// program registered.
    pub rule: String,
    /// Minimum inside fraction for `rule = "fraction"` (0 < f <= 1, default 0.5).
    pub fraction: f64,
    /// Connected components kept: `"largest"` (default) or `"all"`.
    pub components: ComponentPolicy,
    /// Refuse lattices with more cells than this (default:
    /// [`VoxelizeOptions::default`]'s).
    pub max_cells: u64,
}

/// `[voxelize]` as written.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVoxelizeSection {
    cells: Option<CellsKey>,
    cell_size: Option<CellSizeKey>,
    #[serde(default = "default_rule")]
    rule: String,
    #[serde(default = "default_fraction")]
    fraction: f64,
    #[serde(default)]
    components: ComponentPolicy,
    #[serde(default = "default_max_cells")]
    max_cells: u64,
}

/// `cells`: along the longest axis, or along x and y for a 2D body.
#[derive(Deserialize)]
#[serde(
    untagged,
    expecting = "a number of cells along the longest axis, or [nx, ny] for a 2D body"
)]
enum CellsKey {
    Longest(u32),
    PerAxis([u32; 2]),
}

/// `cell_size`: one length, or two for a 2D body's rectangles.
#[derive(Deserialize)]
#[serde(untagged, expecting = "a length in metres, or [lx, ly] for a 2D body")]
enum CellSizeKey {
    Cube(f64),
    Sides([f64; 2]),
}

impl From<RawVoxelizeSection> for VoxelizeSection {
    fn from(raw: RawVoxelizeSection) -> Self {
        let (cell_size, cell_sides) = match raw.cell_size {
            None => (None, None),
            Some(CellSizeKey::Cube(h)) => (Some(h), None),
            Some(CellSizeKey::Sides(s)) => (None, Some(s)),
        };
        let (cells, cells_per_axis) = match raw.cells {
            None => (None, None),
            Some(CellsKey::Longest(n)) => (Some(n), None),
            Some(CellsKey::PerAxis(n)) => (None, Some(n)),
        };
        Self {
            cells,
            cells_per_axis,
            cell_size,
            cell_sides,
            rule: raw.rule,
            fraction: raw.fraction,
            components: raw.components,
            max_cells: raw.max_cells,
        }
    }
}

fn default_rule() -> String {
    "centre".to_owned()
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
            cells_per_axis: None,
            cell_size: None,
            cell_sides: None,
            rule: default_rule(),
            fraction: default_fraction(),
            components: ComponentPolicy::default(),
            max_cells: default_max_cells(),
        }
    }
}

/// Cells along the longest axis when `[voxelize]` gives neither `cells` nor `cell_size`.
pub const DEFAULT_CELLS: u32 = 24;

impl VoxelizeSection {
    /// The requested resolution (`cell_size` if given, else `cells`, else
    /// [`DEFAULT_CELLS`]).
    pub fn resolution(&self) -> Resolution {
        match (self.cell_size, self.cells) {
            (Some(h), _) => Resolution::CellSize(h),
            (None, Some(n)) => Resolution::CellsAlongLongestAxis(n),
            (None, None) => Resolution::CellsAlongLongestAxis(DEFAULT_CELLS),
        }
    }

    /// Checks the ranges of the keys: `cells` or `cell_size` (not both),
    /// `cells >= 1`, a positive finite `cell_size`, `fraction` in (0, 1],
    /// `max_cells >= 1`. Every front end that fills this table (a scene,
    /// `mss voxelize`, Python's `voxelize`) checks it here and names the
    /// key its own way ([`KeyError::key`]).
    pub fn check(&self) -> Result<(), KeyError> {
        let bad = |key: &str, message: String| Err(KeyError::new(key, message));
        if let Some(n) = self.cells_per_axis {
            if self.cell_size.is_some() || self.cell_sides.is_some() {
                return bad("", "give either `cells` or `cell_size`, not both".into());
            }
            if n.contains(&0) {
                return bad(
                    "cells",
                    format!("= {n:?}; the number of cells along each axis must be at least 1"),
                );
            }
        }
        if let Some(s) = self.cell_sides {
            if self.cells.is_some() {
                return bad("", "give either `cells` or `cell_size`, not both".into());
            }
            if !s.iter().all(|h| h.is_finite() && *h > 0.0) {
                return bad(
                    "cell_size",
                    format!("= {s:?}; the cell sides must be positive lengths in metres"),
                );
            }
        }
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

    /// The voxelizer's options for this table, its rule resolved in
    /// `rules` (ranges are checked by [`VoxelizeSection::check`]).
    pub fn options(&self, rules: &OccupancyRules) -> Result<VoxelizeOptions, KeyError> {
        Ok(VoxelizeOptions {
            resolution: self.resolution(),
            rule: rules.rule(&self.rule, self.fraction)?,
            max_cells: self.max_cells,
            components: self.components,
            ..VoxelizeOptions::default()
        })
    }
}
