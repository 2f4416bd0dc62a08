//! `furrow bench shell`: a compressed square sheet solved to equilibrium.

/// Run the shell benchmark on a sheet of about `faces` triangles and return its measurements
/// as a flat JSON object (faces, vertices, iterations, residual, times in seconds).
pub fn bench_shell(faces: usize) -> anyhow::Result<serde_json::Value> {
    anyhow::bail!("bench shell is not built yet ({faces} faces requested)")
}
