//! `[material]`: the library's [`Material`] itself (Young's modulus
//! `young` in Pa, Poisson's ratio `poisson`, density `density` in kg/m^3),
//! with the check a scene makes before any physics; `[[regions]]`: cells
//! with a material of their own ([`RegionSpec`], assigned by
//! [`crate::regions::assign_regions`]).

use mss_core::Material;
use serde::Deserialize;

use super::constraints::check_box;
use super::key::KeyError;
use crate::kind_table::KindTable;

/// Checks that every value of the table is a finite number; their ranges
/// (E > 0, -1 < nu < 0.5, rho > 0) are the parameterization's to check
/// when the model is built, where the message can say which model refuses
/// what.
pub fn check_material(m: &Material) -> Result<(), KeyError> {
    for (key, value) in [
        ("young", m.young),
        ("poisson", m.poisson),
        ("density", m.density),
    ] {
        if !value.is_finite() {
            return Err(KeyError::new(
                key,
                format!("= {value}; must be a finite number"),
            ));
        }
    }
    Ok(())
}

/// The built-in region selectors (`box`, `sphere`, `mesh`), registered in
/// `RegionSelectors::default` (`crate::regions`) under their snake-case names: which cells a
/// region takes, by their centres.
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
    /// Cells whose image label (the label covering most of the cell) is
    /// one of `labels`: for a body made from an `[image]`.
    Label {
        /// The labels.
        labels: Vec<i32>,
    },
}

/// One `[[regions]]` table.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionSpec {
    /// The cells it takes: a selector's `kind` in `RegionSelectors` and
    /// its keys.
    pub select: KindTable,
    /// Young's modulus (Pa); `[material]`'s if absent.
    pub young: Option<f64>,
    /// Poisson's ratio; `[material]`'s if absent.
    pub poisson: Option<f64>,
    /// Density (kg/m^3); `[material]`'s if absent.
    pub density: Option<f64>,
}

impl RegionSelector {
    /// The built-ins' kinds, as `select = { kind = ... }` names them.
    pub const KINDS: [&'static str; 4] = ["box", "sphere", "mesh", "label"];
}

impl RegionSpec {
    /// Checks what the table's own values can say: a built-in selector's
    /// shape (a box with `min <= max`, a sphere with a positive radius, a
    /// mesh path), finite material values, and at least one of them. A
    /// selector of another kind is checked by its factory when the
    /// regions are assigned.
    pub fn check(&self) -> Result<(), KeyError> {
        let finite3 = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        if RegionSelector::KINDS.contains(&self.select.kind.as_str()) {
            match self
                .select
                .tagged_as::<RegionSelector>()
                .map_err(|e| KeyError::new("select", e.to_string()))?
            {
                RegionSelector::Box { min, max, .. } => check_box(&min, &max)?,
                RegionSelector::Sphere { centre, radius } => {
                    if !(finite3(&centre) && radius.is_finite() && radius > 0.0) {
                        return Err(KeyError::new(
                            "",
                            format!(
                                "sphere centre = {centre:?}, radius = {radius}: the centre must \
                                 be finite and the radius a positive length (m)"
                            ),
                        ));
                    }
                }
                RegionSelector::Mesh { path } if path.trim().is_empty() => {
                    return Err(KeyError::new(
                        "",
                        "mesh path is empty; give a closed surface file",
                    ));
                }
                RegionSelector::Mesh { .. } => {}
                RegionSelector::Label { labels } if labels.is_empty() => {
                    return Err(KeyError::new(
                        "",
                        "labels = []; name the image labels whose cells the region takes",
                    ));
                }
                RegionSelector::Label { .. } => {}
            }
        }
        for (what, value) in [
            ("young", self.young),
            ("poisson", self.poisson),
            ("density", self.density),
        ] {
            if let Some(v) = value
                && !v.is_finite()
            {
                return Err(KeyError::new(
                    "",
                    format!("{what} = {v}; must be a finite number"),
                ));
            }
        }
        if self.young.is_none() && self.poisson.is_none() && self.density.is_none() {
            return Err(KeyError::new(
                "",
                "gives none of young, poisson, density: it would change nothing",
            ));
        }
        Ok(())
    }

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
