//! The plug points a job resolves by name, in one value.

use hexmesh::load::Loaders;
use mss_core::Parameterizations;
use mss_core::solver::Integrators;
use mss_io::exporters::Exporters;

use crate::obstacles::Shapes;
use crate::regions::RegionSelectors;
use crate::scene::{LoadKinds, OccupancyRules};

/// Everything a scene can name that a program may extend: mesh loaders (by
/// file extension), spring parameterizations (`[model] parameterization`),
/// time integrators (`[solver] kind`), exporters (`[output]`), obstacle
/// shapes (`[[obstacles]] shape`), occupancy rules (`[voxelize] rule`),
/// loads (`[[loads.custom]]`) and region selectors (`[[regions]] select`).
///
/// A program starts from [`Registry::default`] (the built-ins), registers its
/// own plugins in the public fields, and passes the value to
/// [`Job::prepare`](crate::Job::prepare). There is no global state: two jobs
/// in one process can use different registries.
///
/// ```
/// use std::sync::Arc;
/// use mss_core::{HourglassControl, PaperModel, Parameterization};
/// use mss_scene::Registry;
///
/// let mut registry = Registry::default();
/// // A house model: the paper's with a strong hourglass control, under its own name.
/// registry.parameterizations.register(
///     "paper-stiff-hg",
///     Arc::new(|| Box::new(HourglassControl::new(Box::new(PaperModel), 0.5).unwrap())),
/// );
/// let p = registry.parameterizations.get("paper-stiff-hg").unwrap();
/// assert_eq!(p.name(), "paper+hg");
/// assert!(registry.integrators.contains("implicit"));
/// assert!(registry.exporters.frame_names().contains(&"vtu".to_string()));
/// assert_eq!(registry.loaders.known_extensions(), "obj, ply, stl, vtk, vtp, vtu");
/// ```
#[derive(Debug, Clone, Default)]
pub struct Registry {
    /// Mesh loaders, by file extension.
    pub loaders: Loaders,
    /// Spring parameterizations, by name.
    pub parameterizations: Parameterizations,
    /// Time integrators, by name (`[solver] kind`; `"static"` is not one).
    pub integrators: Integrators,
    /// Frame and skin exporters, by name.
    pub exporters: Exporters,
    /// Obstacle shapes, by `[[obstacles]] shape = { kind = ... }`.
    pub shapes: Shapes,
    /// Occupancy rules of the voxelizer, by `[voxelize] rule`.
    pub occupancy: OccupancyRules,
    /// Loads, by `[[loads.custom]] kind`.
    pub loads: LoadKinds,
    /// Region selectors, by `[[regions]] select = { kind = ... }`.
    pub regions: RegionSelectors,
}
