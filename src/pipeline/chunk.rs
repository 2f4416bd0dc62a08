//! Chunks of a clip for render farms: a run limited to `--frames A:B` writes, next to its
//! glTF, a chunk file with its exact frames (f64) and what identifies the run; `furrow merge`
//! checks the chunks belong together, joins them, and exports one file byte-identical to an
//! unsplit run (the export is a pure function of the frames).
//!
//! A pre-rolled chunk (`--preroll P`) simulates from rest P frames before its first: chunks
//! then run in parallel, may overlap, and [`join`] cross-fades them over their overlap; it
//! refuses a mix of exact and pre-rolled chunks.
//!
//! Format: the 8 bytes `FURROWC1`, a little-endian u64 length, a JSON header of that length
//! ([`ChunkHeader`]), then the positions of every frame as little-endian f64 (x, y, z per
//! vertex, frame after frame), then, when the header says so, every frame's wrinkle offset
//! (the position minus the blend shapes' surface) as little-endian f32.

use super::frames::FrameRange;
use crate::io::atomic::{self, Overwrite};
use crate::io::origin::VertexOrigin;
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
    /// Frames simulated from rest before the first written one; `None` for an exact chunk
    /// (the clip's whole history simulated).
    #[serde(default)]
    pub preroll: Option<usize>,
    /// The skin's critical wavelength λ (m; 0 when unknown): the seams' amplitude regions
    /// are 2λ wide.
    #[serde(default)]
    pub wavelength_m: f64,
    /// Whether the wrinkle offsets follow the positions.
    #[serde(default)]
    pub offsets: bool,
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
    /// Wrinkle offsets per frame (m): positions minus the blend shapes' surface; empty when
    /// the chunk does not carry them.
    pub offsets: Vec<Vec<Vector3<f64>>>,
}

