//! `furrow bench lattice`: one backward Euler step of a lattice of quadratic elements.

/// Run the lattice benchmark on about `elements` quadratic elements and return its
/// measurements as a flat JSON object (elements, nodes, times in seconds).
pub fn bench_lattice(elements: usize) -> anyhow::Result<serde_json::Value> {
    anyhow::bail!("bench lattice is not built yet ({elements} elements requested)")
}
