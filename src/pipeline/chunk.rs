//! Chunks of a clip for render farms: a run limited to `--frames A:B` writes, next to its
//! glTF, a chunk file with its exact frames (f64) and what identifies the run; `furrow merge`
//! checks the chunks belong together, joins them, and exports one file byte-identical to an
//! unsplit run (the export is a pure function of the frames).
//!
//! Format: the 8 bytes `FURROWC1`, a little-endian u64 length, a JSON header of that length
//! ([`ChunkHeader`]), then the positions of every frame as little-endian f64 (x, y, z per
//! vertex, frame after frame).

use super::frames::FrameRange;
use crate::io::atomic::{self, Overwrite};
use crate::io::export::VertexOrigin;
use crate::io::split::FaceMap;
use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::Path;

const MAGIC: &[u8; 8] = b"FURROWC1";

/// What identifies a chunk and its place in the clip.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChunkHeader {
    /// FNV-1a 64 hash of the rig file's bytes (hex).
    pub rig_hash: String,
    /// Hash of the settings (scene after defaults, fps, mesh choice) (hex).
    pub settings_hash: String,
    /// Frames per second.
    pub fps: f64,
    /// Frames of this chunk.
    pub range: FrameRange,
    /// Frames in the whole clip.
    pub clip_frames: usize,
    /// Vertices per frame.
    pub vertices: usize,
    /// Exported triangles.
    pub triangles: Vec<[usize; 3]>,
    /// Exported vertex origins (loaded vertices, weights).
    pub origin: Vec<([usize; 3], [f64; 3])>,
    /// Metres per file unit the frames were simulated at (their positions are in simulated
    /// metres; `merge` writes them back in the file's units).
    #[serde(default = "one")]
    pub metres_per_unit: f64,
    /// How the refined skin maps onto the loaded face (the wrinkle layer needs it; empty in
    /// chunks from before it existed).
    #[serde(default)]
    pub face_map: FaceMap,
}

/// Chunks written before the rig scale existed were simulated as in the file.
fn one() -> f64 {
    1.0
}

/// A chunk read back.
#[derive(Debug, Clone)]
pub struct Chunk {
    /// Its header.
    pub header: ChunkHeader,
    /// Positions per frame (m).
    pub frames: Vec<Vec<Vector3<f64>>>,
}

/// FNV-1a 64 of bytes, as 16 hex digits.
pub fn fnv64(bytes: &[u8]) -> String {
    let mut h = crate::math::hash::Fnv1a::new();
    for &b in bytes {
        h.mix(u64::from(b));
    }
    format!("{:016x}", h.finish())
}

/// Origins as plain arrays (for the header).
pub fn origin_to_plain(o: &[VertexOrigin]) -> Vec<([usize; 3], [f64; 3])> {
    o.iter().map(|v| (v.vertices, v.weights)).collect()
}

/// Origins from plain arrays.
pub fn origin_from_plain(o: &[([usize; 3], [f64; 3])]) -> Vec<VertexOrigin> {
    o.iter()
        .map(|&(vertices, weights)| VertexOrigin { vertices, weights })
        .collect()
}

