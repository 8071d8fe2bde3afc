//! Materials per region: `[[regions]]` tables that give the cells inside a
//! box, a sphere or a second closed mesh their own Young's modulus, Poisson's
//! ratio and density.
//!
//! A cell belongs to a region when its centre lies inside the region's
//! shape (for a mesh: inside by the voxelizer's own test, a generalized
//! winding number of at least 1/2). Regions are applied in the order given,
//! so a later region overrides an earlier one where they overlap. A key left
//! out of a region keeps the `[material]` value. Material index 0 is
//! `[material]`, index `k` the `k`-th region; the index is written as the
//! cell field `material` of the lattice frames.
//!
//! ```
//! use mss_core::Material;
//! use mss_scene::regions::{RegionSelector, RegionSpec, assign_regions};
//!
//! let lattice = hexmesh::Lattice::block([4, 1, 1], 0.1, [0.0; 3]).unwrap();
//! let base = Material::new(1.0e4, 0.3, 1000.0).unwrap();
//! let stiff_end = RegionSpec {
//!     select: RegionSelector::Box { min: [0.2, -1.0, -1.0], max: [1.0, 1.0, 1.0], relative: false },
//!     young: Some(1.0e5),
//!     poisson: None,
//!     density: None,
//! };
//! let a = assign_regions(&lattice, &base, &[stiff_end], &|_| unreachable!()).unwrap();
//! assert_eq!(a.cell_material, vec![0, 0, 1, 1]);
//! assert_eq!(a.materials[1].young, 1.0e5);
//! assert_eq!(a.materials[1].poisson, 0.3);
//! ```

use hexmesh::winding::WindingInside;
use hexmesh::{Lattice, TriMesh};
use mss_core::Material;
use serde::Deserialize;

/// Which cells a region takes (by their centres).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum RegionSelector {
    /// Centres in the box `min ..= max` (m, or fractions of the lattice's
    /// bounding box if `relative`).
    Box {
        /// Minimum corner.
        min: [f64; 3],
        /// Maximum corner.
        max: [f64; 3],
        /// Whether `min` and `max` are fractions of the bounding box.
        #[serde(default)]
        relative: bool,
    },
    /// Centres within `radius` (m) of `centre` (m).
    Sphere {
        /// Centre (m).
        centre: [f64; 3],
        /// Radius (m), > 0.
        radius: f64,
    },
    /// Centres inside a closed surface mesh (any format `[mesh]` takes),
    /// relative to the scene file's folder, placed like `[mesh]`.
    Mesh {
        /// The mesh file.
        path: String,
    },
}

/// One `[[regions]]` table.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionSpec {
    /// The cells it takes.
    pub select: RegionSelector,
    /// Young's modulus (Pa); `[material]`'s if absent.
    pub young: Option<f64>,
    /// Poisson's ratio; `[material]`'s if absent.
    pub poisson: Option<f64>,
    /// Density (kg/m^3); `[material]`'s if absent.
    pub density: Option<f64>,
}

impl RegionSpec {
    /// The region's material: its own values over `base`'s. The values are
    /// only combined here; the parameterization checks them.
    pub fn material(&self, base: &Material) -> Material {
        Material {
            young: self.young.unwrap_or(base.young),
            poisson: self.poisson.unwrap_or(base.poisson),
            density: self.density.unwrap_or(base.density),
        }
    }
}

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

