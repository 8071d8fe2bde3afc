//! `[loads]`: gravity, forces, tractions and drag springs, and their library
//! specs; `[[loads.custom]]` names any load of the [`LoadKinds`] registry.

use std::sync::Arc;

use mss_core::Model;
use mss_core::constraints::NodeSelector;
use mss_core::loads::{ForceDistribution, Load, LoadError, LoadSpec};
use mss_core::plane::{PlaneDrag, PlaneLoad, PlaneModel, PlaneNodalForces};
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

/// Builds a load for a 2D body from its `[[loads.custom]]` table: the 2D
/// form of an entry of [`LoadKinds`].
pub type PlaneLoadFactory =
    Arc<dyn Fn(&KindTable, &PlaneModel) -> Result<Box<dyn PlaneLoad>, LoadError> + Send + Sync>;

/// The loads a scene can name in `[[loads.custom]] kind = ...`: the
/// built-ins and any a program registers (see the `custom_load` example).
/// A kind has a 3D form ([`LoadKinds::register`]) and may have a 2D one
/// ([`LoadKinds::register_plane`]) for scenes with `[model] dimension = 2`;
/// the built-ins have both.
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
    plane: Named<PlaneLoadFactory>,
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
            plane: Named::new(),
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
        kinds.register_plane(
            "gravity",
            Arc::new(|t, model| {
                let keys: GravityKeys = t.keys_as()?;
                let g = in_plane("gravity", "g", keys.g)?;
                let forces = (0..model.num_nodes() as u32)
                    .zip(model.masses())
                    .map(|(n, m)| (n, [m * g[0], m * g[1]]))
                    .collect();
                Ok(Box::new(PlaneNodalForces::new("gravity", model, forces)?))
            }),
        );
        kinds.register_plane(
            "force",
            Arc::new(|t, model| {
                let forces = plane_force(&t.keys_as::<ForceSpec>()?, model)?;
                Ok(Box::new(PlaneNodalForces::new("force", model, forces)?))
            }),
        );
        kinds.register_plane(
            "traction",
            Arc::new(|t, model| {
                let forces = plane_traction(&t.keys_as::<TractionSpec>()?, model)?;
                Ok(Box::new(PlaneNodalForces::new("traction", model, forces)?))
            }),
        );
        kinds.register_plane(
            "drag",
            Arc::new(|t, model| Ok(Box::new(plane_drag(&t.keys_as::<DragSpec>()?, model)?))),
        );
        kinds
    }
}

/// The in-plane part of `v`, or the error saying that `key` of `load`
/// leaves the plane.
fn in_plane(load: &str, key: &str, v: [f64; 3]) -> Result<[f64; 2], LoadError> {
    if v[2] != 0.0 || !v.iter().all(|c| c.is_finite()) {
        return Err(LoadError::Invalid {
            load: load.into(),
            message: format!(
                "{key} = {v:?}; a 2D body takes finite vectors in the x-y plane (z = 0)"
            ),
        });
    }
    Ok([v[0], v[1]])
}

/// The nodes `select` picks of a 2D body, or the error naming `load`.
fn plane_nodes(
    load: &str,
    select: &NodeSelector,
    model: &PlaneModel,
) -> Result<Vec<u32>, LoadError> {
    model
        .select_nodes(select)
        .map_err(|source| LoadError::Selection {
            load: load.into(),
            source,
        })
}

/// A force table's nodal forces on a 2D body.
pub fn plane_force(
    spec: &ForceSpec,
    model: &PlaneModel,
) -> Result<Vec<(u32, [f64; 2])>, LoadError> {
    let force = in_plane("force", "force", spec.force)?;
    let nodes = plane_nodes("force", &spec.select, model)?;
    let share = if spec.per_node {
        1.0
    } else {
        1.0 / nodes.len() as f64
    };
    Ok(nodes
        .into_iter()
        .map(|n| (n, [force[0] * share, force[1] * share]))
        .collect())
}

/// A traction table's nodal forces on a 2D body (its boundary edges whose
/// midpoints lie in the box, times the thickness).
pub fn plane_traction(
    spec: &TractionSpec,
    model: &PlaneModel,
) -> Result<Vec<(u32, [f64; 2])>, LoadError> {
    let traction = in_plane("traction", "traction", spec.traction)?;
    check_box(&spec.min, &spec.max).map_err(|e| LoadError::Invalid {
        load: "traction".into(),
        message: format!("{}: {}", e.key, e.message),
    })?;
    model
        .traction_forces(spec.min, spec.max, traction)
        .ok_or_else(|| LoadError::Invalid {
            load: "traction".into(),
            message: format!(
                "no boundary edge has its midpoint in the box {:?}..{:?} (z = 0 must be in it); widen the box",
                spec.min, spec.max
            ),
        })
}

/// A drag table's spring on a 2D body.
pub fn plane_drag(spec: &DragSpec, model: &PlaneModel) -> Result<PlaneDrag, LoadError> {
    let target = in_plane("drag", "target", spec.target)?;
    let nodes = plane_nodes("drag", &spec.select, model)?;
    PlaneDrag::new(model, nodes, target, spec.stiffness)
}

impl LoadKinds {
    /// Registers (or replaces) the load called `kind`.
    pub fn register(&mut self, kind: &str, factory: LoadFactory) {
        self.entries.register(kind, factory);
    }

    /// Registers (or replaces) the 2D form of the load called `kind`.
    pub fn register_plane(&mut self, kind: &str, factory: PlaneLoadFactory) {
        self.plane.register(kind, factory);
    }

    /// The registered kinds, in registration order.
    pub fn names(&self) -> Vec<String> {
        self.entries.names()
    }

    /// The kinds with a 2D form, in registration order.
    pub fn plane_names(&self) -> Vec<String> {
        self.plane.names()
    }

    /// The 2D load `table` describes, for `model`.
    pub fn build_plane(
        &self,
        table: &KindTable,
        model: &PlaneModel,
    ) -> Result<Box<dyn PlaneLoad>, LoadError> {
        let factory = self.plane.lookup(&table.kind).map_err(|u| {
            let message = if self.entries.lookup(&table.kind).is_ok() {
                format!(
                    "this load kind has no 2D form (kinds with one: {}); a program registers one with LoadKinds::register_plane",
                    u.known
                )
            } else {
                format!("unknown load kind (known in 2D: {})", u.known)
            };
            LoadError::Invalid {
                load: u.name.clone(),
                message,
            }
        })?;
        factory(table, model)
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
