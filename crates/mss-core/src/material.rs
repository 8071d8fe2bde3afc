//! Isotropic linear-elastic material parameters.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why a material was refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MaterialError {
    /// Young's modulus must be positive and finite.
    #[error("Young's modulus E = {0} Pa must be a positive finite number")]
    Young(f64),
    /// Poisson's ratio outside the open range the model supports.
    #[error(
        "Poisson's ratio nu = {value} is outside ({min}, {max}); the hexahedral MSS needs {min} < nu < {max} (use e.g. 0.49 for nearly incompressible material)"
    )]
    Poisson {
        /// The value given.
        value: f64,
        /// Exclusive lower bound.
        min: f64,
        /// Exclusive upper bound.
        max: f64,
    },
    /// Density must be positive and finite.
    #[error("density rho = {0} kg/m^3 must be a positive finite number")]
    Density(f64),
}

/// Isotropic material: Young's modulus `young` (Pa), Poisson's ratio `poisson`
/// (dimensionless) and mass density `density` (kg/m^3).
///
/// In scene files this is the `[material]` table (`young`, `poisson`,
/// `density`; unknown keys are refused).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Young's modulus E (Pa).
    pub young: f64,
    /// Poisson's ratio nu.
    pub poisson: f64,
    /// Mass density rho (kg/m^3).
    pub density: f64,
}

impl Material {
    /// Lower bound (exclusive) of Poisson's ratio for the paper's model.
    pub const POISSON_MIN: f64 = -0.25;
    /// Upper bound (exclusive) of Poisson's ratio.
    pub const POISSON_MAX: f64 = 0.5;

    /// A material valid for the paper's model: E > 0, -0.25 < nu < 0.5, rho > 0.
    pub fn new(young: f64, poisson: f64, density: f64) -> Result<Self, MaterialError> {
        Self::with_poisson_range(
            young,
            poisson,
            density,
            Self::POISSON_MIN,
            Self::POISSON_MAX,
        )
    }

    /// A material with a custom open range for nu (parameterizations other than
    /// the paper's may accept a wider one).
    pub fn with_poisson_range(
        young: f64,
        poisson: f64,
        density: f64,
        min: f64,
        max: f64,
    ) -> Result<Self, MaterialError> {
        if !(young.is_finite() && young > 0.0) {
            return Err(MaterialError::Young(young));
        }
        if !(poisson.is_finite() && poisson > min && poisson < max) {
            return Err(MaterialError::Poisson {
                value: poisson,
                min,
                max,
            });
        }
        if !(density.is_finite() && density > 0.0) {
            return Err(MaterialError::Density(density));
        }
        Ok(Self {
            young,
            poisson,
            density,
        })
    }

    /// Shear modulus mu = E / (2 (1 + nu)) (Pa).
    pub fn shear_modulus(&self) -> f64 {
        self.young / (2.0 * (1.0 + self.poisson))
    }

    /// First Lame parameter lambda = E nu / ((1 + nu)(1 - 2 nu)) (Pa).
    pub fn lambda(&self) -> f64 {
        self.young * self.poisson / ((1.0 + self.poisson) * (1.0 - 2.0 * self.poisson))
    }

    /// Bulk modulus K = E / (3 (1 - 2 nu)) (Pa).
    pub fn bulk_modulus(&self) -> f64 {
        self.young / (3.0 * (1.0 - 2.0 * self.poisson))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_invalid_parameters() {
        assert!(Material::new(1.0, 0.3, 1.0).is_ok());
        assert_eq!(Material::new(0.0, 0.3, 1.0), Err(MaterialError::Young(0.0)));
        assert!(matches!(
            Material::new(1.0, 0.5, 1.0),
            Err(MaterialError::Poisson { .. })
        ));
        assert!(matches!(
            Material::new(1.0, -0.25, 1.0),
            Err(MaterialError::Poisson { .. })
        ));
        assert!(matches!(
            Material::new(1.0, f64::NAN, 1.0),
            Err(MaterialError::Poisson { .. })
        ));
        assert_eq!(
            Material::new(1.0, 0.3, -1.0),
            Err(MaterialError::Density(-1.0))
        );
        let msg = Material::new(1.0, 0.5, 1.0).unwrap_err().to_string();
        assert!(msg.contains("0.5"), "{msg}");
    }

    #[test]
    fn moduli_are_consistent() {
        let m = Material::new(1000.0, 0.3, 1.0).unwrap();
        let (mu, lambda, k) = (m.shear_modulus(), m.lambda(), m.bulk_modulus());
        assert!((k - (lambda + 2.0 * mu / 3.0)).abs() < 1e-9);
    }
}
