//! `[loads]`: gravity, forces, tractions and drag springs, and their library
//! specs; `[[loads.custom]]` names any load of the [`LoadKinds`] registry.

use std::sync::Arc;

use mss_core::Model;
use mss_core::constraints::NodeSelector;
use mss_core::loads::{ForceDistribution, Load, LoadError, LoadSpec};
use mss_registry::Named;
use serde::Deserialize;

use super::constraints::{check_box, check_selector};
use super::key::KeyError;
use crate::kind_table::{KindKeysError, KindTable};

/// `[loads]`: external loads. All default to none.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct LoadsSection {
    /// Gravity acceleration (m/s^2), e.g. `[0, 0, -9.81]`.
    pub gravity: Option<[f64; 3]>,
    /// `[[loads.forces]]`: forces on node sets.
    #[serde(default)]
    pub forces: Vec<ForceSpec>,
    /// `[[loads.tractions]]`: surface tractions on boundary faces.
    #[serde(default)]
    pub tractions: Vec<TractionSpec>,
    /// `[[loads.drags]]`: springs pulling a node toward a target point.
    #[serde(default)]
    pub drags: Vec<DragSpec>,
    /// `[[loads.custom]]`: loads by `kind`, resolved in [`LoadKinds`] (the
    /// built-ins `gravity`, `force`, `traction`, `drag` with the keys of
    /// their own tables, and any a program registers).
    #[serde(default)]
    pub custom: Vec<KindTable>,
}

/// Builds a load for a model from its `[[loads.custom]]` table: one entry
/// of [`LoadKinds`].
pub type LoadFactory =
    Arc<dyn Fn(&KindTable, &Model) -> Result<Box<dyn Load>, LoadError> + Send + Sync>;

/// The loads a scene can name in `[[loads.custom]] kind = ...`: the
/// built-ins and any a program registers (see the `custom_load` example).
///
/// ```
/// use mss_scene::kind_table::KindTable;
/// use mss_scene::scene::LoadKinds;
///
/// let kinds = LoadKinds::default();
/// assert_eq!(kinds.names(), ["gravity", "force", "traction", "drag"]);
/// let lattice = hexmesh::Lattice::block([2, 1, 1], 0.1, [0.0; 3]).unwrap();
/// let material = mss_core::Material::new(1.0e4, 0.3, 1000.0).unwrap();
/// let model = mss_core::Model::new(&lattice, material, &mss_core::PaperModel).unwrap();
/// let table: KindTable = toml::from_str("kind = \"gravity\"\ng = [0, 0, -9.81]").unwrap();
/// assert!(kinds.build(&table, &model).unwrap().name().starts_with("gravity"));
/// let wind: KindTable = toml::from_str("kind = \"wind\"").unwrap();
/// let err = kinds.build(&wind, &model).unwrap_err().to_string();
/// assert!(err.contains("known: gravity, force, traction, drag"), "{err}");
/// ```
#[derive(Clone, Debug)]
pub struct LoadKinds {
    entries: Named<LoadFactory>,
}

/// `kind = "gravity"`'s keys.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GravityKeys {
    g: [f64; 3],
}

impl Default for LoadKinds {
    fn default() -> Self {
        let mut kinds = LoadKinds {
            entries: Named::new(),
        };
        kinds.register(
            "gravity",
            Arc::new(|t, model| {
                let keys: GravityKeys = t.keys_as()?;
                LoadSpec::Gravity { g: keys.g }.resolve(model)
            }),
        );
        kinds.register(
            "force",
            Arc::new(|t, model| LoadSpec::from(&t.keys_as::<ForceSpec>()?).resolve(model)),
        );
        kinds.register(
            "traction",
            Arc::new(|t, model| LoadSpec::from(&t.keys_as::<TractionSpec>()?).resolve(model)),
        );
        kinds.register(
            "drag",
            Arc::new(|t, model| LoadSpec::from(&t.keys_as::<DragSpec>()?).resolve(model)),
        );
        kinds
    }
}

impl LoadKinds {
    /// Registers (or replaces) the load called `kind`.
    pub fn register(&mut self, kind: &str, factory: LoadFactory) {
        self.entries.register(kind, factory);
    }

    /// The registered kinds, in registration order.
    pub fn names(&self) -> Vec<String> {
        self.entries.names()
    }

    /// The load `table` describes, for `model`.
    pub fn build(&self, table: &KindTable, model: &Model) -> Result<Box<dyn Load>, LoadError> {
        let factory = self
            .entries
            .lookup(&table.kind)
            .map_err(|u| LoadError::Invalid {
                load: u.name.clone(),
                message: format!("unknown load kind (known: {})", u.known),
            })?;
        factory(table, model)
    }
}

