//! What a muscle is: a named set of lattice elements with a fibre direction per element, its
//! strength and activation bounds, and for an actuation muscle the rest change it makes.

use serde::{Deserialize, Serialize};

type V3 = nalgebra::Vector3<f64>;

/// Default maximum contraction c (free fibre strain at full activation, dimensionless).
pub const DEFAULT_MAX_CONTRACTION: f64 = 0.2;

/// A muscle: a named set of lattice elements, a unit fibre direction per element (rest
/// frame), its strength and its activation bounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Muscle {
    /// Name (from the rig file or the blend shape it was generated from).
    pub name: String,
    /// Lattice element indices (sorted, no duplicates).
    pub elements: Vec<usize>,
    /// Unit fibre direction of each element, rest frame (same length as `elements`).
    pub fibres: Vec<[f64; 3]>,
    /// Maximum contraction c (dimensionless, in (0, 1)): the fibre strain of a free block of
    /// this muscle at activation 1. The active stress is σ = 3 μ c (Pa).
    pub max_contraction: f64,
    /// Activation bounds [lower, upper] (dimensionless; default [0, 1]).
    pub bounds: [f64; 2],
    /// Rest-state offsets at activation 1 of an actuation muscle: 3K numbers per element of
    /// `elements` (m, element frame, see [`crate::fem::Interior::set_actuation`]); empty for a
    /// fibre muscle (then `fibres` acts).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub actuation: Vec<f64>,
    /// The lattice's rest change at activation 1 that `actuation` is the element offsets of
    /// (node, displacement m), on every node it moves; muscles with one combine by
    /// adding these ([`super::blend`]). Empty: the offsets add linearly.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rest_change: Vec<(usize, [f64; 3])>,
}

impl Muscle {
    /// A muscle with one fibre direction for all its elements, the default contraction and
    /// bounds [0, 1]. The fibre is normalised.
    pub fn uniform(name: &str, elements: Vec<usize>, fibre: V3) -> Self {
        let f = fibre.normalize();
        let mut elements = elements;
        elements.sort_unstable();
        elements.dedup();
        Self {
            name: name.to_string(),
            fibres: vec![[f.x, f.y, f.z]; elements.len()],
            elements,
            max_contraction: DEFAULT_MAX_CONTRACTION,
            bounds: [0.0, 1.0],
            actuation: Vec::new(),
            rest_change: Vec::new(),
        }
    }

    /// Whether the muscle acts by changing the rest state (else along its fibres).
    pub fn is_actuation(&self) -> bool {
        !self.actuation.is_empty()
    }

    /// Whether the actuation comes with the lattice rest change it was made from.
    pub fn has_rest_change(&self) -> bool {
        self.is_actuation() && !self.rest_change.is_empty()
    }

    /// Check the muscle against a lattice of `element_count` elements; the message names the
    /// muscle and the field that is wrong.
    pub fn validate(&self, element_count: usize) -> Result<(), String> {
        let n = &self.name;
        if self.elements.is_empty() {
            return Err(format!("muscle '{n}': no elements"));
        }
        if self.is_actuation() {
            let per = self.actuation.len() / self.elements.len();
            if self.actuation.len() % self.elements.len() != 0 || !(per == 24 || per == 81) {
                return Err(format!(
                    "muscle '{n}': {} actuation offsets for {} elements (3 per node of each)",
                    self.actuation.len(),
                    self.elements.len()
                ));
            }
            if self.actuation.iter().any(|v| !v.is_finite()) {
                return Err(format!("muscle '{n}': an actuation offset is not finite"));
            }
            if self
                .rest_change
                .iter()
                .any(|(_, s)| s.iter().any(|v| !v.is_finite()))
            {
                return Err(format!("muscle '{n}': a rest change is not finite"));
            }
        } else if self.fibres.len() != self.elements.len() {
            return Err(format!(
                "muscle '{n}': {} fibres for {} elements",
                self.fibres.len(),
                self.elements.len()
            ));
        }
        if let Some(&e) = self.elements.iter().find(|&&e| e >= element_count) {
            return Err(format!(
                "muscle '{n}': element {e} does not exist (the lattice has {element_count})"
            ));
        }
        for f in &self.fibres {
            let l = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
            if !(l.is_finite() && (l - 1.0).abs() < 1e-6) {
                return Err(format!("muscle '{n}': fibre {f:?} is not a unit vector"));
            }
        }
        if !(self.max_contraction.is_finite()
            && self.max_contraction > 0.0
            && self.max_contraction < 1.0)
        {
            return Err(format!(
                "muscle '{n}': max_contraction must be in (0, 1), got {}",
                self.max_contraction
            ));
        }
        let [lo, hi] = self.bounds;
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(format!(
                "muscle '{n}': bounds must be finite with lower ≤ upper, got [{lo}, {hi}]"
            ));
        }
        Ok(())
    }

    /// Active stress at activation 1, σ = 3 μ c (Pa), for an interior of shear modulus `mu`.
    pub fn stress(&self, mu: f64) -> f64 {
        3.0 * mu * self.max_contraction
    }
}
