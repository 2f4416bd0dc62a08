//! Skin material: isotropic linear elastic thin sheet.

/// Elastic constants and thickness of the skin (a thin isotropic sheet).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ShellMaterial {
    /// Young's modulus E_x (Pa).
    pub young: f64,
    /// Poisson ratio ν_x (dimensionless, in (−1, 0.5)).
    pub poisson: f64,
    /// Thickness h (m).
    pub thickness: f64,
}

/// A material setting that cannot describe a physical sheet.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("shell material: {field} = {value} is invalid: {reason}")]
pub struct MaterialError {
    /// Name of the offending field.
    pub field: &'static str,
    /// Its value.
    pub value: f64,
    /// What it must satisfy.
    pub reason: &'static str,
}

impl ShellMaterial {
    /// Check the constants; the error names the bad field.
    pub fn validate(&self) -> Result<(), MaterialError> {
        if !(self.young.is_finite() && self.young > 0.0) {
            return Err(MaterialError {
                field: "young",
                value: self.young,
                reason: "Young's modulus must be a positive number of pascals",
            });
        }
        if !(self.poisson.is_finite() && self.poisson > -1.0 && self.poisson < 0.5) {
            return Err(MaterialError {
                field: "poisson",
                value: self.poisson,
                reason: "Poisson's ratio must lie in (-1, 0.5)",
            });
        }
        if !(self.thickness.is_finite() && self.thickness > 0.0) {
            return Err(MaterialError {
                field: "thickness",
                value: self.thickness,
                reason: "thickness must be a positive number of metres",
            });
        }
        Ok(())
    }

    /// Bending rigidity D = E h³ / (12 (1 − ν²)) in N·m.
    pub fn bending_rigidity(&self) -> f64 {
        self.young * self.thickness.powi(3) / (12.0 * (1.0 - self.poisson * self.poisson))
    }

    /// Plane-stress stretching stiffness E h / (1 − ν²) in N/m.
    pub fn stretch_stiffness(&self) -> f64 {
        self.young * self.thickness / (1.0 - self.poisson * self.poisson)
    }

    /// The Newton tolerance (N) on the residual's L2 norm of a skin of `vertices` vertices
    /// with mean edge `edge` (m) whose RMS residual force per vertex may be `relative` times
    /// the force scale E h / (1 − ν²) × edge (`solver.shell_tolerance`): the norm grows as
    /// √vertices, so a finer or larger skin is held to the same force per vertex.
    pub fn residual_tolerance(&self, relative: f64, edge: f64, vertices: usize) -> f64 {
        relative * self.stretch_stiffness() * edge * (vertices as f64).sqrt()
    }

    /// Plane-stress Lamé parameters times thickness, (μ h, λ h) in N/m:
    /// μ = E / (2 (1 + ν)), λ = E ν / (1 − ν²).
    pub fn lame_times_thickness(&self) -> (f64, f64) {
        let e = self.young;
        let nu = self.poisson;
        let h = self.thickness;
        (e * h / (2.0 * (1.0 + nu)), e * nu * h / (1.0 - nu * nu))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_field_and_rigidity_formula() {
        let m = ShellMaterial {
            young: 1e6,
            poisson: 0.3,
            thickness: 1e-3,
        };
        m.validate().unwrap();
        let d = 1e6 * 1e-9 / (12.0 * 0.91);
        assert!((m.bending_rigidity() - d).abs() < 1e-15);
        assert_eq!(
            ShellMaterial { poisson: 0.5, ..m }
                .validate()
                .unwrap_err()
                .field,
            "poisson"
        );
        assert_eq!(
            ShellMaterial { young: -1.0, ..m }
                .validate()
                .unwrap_err()
                .field,
            "young"
        );
        assert_eq!(
            ShellMaterial {
                thickness: f64::NAN,
                ..m
            }
            .validate()
            .unwrap_err()
            .field,
            "thickness"
        );
    }
}
