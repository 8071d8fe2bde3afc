//! Materials per region: `[[regions]]` tables that give the cells inside a
//! box, a sphere or a second closed mesh their own Young's modulus, Poisson's
//! ratio and density. The region's `select = { kind = ... }` is resolved by
//! name in [`RegionSelectors`] (the registry's `regions`), where a program
//! registers selectors of its own.
//!
//! A cell belongs to a region when its centre lies inside the region's
//! shape (for a mesh: inside by the voxelizer's own test, a generalized
//! winding number of at least 1/2), or, for a body made from a label image,
//! when the label covering most of the cell is one of the region's
//! (`{ kind = "label", labels = [2] }`). Regions are applied in the order given,
//! so a later region overrides an earlier one where they overlap. A key left
//! out of a region keeps the `[material]` value. Material index 0 is
//! `[material]`, index `k` the `k`-th region; the index is written as the
//! cell field `material` of the lattice frames.
//!
//! ```
//! use mss_core::Material;
//! use mss_scene::regions::{RegionSelectors, RegionSpec, assign_regions};
//!
//! let lattice = hexmesh::Lattice::block([4, 1, 1], 0.1, [0.0; 3]).unwrap();
//! let base = Material::new(1.0e4, 0.3, 1000.0).unwrap();
//! let stiff_end: RegionSpec = toml::from_str(
//!     "select = { kind = \"box\", min = [0.2, -1, -1], max = [1, 1, 1] }\nyoung = 1e5",
//! )
//! .unwrap();
//! let selectors = RegionSelectors::default();
//! let a = assign_regions(&lattice, &base, &[stiff_end], &selectors, &|_| unreachable!()).unwrap();
//! assert_eq!(a.cell_material, vec![0, 0, 1, 1]);
//! assert_eq!(a.materials[1].young, 1.0e5);
//! assert_eq!(a.materials[1].poisson, 0.3);
//! ```

use std::sync::Arc;

use hexmesh::winding::WindingInside;
use hexmesh::{Aabb, Lattice, TriMesh};
use mss_core::Material;
use mss_registry::Named;

use crate::kind_table::KindTable;
pub use crate::scene::{RegionSelector, RegionSpec};

/// The materials of a lattice with regions.
#[derive(Debug, Clone, PartialEq)]
pub struct RegionAssignment {
    /// `[material]`, then one material per region.
    pub materials: Vec<Material>,
    /// Material index of every cell.
    pub cell_material: Vec<u32>,
    /// Cells whose centre each region's shape contains (before later
    /// regions override), one entry per region.
    pub selected: Vec<usize>,
}

impl RegionAssignment {
    /// Cells that end with each material (index 0 = `[material]`).
    pub fn cells_per_material(&self) -> Vec<usize> {
        let mut n = vec![0; self.materials.len()];
        for &m in &self.cell_material {
            n[m as usize] += 1;
        }
        n
    }
}

/// Why regions could not be assigned: the region (0-based) and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("[[regions]] #{}: {message}", .region + 1)]
pub struct RegionError {
    /// The region, 0-based.
    pub region: usize,
    /// What is wrong.
    pub message: String,
}

/// Whether a point (a cell centre, m) lies in a region.
pub type CellTest = Box<dyn Fn([f64; 3]) -> bool + Send + Sync>;

/// What a region selector's factory may use: the lattice's bounding box
/// and cell edge, the loader of the scene's meshes (placed like `[mesh]`),
/// and the image label of the cell around a point, for a body made from a
/// label image.
pub struct RegionContext<'a> {
    /// The lattice's bounding box (m).
    pub bounds: Aabb,
    /// The cell edge (m).
    pub h: f64,
    /// Loads and places a mesh file the scene names.
    pub mesh_of: &'a dyn Fn(&str) -> Result<TriMesh, String>,
    /// The label of the cell holding a point (m), if the body has labels.
    pub cell_labels: Option<Arc<CellLabels>>,
}

/// The image labels of a lattice's cells, looked up by a point.
#[derive(Debug, Clone)]
pub struct CellLabels {
    origin: [f64; 3],
    /// Cell sides (m; a 2D lattice's z side is a unit slab around z = 0).
    sides: [f64; 3],
    labels: std::collections::HashMap<[u32; 3], i32>,
}

