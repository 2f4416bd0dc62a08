//! The glTF container: `.glb` (JSON chunk + binary chunk) or `.gltf` (JSON with external or
//! embedded `data:` buffers), parsed into the JSON document and the resolved buffer bytes.

use super::error::{GltfError, GltfResult};
use super::uri::{self, Refusal, Resolved};
use base64::Engine;
use std::path::Path;

/// A parsed glTF file: its JSON (kept verbatim for lossless re-export), the typed root, and
/// the bytes of every buffer (index = buffer index).
pub struct Container {
    /// The JSON document exactly as read.
    pub json: serde_json::Value,
    /// The typed view of the same document.
    pub root: gltf_json::Root,
    /// Bytes of each buffer; a meshopt fallback buffer with no data is empty.
    pub buffers: Vec<Vec<u8>>,
    /// Where each image's bytes are (index = image index).
    pub images: Vec<ImageSource>,
    /// True when the file was binary (`.glb`).
    pub binary: bool,
}

/// How a file is read.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Read buffer and image files outside the rig's folder (absolute paths, `..`, symlinks
    /// out); refused by default.
    pub allow_outside_paths: bool,
}

/// Where the bytes of one of the file's images are, as judged when the file was read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ImageSource {
    /// In the file itself: a buffer view or a `data:` URI.
    Embedded,
    /// In an external file, judged against the rig's folder (unless outside paths are
    /// allowed); the export reads it from there.
    File(Resolved),
    /// In an external file furrow cannot read (remote, or not found when the rig was read);
    /// the export refuses it with this message.
    Unreadable(String),
}

/// Extensions furrow reads; a file requiring any other is refused.
pub const SUPPORTED_REQUIRED: &[&str] = &[
    "KHR_mesh_quantization",
    "EXT_meshopt_compression",
    "KHR_texture_transform",
    "KHR_materials_unlit",
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "KHR_materials_emissive_strength",
];

/// The byte a `.gltf` file's JSON text starts with (after white space): `{`.
const JSON_OBJECT_START: u8 = b'{';

/// Read and parse the file at `path`.
pub fn read(path: &Path, opts: ReadOptions) -> GltfResult<Container> {
    let bytes = std::fs::read(path)
        .map_err(|e| GltfError::new(path, format!("cannot read the file: {e}")))?;
    parse(path, &bytes, opts)
}

/// Parse glTF bytes that came from `path` (the path names errors and anchors relative URIs;
/// buffer and image URIs must stay in its folder unless `opts` allows outside paths).
pub fn parse(path: &Path, bytes: &[u8], opts: ReadOptions) -> GltfResult<Container> {
    let (json_bytes, bin) = split_chunks(path, bytes)?;
    let (json, root) = parse_document(path, json_bytes)?;
    let buffers = resolve_buffers(path, &json, &root, bin, opts)?;
    let images = resolve_images(path, &json, opts)?;
    Ok(Container {
        json,
        root,
        buffers,
        images,
        binary: bin.is_some() || bytes.starts_with(b"glTF"),
    })
}

/// The JSON text and the GLB binary chunk (if any) of a `.glb` or `.gltf` file's bytes.
fn split_chunks<'b>(path: &Path, bytes: &'b [u8]) -> GltfResult<(&'b [u8], Option<&'b [u8]>)> {
    if bytes.starts_with(b"glTF") {
        glb_chunks(path, bytes)
    } else {
        let first = bytes.iter().find(|b| !b.is_ascii_whitespace());
        if first != Some(&JSON_OBJECT_START) {
            return Err(GltfError::new(
                path,
                "not a glTF file: neither a GLB header ('glTF') nor a JSON object".to_string(),
            ));
        }
        Ok((bytes, None))
    }
}

