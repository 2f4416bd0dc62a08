//! Element Hessians added straight into a sparse matrix's values, in parallel and without
//! locks (the skin's Newton matrix, [`crate::math::Energy::hessian_scatter`]).
//!
//! The elements are split by a greedy colouring so that no two elements of one colour share
//! a vertex. Given a slot map (one matrix slot per distinct (row, column) of the Hessian's
//! triplets), two elements of one colour write disjoint slots, so a colour's elements run in
//! parallel; colours run one after another. Each slot's sum is then taken in colour order,
//! whatever the thread count, so the matrix is the same bits on any machine.
//!
//! Against evaluating the triplet values into a buffer and gathering them per slot, this
//! writes no 47 MB buffer and reads nothing back at random (the demo's skin: 5.8 million
//! triplet values into 0.8 million lower-triangle slots).

use super::psd::project_psd;
use crate::math::energy::NO_SLOT;
use rayon::prelude::*;

/// Elements grouped so that no two elements of a group share a vertex.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Colouring {
    /// Element indices of each colour, ascending.
    pub colours: Vec<Vec<u32>>,
}

impl Colouring {
    /// Greedy colouring of elements given by their vertices (each element takes the first
    /// colour none of its vertices has yet), in element order: deterministic.
    pub fn greedy<const K: usize>(elements: impl Iterator<Item = [usize; K]>) -> Self {
        // Per vertex, a bit set of the colours of its elements (64 colours per word).
        let mut used: Vec<Vec<u64>> = Vec::new();
        let mut colours: Vec<Vec<u32>> = Vec::new();
        for (e, v) in elements.enumerate() {
            let top = v.iter().copied().max().map_or(0, |m| m + 1);
            if used.len() < top {
                used.resize(top, Vec::new());
            }
            let mut c = 0;
            while v.iter().any(|&i| has(&used[i], c)) {
                c += 1;
            }
            for &i in &v {
                set(&mut used[i], c);
            }
            if colours.len() <= c {
                colours.resize(c + 1, Vec::new());
            }
            colours[c].push(e as u32);
        }
        Self { colours }
    }

    /// Number of elements coloured.
    pub fn elements(&self) -> usize {
        self.colours.iter().map(Vec::len).sum()
    }
}

fn has(bits: &[u64], c: usize) -> bool {
    bits.get(c / 64).is_some_and(|w| w & (1 << (c % 64)) != 0)
}

fn set(bits: &mut Vec<u64>, c: usize) {
    if bits.len() <= c / 64 {
        bits.resize(c / 64 + 1, 0);
    }
    bits[c / 64] |= 1 << (c % 64);
}

/// The flag of a packed slot ([`pack_symmetric_slots`]) whose value is the block's
/// transposed entry: element pair (a, b), a ≤ b, is stored at the Hessian's (b, a).
const TRANSPOSED: u32 = 1 << 31;

/// Pack the slot map of symmetric `dim × dim` element blocks (row-major, `dim²` slots per
/// element) to one slot per pair of local dofs a ≤ b: the slot of (a, b), or that of (b, a)
/// flagged [`TRANSPOSED`] when only that one is stored ([`NO_SLOT`] when neither is). A
/// lower-triangle matrix stores one of the two for every pair (a pinned dof's row stores
/// neither), so the scatter reads `dim(dim+1)/2` slots per element instead of `dim²` (78
/// of 144 for a hinge) and adds the same values. `None` when a pair has both slots (the
/// map is not of one triangle) or a slot needs the flag's bit.
pub fn pack_symmetric_slots(slot: &[u32], dim: usize) -> Option<Vec<u32>> {
    let len = dim * dim;
    if dim == 0 || slot.len() % len != 0 {
        return None;
    }
    let pairs = dim * (dim + 1) / 2;
    let mut packed = Vec::with_capacity(slot.len() / len * pairs);
    for block in slot.chunks_exact(len) {
        for a in 0..dim {
            for b in a..dim {
                let (v, w) = (block[a * dim + b], block[b * dim + a]);
                if [v, w].iter().any(|&s| s != NO_SLOT && s >= TRANSPOSED) {
                    return None;
                }
                let s = match (v, w) {
                    (v, _) if a == b => v,
                    (v, NO_SLOT) => v,
                    (NO_SLOT, w) => w | TRANSPOSED,
                    _ => return None,
                };
                packed.push(s);
            }
        }
    }
    Some(packed)
}

