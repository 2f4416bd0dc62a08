//! The glTF container: `.glb` (JSON chunk + binary chunk) or `.gltf` (JSON with external or
//! embedded `data:` buffers), parsed into the JSON document and the resolved buffer bytes.

use super::error::{GltfError, GltfResult};
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
    /// True when the file was binary (`.glb`).
    pub binary: bool,
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
pub fn read(path: &Path) -> GltfResult<Container> {
    let bytes = std::fs::read(path)
        .map_err(|e| GltfError::new(path, format!("cannot read the file: {e}")))?;
    parse(path, &bytes)
}

/// Parse glTF bytes that came from `path` (the path names errors and anchors relative URIs).
pub fn parse(path: &Path, bytes: &[u8]) -> GltfResult<Container> {
    let (json_bytes, bin) = split_chunks(path, bytes)?;
    let (json, root) = parse_document(path, json_bytes)?;
    let buffers = resolve_buffers(path, &json, &root, bin)?;
    Ok(Container {
        json,
        root,
        buffers,
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

fn resolve_buffers(
    path: &Path,
    json: &serde_json::Value,
    root: &gltf_json::Root,
    bin: Option<&[u8]>,
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
                let decoded = percent_decode(uri);
                if decoded.contains("://") {
                    return Err(err(format!("buffer {i}: remote URI {uri:?} is not supported; download it next to the file")));
                }
                let p = path.parent().unwrap_or(Path::new(".")).join(&decoded);
                std::fs::read(&p).map_err(|e| {
                    err(format!(
                        "buffer {i}: cannot read external buffer {}: {e}",
                        p.display()
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

/// Decode `%XX` escapes in a relative URI.
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            if let Ok(v) = u8::from_str_radix(&s[i + 1..i + 3], 16) {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
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
        let e = parse(Path::new("x.glb"), &b)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("x.glb") && e.contains("length of 5"), "{e}");
        let e = parse(Path::new("y.glb"), b"glTF\x02\0")
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("cut short"), "{e}");
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.bin"), "a b.bin");
        assert_eq!(percent_decode("plain.bin"), "plain.bin");
        assert_eq!(percent_decode("bad%2"), "bad%2");
    }
}
