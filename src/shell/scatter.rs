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
/// ([`crate::math::Energy::hessian_scatter`]); slots out of range panic.
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
    assert_eq!(
        slot.len(),
        colouring.elements() * len,
        "one slot per triplet"
    );
    let (ptr, n) = (Values(out.as_mut_ptr()), out.len());
    for colour in &colouring.colours {
        colour.par_iter().with_min_len(64).for_each(|&e| {
            let e = e as usize;
            let mut h = [0.0; 144];
            block(e, &mut h[..len]);
            if project {
                project_psd(&mut h[..len], dim);
            }
            let p = ptr;
            for (k, &s) in slot[e * len..(e + 1) * len].iter().enumerate() {
                if s != NO_SLOT {
                    let s = s as usize;
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
}