/// A pointer to the values being written, shared by the threads of one colour.
#[derive(Clone, Copy)]
struct Values(*mut f64);

// SAFETY: the threads of one colour write disjoint slots (see `scatter_element_hessians`).
unsafe impl Send for Values {}
unsafe impl Sync for Values {}

/// Add element `dim × dim` Hessians (J/m², row-major; element e's triplets are
/// `e·dim² .. (e+1)·dim²` of `slot`) into `out`, colour by colour: `block(e, h)` writes
/// element e's block into `h`, projected to PSD when `project` is set. The elements of
/// `colouring` must share no vertex within a colour and `slot` must be a slot map
/// ([`crate::math::Energy::hessian_scatter`]), or its packed form of `dim(dim+1)/2` slots
/// per element ([`pack_symmetric_slots`], told apart by its length), which adds the same
/// values to the same slots; slots out of range panic.
pub fn scatter_element_hessians(
    out: &mut [f64],
    slot: &[u32],
    dim: usize,
    project: bool,
    colouring: &Colouring,
    block: impl Fn(usize, &mut [f64]) + Sync + Send,
) {
    let len = dim * dim;
    assert!(len <= 144, "element blocks of at most 12 × 12");
    let elements = colouring.elements();
    let pairs = dim * (dim + 1) / 2;
    // Per slot of an element, the index of its value in the block.
    let index: Vec<(usize, usize)> = if slot.len() == elements * pairs {
        (0..dim)
            .flat_map(|a| (a..dim).map(move |b| (a * dim + b, b * dim + a)))
            .collect()
    } else {
        assert_eq!(slot.len(), elements * len, "one slot per triplet");
        (0..len).map(|k| (k, k)).collect()
    };
    let per = index.len();
    let (ptr, n) = (Values(out.as_mut_ptr()), out.len());
    for colour in &colouring.colours {
        colour.par_iter().with_min_len(64).for_each(|&e| {
            let e = e as usize;
            // An element whose dofs are all pinned adds nothing: its block is not computed.
            if slot[e * per..(e + 1) * per].iter().all(|&s| s == NO_SLOT) {
                return;
            }
            let mut h = [0.0; 144];
            block(e, &mut h[..len]);
            if project {
                project_psd(&mut h[..len], dim);
            }
            let p = ptr;
            for (&s, &(k, kt)) in slot[e * per..(e + 1) * per].iter().zip(&index) {
                if s != NO_SLOT {
                    let (s, k) = if s & TRANSPOSED != 0 && per != len {
                        ((s & !TRANSPOSED) as usize, kt)
                    } else {
                        (s as usize, k)
                    };
                    assert!(s < n, "slot {s} past the {n} values");
                    // SAFETY: `s` is in bounds (checked above); the elements of this colour
                    // share no vertex, so their triplets have different (row, column) pairs
                    // and, by the slot map, different slots: no other thread of this colour
                    // touches out[s], and colours run one after another.
                    unsafe { *p.0.add(s) += h[k] };
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Triangles of a strip share vertices with their neighbours: no colour holds two that
    /// share a vertex, every element is coloured once, and the colouring is the same twice.
    #[test]
    fn greedy_colours_separate_elements_that_share_a_vertex() {
        let tris: Vec<[usize; 3]> = (0..50)
            .map(|i| {
                if i % 2 == 0 {
                    [i, i + 1, i + 2]
                } else {
                    [i + 1, i, i + 2]
                }
            })
            .collect();
        let c = Colouring::greedy(tris.iter().copied());
        assert_eq!(c.elements(), tris.len());
        for colour in &c.colours {
            let mut seen = std::collections::HashSet::new();
            for &e in colour {
                for v in tris[e as usize] {
                    assert!(seen.insert(v), "vertex {v} twice in a colour");
                }
            }
        }
        assert!(c.colours.len() <= 5, "{} colours", c.colours.len());
        assert_eq!(c, Colouring::greedy(tris.iter().copied()));
    }

    /// Scattering blocks of ones into slots by (row, column) gives each slot the number of
    /// elements that touch it, as a sequential sum does.
    #[test]
    fn scatter_sums_like_a_sequential_loop() {
        let elems: Vec<[usize; 2]> = (0..40).map(|i| [i % 17, (i * 7 + 3) % 17]).collect();
        let elems: Vec<[usize; 2]> = elems.into_iter().filter(|e| e[0] != e[1]).collect();
        let c = Colouring::greedy(elems.iter().copied());
        let dim = 6;
        let n = 17 * 3;
        let slot: Vec<u32> = elems
            .iter()
            .flat_map(|e| {
                (0..dim * dim).map(move |k| {
                    let (r, col) = (3 * e[k / dim / 3] + k / dim % 3, 3 * e[k % dim / 3] + k % 3);
                    (r * n + col) as u32
                })
            })
            .collect();
        let value = |e: usize, k: usize| (e * 31 + k) as f64 * 0.25;
        let mut out = vec![0.0; n * n];
        scatter_element_hessians(&mut out, &slot, dim, false, &c, |e, h| {
            for (k, v) in h.iter_mut().enumerate() {
                *v = value(e, k);
            }
        });
        let mut expect = vec![0.0; n * n];
        for (i, &s) in slot.iter().enumerate() {
            expect[s as usize] += value(i / (dim * dim), i % (dim * dim));
        }
        assert_eq!(out, expect);
    }

    /// A lower-triangle slot map (upper entries and a pinned vertex's rows left out) packed
    /// to one slot per pair of an element's dofs scatters the same values as the full map,
    /// bit for bit, with blocks that are not exactly symmetric (the packed map reads the
    /// stored triangle's own entry); a map of both triangles does not pack.
    #[test]
    fn a_packed_lower_slot_map_scatters_the_same_bits() {
        let elems: Vec<[usize; 4]> = (0..30)
            .map(|i| {
                [
                    i % 13,
                    (i * 5 + 1) % 13,
                    (i * 7 + 2) % 13,
                    (i * 11 + 3) % 13,
                ]
            })
            .filter(|e| (0..4).all(|a| (a + 1..4).all(|b| e[a] != e[b])))
            .collect();
        let c = Colouring::greedy(elems.iter().copied());
        let (dim, n, pinned) = (12, 13 * 3, 4);
        let dof = |e: &[usize; 4], k: usize| 3 * e[k / 3] + k % 3;
        let full = |lower_only: bool| -> Vec<u32> {
            elems
                .iter()
                .flat_map(|e| {
                    (0..dim * dim).map(move |k| {
                        let (r, col) = (dof(e, k / dim), dof(e, k % dim));
                        let stored = !lower_only || r >= col;
                        if stored && r / 3 != pinned {
                            (r * n + col) as u32
                        } else {
                            NO_SLOT
                        }
                    })
                })
                .collect()
        };
        let slot = full(true);
        let packed = pack_symmetric_slots(&slot, dim).expect("a lower map packs");
        assert_eq!(packed.len(), elems.len() * 78);
        let value = |e: usize, k: usize| ((e * 31 + k) as f64).sqrt() + (k / dim) as f64 * 1e-3;
        let mut outs = [vec![0.0; n * n], vec![0.0; n * n]];
        for (out, map) in outs.iter_mut().zip([&slot, &packed]) {
            scatter_element_hessians(out, map, dim, false, &c, |e, h| {
                for (k, v) in h.iter_mut().enumerate() {
                    *v = value(e, k);
                }
            });
        }
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&outs[0]), bits(&outs[1]));
        assert!(outs[0].iter().filter(|v| **v != 0.0).count() > 100);
        assert_eq!(pack_symmetric_slots(&full(false), dim), None);
    }
}