impl CellLabels {
    /// The labels of `lattice`'s cells, in its cell order.
    pub fn new(lattice: &Lattice, labels: &[i32]) -> Self {
        Self {
            origin: lattice.origin(),
            sides: [lattice.h(); 3],
            labels: (0..lattice.num_cells())
                .map(|c| lattice.cell_coord(c))
                .zip(labels.iter().copied())
                .collect(),
        }
    }

    /// The labels of a 2D `lattice`'s cells, in its cell order (points
    /// looked up at z = 0).
    pub fn plane(lattice: &hexmesh::plane::RectLattice, labels: &[i32]) -> Self {
        let [ox, oy] = lattice.origin();
        let [lx, ly] = lattice.cell_size();
        Self {
            origin: [ox, oy, -0.5],
            sides: [lx, ly, 1.0],
            labels: lattice
                .cell_coords()
                .iter()
                .map(|&[x, y]| [x, y, 0])
                .zip(labels.iter().copied())
                .collect(),
        }
    }

    /// The label of the cell holding `p` (m), if it is a cell.
    pub fn at(&self, p: [f64; 3]) -> Option<i32> {
        let mut c = [0u32; 3];
        for k in 0..3 {
            let v = ((p[k] - self.origin[k]) / self.sides[k]).floor();
            if !(0.0..u32::MAX as f64).contains(&v) {
                return None;
            }
            c[k] = v as u32;
        }
        self.labels.get(&c).copied()
    }
}

/// Builds a region's test from its `select` table: one entry of
/// [`RegionSelectors`]. The error says what is wrong with the table.
pub type RegionFactory =
    Arc<dyn Fn(&KindTable, &RegionContext<'_>) -> Result<CellTest, String> + Send + Sync>;

/// The region selectors a scene can name in `select = { kind = ... }`:
/// the built-ins ([`RegionSelector`]) and any a program registers.
///
/// ```
/// use std::sync::Arc;
/// use mss_scene::regions::{RegionSelectors, RegionSpec, assign_regions};
///
/// let mut selectors = RegionSelectors::default();
/// // Cells above a height, with the height as the table's one key.
/// selectors.register("above", Arc::new(|table, _| {
///     #[derive(serde::Deserialize)]
///     struct Keys { z: f64 }
///     let z = table.keys_as::<Keys>().map_err(|e| e.to_string())?.z;
///     Ok(Box::new(move |p: [f64; 3]| p[2] > z))
/// }));
/// let lattice = hexmesh::Lattice::block([1, 1, 4], 0.1, [0.0; 3]).unwrap();
/// let base = mss_core::Material::new(1.0e4, 0.3, 1000.0).unwrap();
/// let top: RegionSpec = toml::from_str("select = { kind = \"above\", z = 0.2 }\ndensity = 10.0").unwrap();
/// let a = assign_regions(&lattice, &base, &[top], &selectors, &|_| unreachable!()).unwrap();
/// assert_eq!(a.cell_material, [0, 0, 1, 1]);
/// ```
#[derive(Clone, Debug)]
pub struct RegionSelectors {
    entries: Named<RegionFactory>,
}

impl Default for RegionSelectors {
    fn default() -> Self {
        let mut selectors = RegionSelectors {
            entries: Named::new(),
        };
        for kind in RegionSelector::KINDS {
            selectors.register(kind, Arc::new(builtin_test));
        }
        selectors
    }
}

impl RegionSelectors {
    /// Registers (or replaces) the selector called `kind`.
    pub fn register(&mut self, kind: &str, factory: RegionFactory) {
        self.entries.register(kind, factory);
    }

    /// The registered kinds, in registration order.
    pub fn names(&self) -> Vec<String> {
        self.entries.names()
    }

    fn test(&self, table: &KindTable, context: &RegionContext<'_>) -> Result<CellTest, String> {
        let factory = self.entries.lookup(&table.kind).map_err(|u| {
            format!(
                "unknown region selector kind {:?}; known: {}",
                u.name, u.known
            )
        })?;
        factory(table, context)
    }
}

fn builtin_test(table: &KindTable, context: &RegionContext<'_>) -> Result<CellTest, String> {
    let select: RegionSelector = table.tagged_as().map_err(|e| e.to_string())?;
    Ok(match select {
        RegionSelector::Box { min, max, relative } => {
            let (lo, hi) = if relative {
                (
                    context.bounds.at_fraction(min),
                    context.bounds.at_fraction(max),
                )
            } else {
                (min, max)
            };
            Box::new(move |p| (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]))
        }
        RegionSelector::Sphere { centre, radius } => {
            let r2 = radius * radius;
            Box::new(move |p| (0..3).map(|k| (p[k] - centre[k]).powi(2)).sum::<f64>() <= r2)
        }
        RegionSelector::Mesh { path } => {
            let mesh = (context.mesh_of)(&path)?;
            let test = WindingInside::new(&mesh, context.h);
            Box::new(move |p| test.contains(p))
        }
        RegionSelector::Label { labels } => {
            let cells = context.cell_labels.clone().ok_or_else(|| {
                format!(
                    "selects image labels {labels:?}, but the body is made from a mesh: \
                     label regions need an [image] body"
                )
            })?;
            Box::new(move |p| cells.at(p).is_some_and(|l| labels.contains(&l)))
        }
    })
}