/// Write a chunk file atomically.
pub fn write(
    path: &Path,
    header: &ChunkHeader,
    frames: &[Vec<Vector3<f64>>],
    overwrite: Overwrite,
) -> anyhow::Result<()> {
    let json = serde_json::to_vec(header)?;
    let mut bytes = Vec::with_capacity(16 + json.len() + frames.len() * header.vertices * 24);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&(json.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&json);
    for f in frames {
        if f.len() != header.vertices {
            bail!(
                "chunk frame has {} vertices, header says {}",
                f.len(),
                header.vertices
            );
        }
        for p in f {
            for c in p.iter() {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    atomic::write(path, &bytes, overwrite)
}

/// Read a chunk file, checking its layout.
pub fn read(path: &Path) -> anyhow::Result<Chunk> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let bad = |m: &str| anyhow::anyhow!("{}: not a furrow chunk file ({m})", path.display());
    if bytes.len() < 16 || &bytes[..8] != MAGIC {
        return Err(bad("wrong magic"));
    }
    let n = u64::from_le_bytes(bytes[8..16].try_into().expect("8 bytes")) as usize;
    let json = bytes
        .get(16..16usize.checked_add(n).ok_or_else(|| bad("header length"))?)
        .ok_or_else(|| bad("truncated header"))?;
    let header: ChunkHeader =
        serde_json::from_slice(json).map_err(|e| bad(&format!("header: {e}")))?;
    let body = &bytes[16 + n..];
    let per_frame = header.vertices * 24;
    if per_frame == 0 || body.len() != per_frame * header.range.len() {
        return Err(bad(&format!(
            "{} bytes of frames, expected {} frames of {} vertices",
            body.len(),
            header.range.len(),
            header.vertices
        )));
    }
    let mut frames = Vec::with_capacity(header.range.len());
    for f in body.chunks_exact(per_frame) {
        let v: Vec<f64> = f
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
            .collect();
        if v.iter().any(|x| !x.is_finite()) {
            return Err(bad("a non-finite position"));
        }
        frames.push(
            v.chunks_exact(3)
                .map(|p| Vector3::new(p[0], p[1], p[2]))
                .collect(),
        );
    }
    Ok(Chunk { header, frames })
}

/// Join chunks of one run into the whole [start, end) they cover, checking they share rig,
/// settings, fps and topology and tile the range without gap or overlap.
pub fn join(mut chunks: Vec<(String, Chunk)>) -> anyhow::Result<Chunk> {
    if chunks.is_empty() {
        bail!("no chunks to merge");
    }
    chunks.sort_by_key(|(_, c)| c.header.range.start);
    let (first_name, first) = &chunks[0];
    let h0 = first.header.clone();
    let mut frames = Vec::new();
    let mut next = h0.range.start;
    for (name, c) in &chunks {
        let h = &c.header;
        if h.rig_hash != h0.rig_hash {
            bail!("{name}: made from another rig file than {first_name}");
        }
        if h.settings_hash != h0.settings_hash || h.fps != h0.fps {
            bail!("{name}: made with other settings (scene, fps or mesh) than {first_name}");
        }
        if h.vertices != h0.vertices
            || h.triangles != h0.triangles
            || h.origin != h0.origin
            || h.face_map != h0.face_map
        {
            bail!("{name}: its skin topology differs from {first_name}'s");
        }
        if h.range.start != next {
            if h.range.start < next {
                bail!(
                    "{name}: frames {}:{} overlap the previous chunk (ends at {next})",
                    h.range.start,
                    h.range.end
                );
            }
            bail!(
                "frames {next}:{} are missing between the chunks (next chunk {name} starts at {})",
                h.range.start,
                h.range.start
            );
        }
        next = h.range.end;
        frames.extend(c.frames.iter().cloned());
    }
    let mut header = h0;
    header.range = FrameRange {
        start: header.range.start,
        end: next,
    };
    Ok(Chunk { header, frames })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chunk(start: usize, end: usize) -> Chunk {
        Chunk {
            header: ChunkHeader {
                rig_hash: "r".into(),
                settings_hash: "s".into(),
                fps: 30.0,
                range: FrameRange { start, end },
                clip_frames: 10,
                vertices: 1,
                triangles: vec![],
                origin: vec![([0, 0, 0], [1.0, 0.0, 0.0])],
                metres_per_unit: 1.0,
                face_map: FaceMap::default(),
            },
            frames: (start..end)
                .map(|k| vec![Vector3::new(k as f64, 0.5, -1.0)])
                .collect(),
        }
    }

    #[test]
    fn chunks_round_trip_and_join_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.chunk");
        let c = chunk(3, 6);
        write(&p, &c.header, &c.frames, Overwrite::Refuse).unwrap();
        let r = read(&p).unwrap();
        assert_eq!(r.header, c.header);
        assert_eq!(r.frames, c.frames);
        let j = join(vec![("b".into(), chunk(3, 10)), ("a".into(), chunk(0, 3))]).unwrap();
        assert_eq!(j.header.range, FrameRange { start: 0, end: 10 });
        assert_eq!(j.frames[7][0].x, 7.0);
        let gap = join(vec![("a".into(), chunk(0, 3)), ("b".into(), chunk(4, 10))]);
        assert!(format!("{:#}", gap.unwrap_err()).contains("missing"));
        let over = join(vec![("a".into(), chunk(0, 5)), ("b".into(), chunk(4, 10))]);
        assert!(format!("{:#}", over.unwrap_err()).contains("overlap"));
        let mut other = chunk(3, 10);
        other.header.rig_hash = "x".into();
        let e = join(vec![("a".into(), chunk(0, 3)), ("b".into(), other)]);
        assert!(format!("{:#}", e.unwrap_err()).contains("another rig"));
        std::fs::write(
            dir.path().join("bad"),
            b"FURROWC1\xff\xff\xff\xff\xff\xff\xff\xff",
        )
        .unwrap();
        assert!(read(&dir.path().join("bad")).is_err());
    }
}