impl Chunk {
    /// The blend shapes' surface of each frame (m), when the chunk carries its offsets.
    pub fn smooth(&self) -> Option<Vec<Vec<Vector3<f64>>>> {
        (self.offsets.len() == self.frames.len()).then(|| {
            self.frames
                .iter()
                .zip(&self.offsets)
                .map(|(f, o)| f.iter().zip(o).map(|(p, d)| p - d).collect())
                .collect()
        })
    }
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

/// Write a chunk file atomically: the frames' positions (m) and, when the header says so,
/// their wrinkle `offsets` (m).
pub fn write(
    path: &Path,
    header: &ChunkHeader,
    frames: &[Vec<Vector3<f64>>],
    offsets: &[Vec<Vector3<f64>>],
    overwrite: Overwrite,
) -> anyhow::Result<()> {
    let json = serde_json::to_vec(header)?;
    let mut bytes = Vec::with_capacity(16 + json.len() + frames.len() * header.vertices * 36);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&(json.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&json);
    let offsets = if header.offsets { offsets } else { &[] };
    if header.offsets && offsets.len() != frames.len() {
        bail!(
            "chunk has {} frames but {} offsets",
            frames.len(),
            offsets.len()
        );
    }
    for f in frames.iter().chain(offsets) {
        if f.len() != header.vertices {
            bail!(
                "chunk frame has {} vertices, header says {}",
                f.len(),
                header.vertices
            );
        }
    }
    for p in frames.iter().flatten() {
        p.iter()
            .for_each(|c| bytes.extend_from_slice(&c.to_le_bytes()));
    }
    for d in offsets.iter().flatten() {
        d.iter()
            .for_each(|&c| bytes.extend_from_slice(&(c as f32).to_le_bytes()));
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
    let per_offset = if header.offsets {
        header.vertices * 12
    } else {
        0
    };
    let count = header.range.len();
    if per_frame == 0 || body.len() != (per_frame + per_offset) * count {
        return Err(bad(&format!(
            "{} bytes of frames, expected {} frames of {} vertices",
            body.len(),
            count,
            header.vertices
        )));
    }
    let (positions, offsets) = body.split_at(per_frame * count);
    let f64s = |b: &[u8]| f64::from_le_bytes(b.try_into().expect("8 bytes"));
    let f32s = |b: &[u8]| f64::from(f32::from_le_bytes(b.try_into().expect("4 bytes")));
    let frames =
        vectors(positions, per_frame, 8, f64s).ok_or_else(|| bad("a non-finite position"))?;
    let offsets = if per_offset > 0 {
        vectors(offsets, per_offset, 4, f32s).ok_or_else(|| bad("a non-finite offset"))?
    } else {
        Vec::new()
    };
    Ok(Chunk {
        header,
        frames,
        offsets,
    })
}

/// Frames of `per_frame` bytes of 3-vectors, each number `width` bytes read by `number`;
/// `None` when one is not finite.
fn vectors(
    body: &[u8],
    per_frame: usize,
    width: usize,
    number: impl Fn(&[u8]) -> f64,
) -> Option<Vec<Vec<Vector3<f64>>>> {
    body.chunks_exact(per_frame)
        .map(|f| {
            let v: Vec<f64> = f.chunks_exact(width).map(&number).collect();
            v.iter().all(|x| x.is_finite()).then(|| {
                v.chunks_exact(3)
                    .map(|p| Vector3::new(p[0], p[1], p[2]))
                    .collect()
            })
        })
        .collect()
}

/// Where two neighbouring chunks of a merge meet.
#[derive(Debug, Clone)]
pub struct Seam {
    /// The earlier chunk's file.
    pub before: String,
    /// The later chunk's file.
    pub after: String,
    /// The frames both chunks wrote (empty, at the later chunk's first frame, when they
    /// only touch).
    pub overlap: FrameRange,
    /// The earlier chunk's frames over the overlap (m).
    pub before_frames: Vec<Vec<Vector3<f64>>>,
    /// The later chunk's frames over the overlap (m).
    pub after_frames: Vec<Vec<Vector3<f64>>>,
}

/// Chunks joined: the whole they cover and their seams.
#[derive(Debug, Clone)]
pub struct Joined {
    /// The frames of every chunk in one, over the overlaps cross-faded.
    pub chunk: Chunk,
    /// Each pair of neighbours, in order.
    pub seams: Vec<Seam>,
}

/// Join chunks of one run into the whole [start, end) they cover, checking they share rig,
/// settings, fps and topology and tile the range without gap. Exact chunks may not overlap;
/// pre-rolled ones may, and over an overlap of O frames the later chunk's frame j (0-based)
/// takes weight (j + 1)/(O + 1), the earlier the rest; a mix of the two kinds is refused.
pub fn join(mut chunks: Vec<(String, Chunk)>) -> anyhow::Result<Joined> {
    if chunks.is_empty() {
        bail!("no chunks to merge");
    }
    chunks.sort_by_key(|(_, c)| (c.header.range.start, c.header.range.end));
    let (first_name, first) = &chunks[0];
    let h0 = first.header.clone();
    let prerolled = h0.preroll.is_some();
    let with_offsets = chunks.iter().all(|(_, c)| c.header.offsets);
    let mut frames: Vec<Vec<Vector3<f64>>> = Vec::new();
    let mut offsets: Vec<Vec<Vector3<f64>>> = Vec::new();
    let mut seams = Vec::new();
    let mut next = h0.range.start;
    for (i, (name, c)) in chunks.iter().enumerate() {
        let h = &c.header;
        same_run(&h0, first_name, h, name)?;
        if h.preroll.is_some() != prerolled {
            bail!(
                "{name} is {} but {first_name} is {}: exact and pre-rolled chunks cannot be \
                 merged together (make every chunk with or without --preroll)",
                kind(h),
                kind(&h0)
            );
        }
        let start = h.range.start;
        if start > next {
            bail!(
                "frames {next}:{start} are missing between the chunks (next chunk {name} starts at {start})"
            );
        }
        let overlap = next - start;
        if i > 0 && overlap > 0 && !prerolled {
            bail!(
                "{name}: frames {}:{} overlap the previous chunk (ends at {next})",
                start,
                h.range.end
            );
        }
        if i > 0 && h.range.end <= next {
            bail!(
                "{name}: frames {start}:{} lie within the previous chunks",
                h.range.end
            );
        }
        let base = frames.len() - overlap;
        if i > 0 {
            seams.push(Seam {
                before: chunks[i - 1].0.clone(),
                after: name.clone(),
                overlap: FrameRange { start, end: next },
                before_frames: frames[base..].to_vec(),
                after_frames: c.frames[..overlap].to_vec(),
            });
        }
        for j in 0..overlap {
            let t = (j + 1) as f64 / (overlap + 1) as f64;
            cross_fade(&mut frames[base + j], &c.frames[j], t);
            if with_offsets {
                cross_fade(&mut offsets[base + j], &c.offsets[j], t);
            }
        }
        frames.extend(c.frames[overlap..].iter().cloned());
        if with_offsets {
            offsets.extend(c.offsets[overlap..].iter().cloned());
        }
        next = h.range.end;
    }
    let mut header = h0;
    header.range = FrameRange {
        start: header.range.start,
        end: next,
    };
    header.offsets = with_offsets;
    Ok(Joined {
        chunk: Chunk {
            header,
            frames,
            offsets,
        },
        seams,
    })
}

/// What kind of chunk `h` is, for messages.
fn kind(h: &ChunkHeader) -> String {
    match h.preroll {
        Some(p) => format!("pre-rolled ({p} frames)"),
        None => "exact".into(),
    }
}

/// Refuse chunk `h` (file `name`) when it is not of the run of `h0` (file `first`): another
/// rig file, other settings or fps, or another skin topology.
pub fn same_run(h0: &ChunkHeader, first: &str, h: &ChunkHeader, name: &str) -> anyhow::Result<()> {
    if h.rig_hash != h0.rig_hash {
        bail!("{name}: made from another rig file than {first}");
    }
    if h.settings_hash != h0.settings_hash || h.fps != h0.fps {
        bail!("{name}: made with other settings (scene, fps or mesh) than {first}");
    }
    if h.vertices != h0.vertices
        || h.triangles != h0.triangles
        || h.origin != h0.origin
        || h.face_map != h0.face_map
    {
        bail!("{name}: its skin topology differs from {first}'s");
    }
    Ok(())
}

/// `a` ← (1 − t) a + t b, per vertex.
fn cross_fade(a: &mut [Vector3<f64>], b: &[Vector3<f64>], t: f64) {
    for (p, q) in a.iter_mut().zip(b) {
        *p += t * (q - *p);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chunk of one vertex whose frame k stands at x = k + `shift`, its offset at z.
    fn chunk_at(start: usize, end: usize, preroll: Option<usize>, shift: f64) -> Chunk {
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
                preroll,
                wavelength_m: 0.02,
                offsets: true,
            },
            frames: (start..end)
                .map(|k| vec![Vector3::new(k as f64 + shift, 0.5, -1.0)])
                .collect(),
            offsets: (start..end)
                .map(|_| vec![Vector3::new(0.0, 0.0, 0.25 + shift)])
                .collect(),
        }
    }

    fn chunk(start: usize, end: usize) -> Chunk {
        chunk_at(start, end, None, 0.0)
    }

    #[test]
    fn chunks_round_trip_and_join_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.chunk");
        let c = chunk(3, 6);
        write(&p, &c.header, &c.frames, &c.offsets, Overwrite::Refuse).unwrap();
        let r = read(&p).unwrap();
        assert_eq!(r.header, c.header);
        assert_eq!(r.frames, c.frames);
        assert_eq!(r.offsets, c.offsets);
        assert_eq!(r.smooth().unwrap()[0][0].z, -1.25);
        let j = join(vec![("b".into(), chunk(3, 10)), ("a".into(), chunk(0, 3))]).unwrap();
        assert_eq!(j.chunk.header.range, FrameRange { start: 0, end: 10 });
        assert_eq!(j.chunk.frames[7][0].x, 7.0);
        assert_eq!(j.seams.len(), 1);
        assert!(j.seams[0].overlap.is_empty() && j.seams[0].overlap.start == 3);
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

    #[test]
    fn pre_rolled_chunks_cross_fade_over_their_overlap_and_refuse_exact_ones() {
        // Frames 3 and 4 are written by both; the later chunk stands 3 m further along x.
        let a = chunk_at(0, 5, Some(4), 0.0);
        let b = chunk_at(3, 10, Some(4), 3.0);
        let j = join(vec![("b".into(), b), ("a".into(), a.clone())]).unwrap();
        assert_eq!(j.chunk.header.range, FrameRange { start: 0, end: 10 });
        assert_eq!(j.chunk.frames.len(), 10);
        // Weights 1/3 and 2/3 of the later chunk over the two shared frames.
        assert!((j.chunk.frames[3][0].x - (3.0 + 1.0)).abs() < 1e-12);
        assert!((j.chunk.frames[4][0].x - (4.0 + 2.0)).abs() < 1e-12);
        assert_eq!(j.chunk.frames[5][0].x, 8.0);
        assert!((j.chunk.offsets[3][0].z - 1.25).abs() < 1e-12);
        let seam = &j.seams[0];
        assert_eq!(seam.overlap, FrameRange { start: 3, end: 5 });
        assert_eq!(seam.before_frames[0][0].x, 3.0);
        assert_eq!(seam.after_frames[0][0].x, 6.0);
        let e = join(vec![("a".into(), a), ("c".into(), chunk(5, 10))]).unwrap_err();
        assert!(format!("{e:#}").contains("exact and pre-rolled"), "{e:#}");
        let inside = join(vec![
            ("a".into(), chunk_at(0, 8, Some(2), 0.0)),
            ("b".into(), chunk_at(2, 6, Some(2), 0.0)),
        ]);
        assert!(format!("{:#}", inside.unwrap_err()).contains("within"));
    }
}
