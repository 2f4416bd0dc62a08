//! How actuation muscles combine: their rest changes added as node motions of the whole
//! lattice, each element then taking the rest shape that motion gives it in its own frame.
//!
//! A generated muscle m is fitted as a rest change s_m of the lattice's nodes (m, flat; the
//! shape's lattice fit plus what the tracking leaves to it, [`super::actuation`]); its
//! actuation is the element offsets that change gives, d_m,e = u_e(X + s_m) with
//! u_e(x) = R_e(x)ᵀ (x_a − x_0) − (X_a − X_0) the element's local displacements
//! ([`crate::fem::Interior::element_local_displacements`]). At activations a the rest
//! state is the same map of the summed change:
//!
//!   d_e(a) = u_e(X + Σ_m a_m s_m),
//!
//! so muscles combine as the blend shapes they are fitted to combine, linearly in position:
//! a compatible set of changes makes X + Σ a_m s_m at zero energy, and at a = e_m the offsets
//! are d_m. Blending the offsets themselves, Σ a_m d_m, would take each element's rotation
//! out before blending: an element that a shape turns by θ keeps its full size at partial
//! activation where the blend shape shrinks its chord to |1 − a + a e^{iθ}| (the capture
//! head's eyelids turn 175° within an element; offsets blended that way creased its forehead
//! 0.6 mm at 20 % of a blink, tracking 0.15 mm). Blending per Gauss point as stretch and
//! rotation logarithm (Phace's A(a) = I + Σ a_m (A_m − I) with as-rigid-as-possible
//! interpolation of the turn) departs from the rig the other way: its partial blinks turn
//! the lids rigidly through the eye, and the head's frames 0–25 missed the shape by 38 %
//! with three frames' skin self-intersecting (offsets: 20 %, one).
//!
//! Muscles without a rest change (made from offsets alone) add their offsets linearly.

use super::definition::Muscle;
use crate::fem::Interior;
use rayon::prelude::*;

/// The actuation muscles of an interior, ready to combine.
#[derive(Debug, Clone)]
pub struct ActuationBlend {
    /// Rest node positions X (flat, m).
    rest: Vec<f64>,
    /// Per interior element, whether its rest shape follows the summed node change: true
    /// for the elements of every muscle with a rest change.
    follows: Vec<bool>,
    /// Per muscle with a rest change, the following elements its change moves a node of
    /// (sorted).
    moved: Vec<Vec<usize>>,
    /// Nodes per element.
    nodes: usize,
}

impl ActuationBlend {
    /// The blend of `muscles` (validated against `interior`) on `interior` with rest node
    /// positions `rest` (flat, m).
    pub fn new(interior: &Interior, muscles: &[Muscle], rest: &[f64]) -> Self {
        let mut follows = vec![false; interior.elements.len()];
        for m in muscles.iter().filter(|m| m.has_rest_change()) {
            m.elements.iter().for_each(|&e| follows[e] = true);
        }
        let moved = muscles
            .iter()
            .map(|m| {
                if !m.has_rest_change() {
                    return Vec::new();
                }
                let mut touched = vec![false; interior.nodes];
                m.rest_change.iter().for_each(|&(n, _)| touched[n] = true);
                (0..follows.len())
                    .filter(|&e| follows[e] && interior.elements[e].iter().any(|&n| touched[n]))
                    .collect()
            })
            .collect();
        Self {
            rest: rest.to_vec(),
            follows,
            moved,
            nodes: interior.nodes_per_element(),
        }
    }

    /// X + Σ_m a_m s_m (flat, m).
    fn changed_rest(&self, muscles: &[Muscle], a: &[f64]) -> Vec<f64> {
        let mut x = self.rest.clone();
        for (m, &am) in muscles.iter().zip(a) {
            if am != 0.0 {
                for &(n, s) in &m.rest_change {
                    for i in 0..3 {
                        x[3 * n + i] += am * s[i];
                    }
                }
            }
        }
        x
    }

    /// The interior's actuation at activations `a` (one per muscle): offsets d(a), 3K per
    /// element of the interior (m, element frame); empty when no actuation muscle exists.
    pub fn field(&self, interior: &Interior, muscles: &[Muscle], a: &[f64]) -> Vec<f64> {
        assert_eq!(muscles.len(), a.len(), "one activation per muscle");
        if !muscles.iter().any(Muscle::is_actuation) {
            return Vec::new();
        }
        let n3 = 3 * self.nodes;
        let mut d = vec![0.0; n3 * self.follows.len()];
        if self.follows.contains(&true) {
            let x = self.changed_rest(muscles, a);
            d.par_chunks_mut(n3)
                .enumerate()
                .filter(|(e, _)| self.follows[*e])
                .for_each(|(e, u)| interior.element_local_displacements(&x, e, u, None));
        }
        for (m, &am) in muscles.iter().zip(a) {
            if !m.is_actuation() || m.has_rest_change() || am == 0.0 {
                continue;
            }
            for (j, &e) in m.elements.iter().enumerate() {
                let src = &m.actuation[j * n3..(j + 1) * n3];
                for (o, v) in d[e * n3..(e + 1) * n3].iter_mut().zip(src) {
                    *o += am * v;
                }
            }
        }
        d
    }

    /// ∂d/∂a_m at activations `a` for every actuation muscle m, its unit actuation: the
    /// elements it changes and their offsets' rates (3K per element, m per unit
    /// activation); empty for a fibre muscle.
    pub fn tangents(
        &self,
        interior: &Interior,
        muscles: &[Muscle],
        a: &[f64],
    ) -> Vec<(Vec<usize>, Vec<f64>)> {
        let n3 = 3 * self.nodes;
        let x = self.changed_rest(muscles, a);
        muscles
            .iter()
            .zip(&self.moved)
            .map(|(mu, elements)| {
                if !mu.has_rest_change() {
                    return (mu.elements.clone(), mu.actuation.clone());
                }
                let mut dx = vec![0.0; x.len()];
                for &(n, s) in &mu.rest_change {
                    dx[3 * n..3 * n + 3].copy_from_slice(&s);
                }
                let mut rates = vec![0.0; n3 * elements.len()];
                rates
                    .par_chunks_mut(n3)
                    .zip(elements)
                    .for_each(|(out, &e)| {
                        let mut u = [0.0; 81];
                        interior.element_local_displacements(&x, e, &mut u[..n3], Some((&dx, out)));
                    });
                (elements.clone(), rates)
            })
            .collect()
    }
}
