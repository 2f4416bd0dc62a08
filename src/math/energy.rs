//! The interface every potential energy in furrow implements.

/// The slot of a Hessian triplet that [`Energy::hessian_scatter`] leaves out.
pub const NO_SLOT: u32 = u32::MAX;

/// A potential energy over a flat vector of degrees of freedom (positions in metres, so the
/// energy is in joules, the gradient in newtons and the Hessian in newtons per metre).
///
/// One code path computes value, gradient and Hessian: the kernel fills the optional buffers.
pub trait Energy: Sync {
    /// Number of degrees of freedom (3 × number of points).
    fn dofs(&self) -> usize;

    /// Energy at `x` in joules. When `grad` is given, the gradient (J/m) is **added** to it.
    /// When `hess` is given, Hessian entries (J/m²) are **appended** as `(row, col, value)`
    /// triplets (duplicates are summed by the assembler; both triangles of the symmetric
    /// matrix are emitted). When `project_psd` is true, each element Hessian is projected to
    /// positive semi-definite before it is emitted.
    fn eval(
        &self,
        x: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut Vec<(usize, usize, f64)>>,
        project_psd: bool,
    ) -> f64;

    /// Hessian values only (J/m²), in exactly the order and number of the triplets `eval`
    /// appends at the same `x`, written over `values` (resized). A solver that has kept the
    /// triplet indices refills its matrix from these without the index traffic. The default
    /// evaluates the triplets and copies their values; energies with many elements override
    /// it.
    fn hessian_values(&self, x: &[f64], values: &mut Vec<f64>, project_psd: bool) {
        let mut t = Vec::new();
        self.eval(x, None, Some(&mut t), project_psd);
        values.clear();
        values.extend(t.iter().map(|e| e.2));
    }

    /// The number of Hessian triplets [`Energy::eval`] emits, when the energy knows it
    /// without evaluating (the default: `None`). A solver that kept the triplets' layout
    /// scatters later Hessians by it only while this count agrees.
    fn triplet_count(&self) -> Option<usize> {
        None
    }

    /// A shorter form of the slot map `slot` (one slot per triplet) that
    /// [`Energy::hessian_scatter`] also takes, made once per layout: energies of symmetric
    /// element blocks keep one slot per pair of an element's dofs. `None` (the default) to
    /// be given `slot` itself.
    fn pack_slot_map(&self, _slot: &[u32]) -> Option<Vec<u32>> {
        None
    }

    /// Add the Hessian's values (J/m², at `x`, element-projected with `project_psd`) into
    /// the values of a sparse matrix: the value of triplet i (in `eval`'s order) goes to
    /// `out[slot[i]]`, nowhere when `slot[i]` is [`NO_SLOT`]. `slot` must be a *slot map*:
    /// triplets with the same (row, column) share a slot, different ones never do (an
    /// energy may rely on this to add element blocks in parallel). The default evaluates
    /// [`Energy::hessian_values`] and adds them in order; energies with many elements
    /// scatter their element blocks straight into `out` (no triplet buffer).
    ///
    /// `slot` may instead be what [`Energy::pack_slot_map`] made of the slot map.
    fn hessian_scatter(&self, x: &[f64], slot: &[u32], out: &mut [f64], project_psd: bool) {
        let mut v = Vec::new();
        self.hessian_values(x, &mut v, project_psd);
        for (&s, &h) in slot.iter().zip(&v) {
            if s != NO_SLOT {
                out[s as usize] += h;
            }
        }
    }
}
