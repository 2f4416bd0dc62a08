//! The critical wrinkle wavelength of a stiff skin on a soft interior (film on substrate).
//!
//! λ = 2π h [ (1 − ν_q²) E_x / ( 3 (1 − ν_x²) E_q ) ]^(1/3)  — Rémillard and Kry 2013, Eq. 3,
//! after Timoshenko and Gere (the classical film-on-compliant-substrate result).

/// Skin and interior parameters that determine the wrinkle wavelength.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Bilayer {
    /// Skin thickness h (m).
    pub thickness: f64,
    /// Skin Young's modulus E_x (Pa).
    pub skin_modulus: f64,
    /// Skin Poisson ratio ν_x (dimensionless, in (−1, 0.5)).
    pub skin_poisson: f64,
    /// Interior Young's modulus E_q (Pa).
    pub interior_modulus: f64,
    /// Interior Poisson ratio ν_q (dimensionless, in (−1, 0.5]).
    pub interior_poisson: f64,
}

impl Bilayer {
    /// Check every field is physical; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |v: f64, name: &str, unit: &str| -> Result<(), String> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!(
                    "{name} must be a positive number of {unit}, got {v}"
                ))
            }
        };
        pos(self.thickness, "thickness", "metres")?;
        pos(self.skin_modulus, "skin modulus", "pascals")?;
        pos(self.interior_modulus, "interior modulus", "pascals")?;
        if !(self.skin_poisson > -1.0 && self.skin_poisson < 0.5) {
            return Err(format!(
                "skin Poisson ratio must lie in (−1, 0.5), got {}",
                self.skin_poisson
            ));
        }
        if !(self.interior_poisson > -1.0 && self.interior_poisson <= 0.5) {
            return Err(format!(
                "interior Poisson ratio must lie in (−1, 0.5], got {}",
                self.interior_poisson
            ));
        }
        Ok(())
    }

    /// The critical wavelength λ (m).
    pub fn critical_wavelength(&self) -> f64 {
        let ratio = (1.0 - self.interior_poisson.powi(2)) * self.skin_modulus
            / (3.0 * (1.0 - self.skin_poisson.powi(2)) * self.interior_modulus);
        2.0 * std::f64::consts::PI * self.thickness * ratio.cbrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layer(h: f64, ex: f64, eq: f64, nu: f64) -> Bilayer {
        Bilayer {
            thickness: h,
            skin_modulus: ex,
            skin_poisson: nu,
            interior_modulus: eq,
            interior_poisson: nu,
        }
    }

    /// The paper's Table 1: h = 0.2 mm, E_x/E_q = 100, equal ν gives 4.04 mm; DESIGN.md's couch:
    /// h = 2 mm, 40 MPa on 0.5 MPa foam gives 3.75 cm.
    #[test]
    fn matches_published_values() {
        let l = layer(0.2e-3, 100e3, 1e3, 0.45).critical_wavelength();
        assert!((l - 4.04e-3).abs() < 0.005e-3, "{l}");
        let c = layer(2e-3, 40e6, 0.5e6, 0.3).critical_wavelength();
        assert!((c - 3.75e-2).abs() < 0.005e-2, "{c}");
        // λ ∝ h and ∝ (E_x/E_q)^(1/3).
        let a = layer(1e-3, 8e6, 1e6, 0.3).critical_wavelength();
        let b = layer(2e-3, 64e6, 1e6, 0.3).critical_wavelength();
        assert!((b / a - 4.0).abs() < 1e-12);
    }

    #[test]
    fn unphysical_fields_are_named() {
        assert!(layer(0.0, 1.0, 1.0, 0.3)
            .validate()
            .unwrap_err()
            .contains("thickness"));
        assert!(layer(1.0, -1.0, 1.0, 0.3)
            .validate()
            .unwrap_err()
            .contains("skin modulus"));
        assert!(layer(1.0, 1.0, f64::NAN, 0.3)
            .validate()
            .unwrap_err()
            .contains("interior modulus"));
        assert!(layer(1.0, 1.0, 1.0, 0.5)
            .validate()
            .unwrap_err()
            .contains("skin Poisson"));
        assert!(layer(1e-3, 1e6, 1e4, 0.3).validate().is_ok());
    }
}
