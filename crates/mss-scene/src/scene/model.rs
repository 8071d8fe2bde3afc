//! `[model]`: the spring parameterization and its hourglass control, with the
//! defaults of a scene that names none.

use serde::Deserialize;

use super::key::KeyError;

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
    /// 3 (default): the cubic lattice; 2: the paper's 2D element, plane
    /// stress, on rectangles in the x-y plane (`mss_core::plane`).
    pub dimension: u32,
    /// Thickness of a 2D body (m; required with `dimension = 2`).
    pub thickness: Option<f64>,
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
    #[serde(default = "default_dimension")]
    dimension: u32,
    thickness: Option<f64>,
}

fn default_dimension() -> u32 {
    3
}

impl From<RawModelSection> for ModelSection {
    fn from(raw: RawModelSection) -> Self {
        ModelSection {
            dimension: raw.dimension,
            thickness: raw.thickness,
            ..ModelSection::new(raw.parameterization, raw.hourglass)
        }
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
                dimension: 3,
                thickness: None,
            },
            None => ModelSection {
                parameterization: DEFAULT_PARAMETERIZATION.to_owned(),
                hourglass: Some(hourglass.unwrap_or(DEFAULT_HOURGLASS)),
                dimension: 3,
                thickness: None,
            },
        }
    }

    /// Whether the body is the 2D element's.
    pub fn is_plane(&self) -> bool {
        self.dimension == 2
    }

    /// Checks `dimension` (2 or 3) and, in 2D, the thickness and the
    /// parameterization's name.
    pub fn check(&self) -> Result<(), KeyError> {
        match self.dimension {
            3 => {
                if self.thickness.is_some() {
                    return Err(KeyError::new(
                        "thickness",
                        "is for 2D bodies ([model] dimension = 2); a 3D body's thickness is its mesh's",
                    ));
                }
                Ok(())
            }
            2 => {
                match self.thickness {
                    None => {
                        return Err(KeyError::new(
                            "thickness",
                            "is missing: a 2D body (plane stress) needs its thickness in metres",
                        ));
                    }
                    Some(t) if !(t.is_finite() && t > 0.0) => {
                        return Err(KeyError::new(
                            "thickness",
                            format!("= {t}; the thickness must be a positive length (m)"),
                        ));
                    }
                    Some(_) => {}
                }
                self.plane_variant().map(|_| ())
            }
            d => Err(KeyError::new(
                "dimension",
                format!("= {d}; 3 (cubes) or 2 (the paper's rectangles, plane stress)"),
            )),
        }
    }

    /// The 2D variant and hourglass factor: `"paper"`, `"springs"` or
    /// `"areal"`, optionally `"+hg"` (factor `hourglass`, default 1). A
    /// scene that names no parameterization gets `"paper+hg"`.
    pub fn plane_variant(
        &self,
    ) -> Result<(mss_core::plane::PlaneParameterization, Option<f64>), KeyError> {
        let name = if self.parameterization == DEFAULT_PARAMETERIZATION {
            "paper+hg"
        } else {
            self.parameterization.as_str()
        };
        let (base, hg) = match name.strip_suffix("+hg") {
            Some(base) => (base, Some(self.hourglass.unwrap_or(DEFAULT_HOURGLASS))),
            None => (name, self.hourglass),
        };
        let variant = mss_core::plane::PlaneParameterization::from_name(base).ok_or_else(|| {
            KeyError::new(
                "parameterization",
                format!(
                    "= {:?}; the 2D models are {} (each with \"+hg\")",
                    self.parameterization,
                    mss_core::plane::PlaneParameterization::NAMES.join(", ")
                ),
            )
        })?;
        Ok((variant, hg))
    }
}

impl Default for ModelSection {
    fn default() -> Self {
        RawModelSection {
            parameterization: None,
            hourglass: None,
            dimension: default_dimension(),
            thickness: None,
        }
        .into()
    }
}
