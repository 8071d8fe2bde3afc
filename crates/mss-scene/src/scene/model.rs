//! `[model]`: the spring parameterization and its hourglass control, with the
//! defaults of a scene that names none.

use serde::Deserialize;

/// `[model]`: the spring parameterization.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(from = "RawModelSection")]
pub struct ModelSection {
    /// `"volumetric-barrier+hg"` (default), `"paper"` (springs and correction
    /// forces of Baudet et al.), `"springs"` (springs only), `"volumetric"`,
    /// `"volumetric-barrier"`, each optionally with hourglass control
    /// (`"paper+hg"`, ...), or another name the library knows.
    pub parameterization: String,
    /// Factor alpha of the hourglass control on the lattice's mechanisms
    /// (dimensionless, >= 0; 1 gives a mechanism its elastic strain energy).
    /// Given, it adds the control to any parameterization (or sets the factor
    /// of a `"+hg"` one); absent, `"+hg"` names use the library's default
    /// ([`mss_core::HourglassControl::DEFAULT_ALPHA`]) and the others have
    /// none. When the parameterization is not given either, it is
    /// [`DEFAULT_HOURGLASS`]: the default model is the one that keeps soft
    /// bodies from folding (docs/robustness.md).
    pub hourglass: Option<f64>,
}

/// Parameterization of a scene that names none.
pub const DEFAULT_PARAMETERIZATION: &str = "volumetric-barrier+hg";

/// Hourglass factor of a scene that names neither a parameterization nor a
/// factor: the mechanisms' elastic energy.
pub const DEFAULT_HOURGLASS: f64 = 1.0;

/// `[model]` as written: the defaults of one key depend on the other.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModelSection {
    parameterization: Option<String>,
    hourglass: Option<f64>,
}

impl From<RawModelSection> for ModelSection {
    fn from(raw: RawModelSection) -> Self {
        ModelSection::new(raw.parameterization, raw.hourglass)
    }
}

impl ModelSection {
    /// The table with these keys given or left out: without a
    /// parameterization, [`DEFAULT_PARAMETERIZATION`] with the hourglass
    /// factor given or [`DEFAULT_HOURGLASS`].
    pub fn new(parameterization: Option<String>, hourglass: Option<f64>) -> Self {
        match parameterization {
            Some(parameterization) => ModelSection {
                parameterization,
                hourglass,
            },
            None => ModelSection {
                parameterization: DEFAULT_PARAMETERIZATION.to_owned(),
                hourglass: Some(hourglass.unwrap_or(DEFAULT_HOURGLASS)),
            },
        }
    }
}

impl Default for ModelSection {
    fn default() -> Self {
        RawModelSection {
            parameterization: None,
            hourglass: None,
        }
        .into()
    }
}