/// The JSON chunk and the binary chunk (if any) of a GLB container, refusing a corrupt
/// header or a version other than 2.
fn glb_chunks<'b>(path: &Path, bytes: &'b [u8]) -> GltfResult<(&'b [u8], Option<&'b [u8]>)> {
    let err = |m: String| GltfError::new(path, m);
    // The header's total length must cover at least the header itself (the gltf crate
    // subtracts without checking; found by fuzzing).
    let declared = bytes
        .get(8..12)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
    match declared {
        Some(n) if n >= 12 => {}
        Some(n) => {
            return Err(err(format!(
                "not a valid GLB container: header declares a total length of {n} bytes"
            )))
        }
        None => {
            return Err(err(
                "not a valid GLB container: the file is cut short inside the 12-byte header".into(),
            ))
        }
    }
    let glb = gltf::binary::Glb::from_slice(bytes).map_err(|e| {
        err(format!(
            "not a valid GLB container (cut short or corrupt): {e}"
        ))
    })?;
    if glb.header.version != 2 {
        return Err(err(format!(
            "GLB version {} is not glTF 2.0",
            glb.header.version
        )));
    }
    let json: &[u8] = match glb.json {
        std::borrow::Cow::Borrowed(b) => b,
        std::borrow::Cow::Owned(_) => unreachable!("Glb::from_slice borrows"),
    };
    let bin = glb.bin.map(|b| match b {
        std::borrow::Cow::Borrowed(b) => b,
        std::borrow::Cow::Owned(_) => unreachable!("Glb::from_slice borrows"),
    });
    Ok((json, bin))
}

/// The JSON document and its typed root, refusing anything but glTF 2.0 and required
/// extensions outside [`SUPPORTED_REQUIRED`].
fn parse_document(
    path: &Path,
    json_bytes: &[u8],
) -> GltfResult<(serde_json::Value, gltf_json::Root)> {
    let err = |m: String| GltfError::new(path, m);
    let json: serde_json::Value =
        serde_json::from_slice(json_bytes).map_err(|e| err(format!("broken JSON: {e}")))?;
    let root: gltf_json::Root = serde_json::from_value(json.clone())
        .map_err(|e| err(format!("JSON is not a valid glTF 2.0 document: {e}")))?;
    let version = root.asset.version.as_str();
    if !version.starts_with("2.") {
        return Err(err(format!(
            "asset.version is {version:?}; furrow reads glTF 2.0"
        )));
    }
    for ext in &root.extensions_required {
        if !SUPPORTED_REQUIRED.contains(&ext.as_str()) {
            return Err(err(format!(
                "requires extension {ext}, which furrow does not support (supported: {})",
                SUPPORTED_REQUIRED.join(", ")
            )));
        }
    }
    Ok((json, root))
}

fn is_meshopt_fallback(json: &serde_json::Value, index: usize) -> bool {
    json["buffers"][index]["extensions"]["EXT_meshopt_compression"]["fallback"]
        .as_bool()
        .unwrap_or(false)
}