/// Assigns every cell of `lattice` its material: `base`, overridden by each
/// region in turn, its selector resolved in `selectors`. `mesh_of` loads
/// (and places) a region's mesh by its path. A region whose shape contains
/// no cell centre is an error: it most likely lies elsewhere than intended
/// (a unit or placement mistake).
pub fn assign_regions(
    lattice: &Lattice,
    base: &Material,
    regions: &[RegionSpec],
    selectors: &RegionSelectors,
    mesh_of: &dyn Fn(&str) -> Result<TriMesh, String>,
) -> Result<RegionAssignment, RegionError> {
    assign_regions_with_labels(lattice, None, base, regions, selectors, mesh_of)
}

/// [`assign_regions`] for a lattice whose cells carry image labels
/// (`cell_labels`, in cell order), which `label` regions select.
pub fn assign_regions_with_labels(
    lattice: &Lattice,
    cell_labels: Option<&[i32]>,
    base: &Material,
    regions: &[RegionSpec],
    selectors: &RegionSelectors,
    mesh_of: &dyn Fn(&str) -> Result<TriMesh, String>,
) -> Result<RegionAssignment, RegionError> {
    let (o, h) = (lattice.origin(), lattice.h());
    let centres: Vec<[f64; 3]> = (0..lattice.num_cells())
        .map(|cell| {
            let c = lattice.cell_coord(cell);
            std::array::from_fn(|k| o[k] + (c[k] as f64 + 0.5) * h)
        })
        .collect();
    let context = RegionContext {
        bounds: lattice.bounding_box(),
        h,
        mesh_of,
        cell_labels: cell_labels.map(|l| Arc::new(CellLabels::new(lattice, l))),
    };
    assign_regions_at(&centres, &context, base, regions, selectors)
}

/// [`assign_regions`] for cells given by their centres (a 2D body's
/// rectangles, at z = 0), in `context`.
pub fn assign_regions_at(
    centres: &[[f64; 3]],
    context: &RegionContext<'_>,
    base: &Material,
    regions: &[RegionSpec],
    selectors: &RegionSelectors,
) -> Result<RegionAssignment, RegionError> {
    let mut materials = vec![*base];
    let mut cell_material = vec![0u32; centres.len()];
    let mut selected = Vec::with_capacity(regions.len());
    for (r, region) in regions.iter().enumerate() {
        let error = |message: String| RegionError { region: r, message };
        let inside = selectors.test(&region.select, context).map_err(error)?;
        let index = materials.len() as u32;
        let mut count = 0;
        for (c, &p) in centres.iter().enumerate() {
            if inside(p) {
                cell_material[c] = index;
                count += 1;
            }
        }
        if count == 0 {
            return Err(error(format!(
                "selects no cell: no cell centre lies in {} (the lattice spans {:?} .. {:?} m)",
                describe(&region.select),
                context.bounds.min,
                context.bounds.max
            )));
        }
        selected.push(count);
        materials.push(region.material(base));
    }
    let assignment = RegionAssignment {
        materials,
        cell_material,
        selected,
    };
    for (r, &n) in assignment.cells_per_material().iter().enumerate().skip(1) {
        if n == 0 {
            log::warn!("[[regions]] #{r}: every cell it selects is taken by a later region");
        }
    }
    Ok(assignment)
}

