//! The skin coupling's extra terms of a step (a stiffness K_x and a force F_x over the
//! interior's node DOFs) and the key by which a step knows their triplet layout still holds.

/// Extra coupling terms for one step (the skin): a symmetric stiffness K_x (triplets over
/// node DOFs, both triangles, N/m) and a force F_x (flat over node DOFs, N), held fixed
/// within the step.
#[derive(Debug, Clone, Copy)]
pub struct ExtraTerms<'a> {
    /// K_x as (row, col, value) triplets over DOFs 3·node + axis.
    pub stiffness: &'a [(usize, usize, f64)],
    /// F_x, flat over node DOFs.
    pub force: &'a [f64],
    /// A key of the triplets' (row, column) sequence that the caller changes whenever that
    /// sequence changes, so that a step need not pass over a large coupling stiffness to
    /// know its matrix layout still holds: a step checks the triplets (indices in range,
    /// values finite) only when their key is new, so a caller that changes the values under
    /// the same key vouches that they are finite. `None`: every step hashes and checks them.
    pub layout: Option<u64>,
}

impl<'a> ExtraTerms<'a> {
    /// Terms whose layout each step hashes.
    pub fn new(stiffness: &'a [(usize, usize, f64)], force: &'a [f64]) -> Self {
        Self {
            stiffness,
            force,
            layout: None,
        }
    }
}

/// FNV-1a hash of the (row, column) sequence of stiffness triplets: the key a step compares
/// to know its matrix layout still holds (an [`ExtraTerms::layout`] for a caller that keeps
/// one stiffness over many steps).
pub fn triplet_layout_key(stiffness: &[(usize, usize, f64)]) -> u64 {
    let mut h = crate::math::hash::Fnv1a::new();
    for &(r, c, _) in stiffness {
        h.mix_usize(r);
        h.mix_usize(c);
    }
    h.mix_usize(stiffness.len());
    h.finish()
}

/// The node pairs (larger, smaller) that the extra stiffness couples (none without extra
/// terms): the signature of the pattern a [`super::system::System`] is built for.
pub(super) fn extra_signature(extra: Option<&ExtraTerms>) -> Vec<(usize, usize)> {
    node_pairs(extra.map_or(&[], |x| x.stiffness))
}

/// The node pairs (larger, smaller) that `stiffness` triplets over DOFs couple, sorted.
pub(super) fn node_pairs(stiffness: &[(usize, usize, f64)]) -> Vec<(usize, usize)> {
    let mut s: Vec<(usize, usize)> = stiffness
        .iter()
        .map(|&(r, c, _)| ((r / 3).max(c / 3), (r / 3).min(c / 3)))
        .collect();
    s.sort_unstable();
    s.dedup();
    s
}