impl From<KindKeysError> for LoadError {
    fn from(e: KindKeysError) -> Self {
        LoadError::Invalid {
            load: e.kind,
            message: e.message,
        }
    }
}

/// A constant force on a node set.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceSpec {
    /// The nodes.
    pub select: NodeSelector,
    /// Force (N): the total, shared equally by the selected nodes, or with
    /// `per_node = true` the force on each node.
    pub force: [f64; 3],
    /// Whether `force` applies to each node rather than to the set (default false).
    #[serde(default)]
    pub per_node: bool,
}

/// A traction (force per area) on the lattice's boundary faces whose centres
/// lie in a box.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TractionSpec {
    /// Box minimum corner (m).
    pub min: [f64; 3],
    /// Box maximum corner (m).
    pub max: [f64; 3],
    /// Traction (Pa).
    pub traction: [f64; 3],
}

/// A drag spring: pulls the centroid of a node set toward a target point
/// (zero-length springs shared by the nodes, so the set is not collapsed).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DragSpec {
    /// The nodes.
    pub select: NodeSelector,
    /// Target of the set's centroid (m).
    pub target: [f64; 3],
    /// Total spring stiffness (N/m), > 0.
    pub stiffness: f64,
}

impl LoadsSection {
    /// Checks the values the tables give: finite vectors, valid selectors
    /// and boxes, a positive drag stiffness. Errors name an entry of a list
    /// as `forces #1`; the kinds of `custom` loads are resolved when the
    /// problem is built.
    pub fn check(&self) -> Result<(), KeyError> {
        let finite3 = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        if let Some(g) = &self.gravity
            && !finite3(g)
        {
            return Err(KeyError::new("gravity", format!("= {g:?}; must be finite")));
        }
        let entry = |list: &str, i: usize| format!("{list} #{}", i + 1);
        for (i, f) in self.forces.iter().enumerate() {
            let at = entry("forces", i);
            check_selector(&f.select).map_err(|e| e.within(&at))?;
            if !finite3(&f.force) {
                let message = format!("force = {:?}; must be finite", f.force);
                return Err(KeyError::new(at, message));
            }
        }
        for (i, t) in self.tractions.iter().enumerate() {
            let at = entry("tractions", i);
            check_box(&t.min, &t.max).map_err(|e| e.within(&at))?;
            if !finite3(&t.traction) {
                let message = format!("traction = {:?}; must be finite", t.traction);
                return Err(KeyError::new(at, message));
            }
        }
        for (i, d) in self.drags.iter().enumerate() {
            let at = entry("drags", i);
            check_selector(&d.select).map_err(|e| e.within(&at))?;
            if !finite3(&d.target) {
                let message = format!("target = {:?}; must be a finite point", d.target);
                return Err(KeyError::new(at, message));
            }
            if !(d.stiffness.is_finite() && d.stiffness > 0.0) {
                let message = format!("stiffness = {}; must be positive (N/m)", d.stiffness);
                return Err(KeyError::new(at, message));
            }
        }
        Ok(())
    }

    /// The library's load descriptions: gravity, then forces, tractions and
    /// drag springs in the order written.
    pub fn specs(&self) -> Vec<LoadSpec> {
        let mut specs = Vec::new();
        if let Some(g) = self.gravity {
            specs.push(LoadSpec::Gravity { g });
        }
        specs.extend(self.forces.iter().map(LoadSpec::from));
        specs.extend(self.tractions.iter().map(LoadSpec::from));
        specs.extend(self.drags.iter().map(LoadSpec::from));
        specs
    }
}

impl From<&ForceSpec> for LoadSpec {
    fn from(f: &ForceSpec) -> Self {
        LoadSpec::Force {
            select: f.select.clone(),
            force: f.force,
            distribution: if f.per_node {
                ForceDistribution::PerNode
            } else {
                ForceDistribution::Total
            },
        }
    }
}

impl From<&TractionSpec> for LoadSpec {
    fn from(t: &TractionSpec) -> Self {
        LoadSpec::Traction {
            min: t.min,
            max: t.max,
            traction: t.traction,
        }
    }
}

impl From<&DragSpec> for LoadSpec {
    fn from(d: &DragSpec) -> Self {
        LoadSpec::Drag {
            select: d.select.clone(),
            target: d.target,
            stiffness: d.stiffness,
        }
    }
}
