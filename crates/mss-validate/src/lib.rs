//! # mss-validate
//!
//! Everything that checks the hexahedral mass-spring model against something
//! else, kept apart from the model itself (`mss-core`):
//!
//! - [`fem`]: a trilinear (Q1) hexahedral finite element reference on the same
//!   lattices, linear and large-deformation (neo-Hookean, St. Venant-Kirchhoff).
//! - [`material_test`]: virtual material tests (uniaxial tension, pure shear,
//!   uniform dilation) that measure E, nu, G and K of any parameterization.
//! - [`experiments`]: the paper's cantilever and L-shape experiments and any
//!   lattice with fixed regions and loads, against the refined FEM, with the
//!   paper's error metric.
//! - [`figures`]: published figures (the paper's, and those of the independent
//!   implementation `docs/model.md` quotes) as named data.
//! - [`plane`]: the 2D element's virtual tests and cantilever study against
//!   bilinear plane-stress finite elements (`mss experiment 2d`).
//! - [`report`]: Markdown sections, CSV tables, SVG plots and `.vtu` files of
//!   the results.
//!
//! The model's definition and the facts checked here are in `docs/model.md`.
//!
//! ```
//! use mss_core::Material;
//! use mss_core::model::PaperModel;
//! use mss_validate::material_test::measure_material;
//!
//! // The paper's model reproduces E and nu in uniaxial tension exactly.
//! let material = Material::new(1000.0, 0.3, 1.0).unwrap();
//! let measured = measure_material(material, &PaperModel, 1).unwrap();
//! assert!((measured.young / 1000.0 - 1.0).abs() < 1e-8);
//! assert!((measured.poisson - 0.3).abs() < 1e-8);
//! ```

pub mod experiments;
pub mod fem;
pub mod figures;
pub mod material_test;
pub mod plane;
pub mod report;
pub mod suite;

pub use material_test::{MeasuredMaterial, measure_material};