/// Assigns every cell of `lattice` its material: `base`, overridden by each
/// region in turn. `mesh_of` loads (and places) a region's mesh by its path.
/// A region whose shape contains no cell centre is an error: it most likely
/// lies elsewhere than intended (a unit or placement mistake).
pub fn assign_regions(
    lattice: &Lattice,
    base: &Material,
    regions: &[RegionSpec],
    mesh_of: &dyn Fn(&str) -> Result<TriMesh, String>,
) -> Result<RegionAssignment, RegionError> {
    let (o, h) = (lattice.origin(), lattice.h());
    let centres: Vec<[f64; 3]> = lattice
        .cell_coords()
        .iter()
        .map(|c| std::array::from_fn(|k| o[k] + (c[k] as f64 + 0.5) * h))
        .collect();
    let bounds = lattice.bounding_box();
    let mut materials = vec![*base];
    let mut cell_material = vec![0u32; centres.len()];
    let mut selected = Vec::with_capacity(regions.len());
    for (r, region) in regions.iter().enumerate() {
        let error = |message: String| RegionError { region: r, message };
        let inside: Box<dyn Fn([f64; 3]) -> bool> = match &region.select {
            RegionSelector::Box { min, max, relative } => {
                let (lo, hi) = if *relative {
                    (bounds.at_fraction(*min), bounds.at_fraction(*max))
                } else {
                    (*min, *max)
                };
                Box::new(move |p| (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]))
            }
            RegionSelector::Sphere { centre, radius } => {
                let (c, r2) = (*centre, radius * radius);
                Box::new(move |p| (0..3).map(|k| (p[k] - c[k]).powi(2)).sum::<f64>() <= r2)
            }
            RegionSelector::Mesh { path } => {
                let mesh = mesh_of(path).map_err(error)?;
                let test = WindingInside::new(&mesh, h);
                Box::new(move |p| test.contains(p))
            }
        };
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
                bounds.min,
                bounds.max
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

fn describe(s: &RegionSelector) -> String {
    match s {
        RegionSelector::Box { min, max, relative } => format!(
            "the box {min:?} .. {max:?}{}",
            if *relative {
                " (fractions of the bounding box)"
            } else {
                " m"
            }
        ),
        RegionSelector::Sphere { centre, radius } => {
            format!("the sphere of radius {radius} m around {centre:?} m")
        }
        RegionSelector::Mesh { path } => format!("the mesh {path}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bar() -> Lattice {
        Lattice::block([4, 2, 2], 0.05, [0.0; 3]).unwrap()
    }

    #[test]
    fn later_regions_override_earlier_ones() {
        let base = Material::new(1.0e4, 0.3, 1000.0).unwrap();
        let all = RegionSpec {
            select: RegionSelector::Box {
                min: [0.0; 3],
                max: [1.0; 3],
                relative: true,
            },
            young: Some(2.0e4),
            poisson: None,
            density: Some(500.0),
        };
        let ball = RegionSpec {
            select: RegionSelector::Sphere {
                centre: [0.0, 0.0, 0.0],
                radius: 0.05,
            },
            young: None,
            poisson: Some(0.45),
            density: None,
        };
        let a = assign_regions(&bar(), &base, &[all, ball], &|_| unreachable!()).unwrap();
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
        let base = Material::new(1.0e4, 0.3, 1000.0).unwrap();
        let far = RegionSpec {
            select: RegionSelector::Sphere {
                centre: [5.0, 5.0, 5.0],
                radius: 0.1,
            },
            young: Some(1.0),
            poisson: None,
            density: None,
        };
        let err = assign_regions(&bar(), &base, &[far], &|_| unreachable!()).unwrap_err();
        assert_eq!(err.region, 0);
        assert!(
            err.to_string()
                .starts_with("[[regions]] #1: selects no cell"),
            "{err}"
        );
    }

    #[test]
    fn a_mesh_region_takes_the_cells_inside_it() {
        let base = Material::new(1.0e4, 0.3, 1000.0).unwrap();
        let inner = RegionSpec {
            select: RegionSelector::Mesh {
                path: "half.obj".into(),
            },
            young: Some(3.0e4),
            poisson: None,
            density: None,
        };
        let half = hexmesh::generate::box_mesh([0.1, -1.0, -1.0], [1.0, 1.0, 1.0]);
        let a = assign_regions(&bar(), &base, &[inner], &|p| {
            assert_eq!(p, "half.obj");
            Ok(half.clone())
        })
        .unwrap();
        assert_eq!(a.cells_per_material(), vec![8, 8]);
        let missing = assign_regions(&bar(), &base, &[a_mesh("gone.obj")], &|p| {
            Err(format!("mesh file {p} does not exist"))
        })
        .unwrap_err();
        assert!(missing.to_string().contains("gone.obj"), "{missing}");
    }

    fn a_mesh(path: &str) -> RegionSpec {
        RegionSpec {
            select: RegionSelector::Mesh { path: path.into() },
            young: None,
            poisson: None,
            density: None,
        }
    }
}