/// The bytes of every buffer: the GLB binary chunk, a `data:` URI or a file in the rig's
/// folder (see [`uri::resolve`]).
fn resolve_buffers(
    path: &Path,
    json: &serde_json::Value,
    root: &gltf_json::Root,
    bin: Option<&[u8]>,
    opts: ReadOptions,
) -> GltfResult<Vec<Vec<u8>>> {
    let err = |m: String| GltfError::new(path, m);
    let mut out = Vec::with_capacity(root.buffers.len());
    for (i, b) in root.buffers.iter().enumerate() {
        let len = b.byte_length.0 as usize;
        let data = match &b.uri {
            None if is_meshopt_fallback(json, i) => Vec::new(),
            None => {
                if i != 0 {
                    return Err(err(format!(
                        "buffer {i} has no uri; only buffer 0 may use the GLB binary chunk"
                    )));
                }
                let bin = bin.ok_or_else(|| {
                    err("buffer 0 has no uri and the file has no GLB binary chunk".into())
                })?;
                bin.to_vec()
            }
            Some(uri) if uri.starts_with("data:") => {
                let comma = uri
                    .find(',')
                    .ok_or_else(|| err(format!("buffer {i}: malformed data URI (no comma)")))?;
                if !uri[..comma].ends_with(";base64") {
                    return Err(err(format!("buffer {i}: data URI is not base64")));
                }
                base64::engine::general_purpose::STANDARD
                    .decode(&uri[comma + 1..])
                    .map_err(|e| err(format!("buffer {i}: bad base64 in data URI: {e}")))?
            }
            Some(uri) => {
                let what = format!("buffer {i}");
                let file = uri::resolve(path, uri, opts.allow_outside_paths)
                    .map_err(|r| err(refusal_message(&what, uri, r)))?;
                std::fs::read(&file.path).map_err(|e| {
                    err(format!(
                        "{what}: cannot read external file {}: {e}",
                        file.path.display()
                    ))
                })?
            }
        };
        if !data.is_empty() && data.len() < len {
            return Err(err(format!(
                "buffer {i} is {} bytes but declares byteLength {len} (file cut short?)",
                data.len()
            )));
        }
        out.push(data);
    }
    Ok(out)
}

/// Where each image's bytes are. An image whose file lies outside the rig's folder is refused
/// (unless `opts` allows it); one that is remote or missing is refused by the export, which
/// reads it, not here (`inspect` and `fit` never read images).
fn resolve_images(
    path: &Path,
    json: &serde_json::Value,
    opts: ReadOptions,
) -> GltfResult<Vec<ImageSource>> {
    let Some(images) = json["images"].as_array() else {
        return Ok(Vec::new());
    };
    let mut out = Vec::with_capacity(images.len());
    for (i, im) in images.iter().enumerate() {
        let source = match im["uri"].as_str() {
            None => ImageSource::Embedded,
            Some(u) if u.starts_with("data:") => ImageSource::Embedded,
            Some(u) => match uri::resolve(path, u, opts.allow_outside_paths) {
                Ok(file) => ImageSource::File(file),
                Err(r @ Refusal::Outside { .. }) => {
                    return Err(GltfError::new(
                        path,
                        refusal_message(&format!("image {i}"), u, r),
                    ))
                }
                Err(r) => ImageSource::Unreadable(refusal_message(&format!("image {i}"), u, r)),
            },
        };
        out.push(source);
    }
    Ok(out)
}

/// The message for a URI `uri` of `what` (`buffer 0`, `image 2`) that gives no file.
fn refusal_message(what: &str, uri: &str, r: Refusal) -> String {
    let decoded = uri::percent_decode(uri);
    let shown = if decoded == uri {
        format!("'{uri}'")
    } else {
        format!("'{uri}' (decoded '{decoded}')")
    };
    match r {
        Refusal::Remote => format!(
            "{what}'s uri {shown} is remote, which is not supported; download it next to the file"
        ),
        Refusal::Outside { folder, why } => format!(
            "{what}'s uri {shown} lies outside the rig's folder {}: {why}; pass \
             --allow-outside-paths to read it",
            folder.display()
        ),
        Refusal::Unresolved { path, error } => {
            format!(
                "{what}: cannot read external file {}: {error}",
                path.display()
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Found by fuzzing: a GLB header whose declared length is below 12 bytes.
    #[test]
    fn glb_header_with_tiny_length_is_an_error_not_a_panic() {
        let mut b = b"glTF".to_vec();
        b.extend(2u32.to_le_bytes());
        b.extend(5u32.to_le_bytes());
        b.extend([0u8; 40]);
        let e = parse(Path::new("x.glb"), &b, ReadOptions::default())
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("x.glb") && e.contains("length of 5"), "{e}");
        let e = parse(Path::new("y.glb"), b"glTF\x02\0", ReadOptions::default())
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("cut short"), "{e}");
    }
}
