//! `furrow wavelength`: the critical wrinkle wavelength of a skin on a soft interior.

use super::Output;
use crate::coupling::wavelength::Bilayer;

/// Arguments of `furrow wavelength` (SI units).
#[derive(Debug, clap::Args)]
pub struct WavelengthArgs {
    /// Skin thickness h (m).
    #[arg(long)]
    pub thickness: f64,
    /// Skin Young's modulus E_x (Pa).
    #[arg(long)]
    pub skin_modulus: f64,
    /// Skin Poisson ratio ν_x.
    #[arg(long, default_value_t = 0.45)]
    pub skin_poisson: f64,
    /// Interior Young's modulus E_q (Pa).
    #[arg(long)]
    pub interior_modulus: f64,
    /// Interior Poisson ratio ν_q.
    #[arg(long, default_value_t = 0.45)]
    pub interior_poisson: f64,
}

/// Print λ.
pub fn run(a: WavelengthArgs, out: &Output) -> anyhow::Result<()> {
    let b = Bilayer {
        thickness: a.thickness,
        skin_modulus: a.skin_modulus,
        skin_poisson: a.skin_poisson,
        interior_modulus: a.interior_modulus,
        interior_poisson: a.interior_poisson,
    };
    b.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    let l = b.critical_wavelength();
    out.json_result(&serde_json::json!({ "ok": true, "wavelength_m": l, "inputs": b }));
    out.say(format!(
        "critical wavelength λ = {:.4} mm ({l:.6e} m)",
        l * 1e3
    ));
    Ok(())
}