fn describe(table: &KindTable) -> String {
    let Ok(select) = table.tagged_as::<RegionSelector>() else {
        return format!("the region of kind {:?}", table.kind);
    };
    match select {
        RegionSelector::Box { min, max, relative } => format!(
            "the box {min:?} .. {max:?}{}",
            if relative {
                " (fractions of the bounding box)"
            } else {
                " m"
            }
        ),
        RegionSelector::Sphere { centre, radius } => {
            format!("the sphere of radius {radius} m around {centre:?} m")
        }
        RegionSelector::Mesh { path } => format!("the mesh {path}"),
        RegionSelector::Label { labels } => format!("a cell of the labels {labels:?}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(s: RegionSelector) -> KindTable {
        // `{:?}` of an array of floats is a TOML array.
        let text = match s {
            RegionSelector::Box { min, max, relative } => {
                format!("kind = \"box\"\nmin = {min:?}\nmax = {max:?}\nrelative = {relative}")
            }
            RegionSelector::Sphere { centre, radius } => {
                format!("kind = \"sphere\"\ncentre = {centre:?}\nradius = {radius:?}")
            }
            RegionSelector::Mesh { path } => format!("kind = \"mesh\"\npath = {path:?}"),
            RegionSelector::Label { labels } => format!("kind = \"label\"\nlabels = {labels:?}"),
        };
        toml::from_str(&text).unwrap()
    }

    fn assign(
        regions: &[RegionSpec],
        mesh_of: &dyn Fn(&str) -> Result<TriMesh, String>,
    ) -> Result<RegionAssignment, RegionError> {
        let base = Material::new(1.0e4, 0.3, 1000.0).unwrap();
        assign_regions(&bar(), &base, regions, &RegionSelectors::default(), mesh_of)
    }

    fn bar() -> Lattice {
        Lattice::block([4, 2, 2], 0.05, [0.0; 3]).unwrap()
    }

    #[test]
    fn later_regions_override_earlier_ones() {
        let all = RegionSpec {
            select: table(RegionSelector::Box {
                min: [0.0; 3],
                max: [1.0; 3],
                relative: true,
            }),
            young: Some(2.0e4),
            poisson: None,
            density: Some(500.0),
        };
        let ball = RegionSpec {
            select: table(RegionSelector::Sphere {
                centre: [0.0, 0.0, 0.0],
                radius: 0.05,
            }),
            young: None,
            poisson: Some(0.45),
            density: None,
        };
        let a = assign(&[all, ball], &|_| unreachable!()).unwrap();
        // The sphere holds the one cell centre at (0.025, 0.025, 0.025).
        assert_eq!(a.selected, vec![16, 1]);
        assert_eq!(a.cells_per_material(), vec![0, 15, 1]);
        assert_eq!(
            a.materials[2],
            Material {
                young: 1.0e4,
                poisson: 0.45,
                density: 1000.0
            }
        );
        assert_eq!(a.materials[1].density, 500.0);
    }

    #[test]
    fn a_region_that_selects_nothing_is_an_error_naming_it() {
        let far = RegionSpec {
            select: table(RegionSelector::Sphere {
                centre: [5.0, 5.0, 5.0],
                radius: 0.1,
            }),
            young: Some(1.0),
            poisson: None,
            density: None,
        };
        let err = assign(&[far], &|_| unreachable!()).unwrap_err();
        assert_eq!(err.region, 0);
        assert!(
            err.to_string()
                .starts_with("[[regions]] #1: selects no cell"),
            "{err}"
        );
    }

    #[test]
    fn a_mesh_region_takes_the_cells_inside_it() {
        let inner = RegionSpec {
            select: table(RegionSelector::Mesh {
                path: "half.obj".into(),
            }),
            young: Some(3.0e4),
            poisson: None,
            density: None,
        };
        let half = hexmesh::generate::box_mesh([0.1, -1.0, -1.0], [1.0, 1.0, 1.0]);
        let a = assign(&[inner], &|p| {
            assert_eq!(p, "half.obj");
            Ok(half.clone())
        })
        .unwrap();
        assert_eq!(a.cells_per_material(), vec![8, 8]);
        let missing = assign(&[a_mesh("gone.obj")], &|p| {
            Err(format!("mesh file {p} does not exist"))
        })
        .unwrap_err();
        assert!(missing.to_string().contains("gone.obj"), "{missing}");
    }

    fn a_mesh(path: &str) -> RegionSpec {
        RegionSpec {
            select: table(RegionSelector::Mesh { path: path.into() }),
            young: None,
            poisson: None,
            density: None,
        }
    }
}
