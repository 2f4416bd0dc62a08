//! `EXT_meshopt_compression` buffer views, decoded with the meshoptimizer library (`meshopt`).

use super::error::{GltfError, GltfResult};
use std::path::Path;

/// Decode one compressed buffer view described by its `EXT_meshopt_compression` object `ext`,
/// reading the compressed bytes from `buffers`. Returns `count × byteStride` bytes.
pub fn decode(
    path: &Path,
    view: usize,
    ext: &serde_json::Value,
    buffers: &[Vec<u8>],
) -> GltfResult<Vec<u8>> {
    let err = |m: String| GltfError::new(path, format!("bufferView {view} (EXT_meshopt_compression): {m}"));
    let get = |k: &str| ext[k].as_u64().map(|v| v as usize);
    let buffer = get("buffer").ok_or_else(|| err("missing 'buffer'".into()))?;
    let offset = get("byteOffset").unwrap_or(0);
    let length = get("byteLength").ok_or_else(|| err("missing 'byteLength'".into()))?;
    let stride = get("byteStride").ok_or_else(|| err("missing 'byteStride'".into()))?;
    let count = get("count").ok_or_else(|| err("missing 'count'".into()))?;
    let mode = ext["mode"].as_str().unwrap_or("");
    let filter = ext["filter"].as_str().unwrap_or("NONE");
    let src = buffers
        .get(buffer)
        .ok_or_else(|| err(format!("buffer {buffer} does not exist")))?;
    let end = offset.checked_add(length).ok_or_else(|| err("byte range overflows".into()))?;
    let src = src.get(offset..end).ok_or_else(|| {
        err(format!("compressed bytes {offset}..{end} lie outside buffer {buffer} ({} bytes)", src.len()))
    })?;
    let size = count.checked_mul(stride).filter(|&s| s <= 1 << 31).ok_or_else(|| {
        err(format!("count {count} × byteStride {stride} is too large"))
    })?;
    let mut dst = vec![0u8; size];
    // meshoptimizer asserts (aborts) on invalid sizes, so every parameter is checked first.
    let rc = match mode {
        "ATTRIBUTES" => {
            if stride == 0 || stride > 256 || stride % 4 != 0 {
                return Err(err(format!("ATTRIBUTES byteStride {stride} must be a multiple of 4 in 4..=256")));
            }
            // SAFETY: dst holds count*stride bytes; src is a valid slice.
            unsafe {
                meshopt::ffi::meshopt_decodeVertexBuffer(
                    dst.as_mut_ptr().cast(),
                    count,
                    stride,
                    src.as_ptr(),
                    src.len(),
                )
            }
        }
        "TRIANGLES" | "INDICES" => {
            if stride != 2 && stride != 4 {
                return Err(err(format!("{mode} byteStride {stride} must be 2 or 4")));
            }
            if mode == "TRIANGLES" && count % 3 != 0 {
                return Err(err(format!("TRIANGLES count {count} is not a multiple of 3")));
            }
            // SAFETY: as above; index size is 2 or 4 and the count a multiple of 3 for triangles.
            unsafe {
                if mode == "TRIANGLES" {
                    meshopt::ffi::meshopt_decodeIndexBuffer(
                        dst.as_mut_ptr().cast(),
                        count,
                        stride,
                        src.as_ptr(),
                        src.len(),
                    )
                } else {
                    meshopt::ffi::meshopt_decodeIndexSequence(
                        dst.as_mut_ptr().cast(),
                        count,
                        stride,
                        src.as_ptr(),
                        src.len(),
                    )
                }
            }
        }
        other => return Err(err(format!("unknown mode {other:?}"))),
    };
    if rc != 0 {
        return Err(err(format!("compressed data is corrupt (meshopt error {rc})")));
    }
    if mode == "ATTRIBUTES" {
        // SAFETY: strides are checked against what each filter accepts.
        unsafe {
            match filter {
                "NONE" => {}
                "OCTAHEDRAL" if stride == 4 || stride == 8 => {
                    meshopt::ffi::meshopt_decodeFilterOct(dst.as_mut_ptr().cast(), count, stride)
                }
                "QUATERNION" if stride == 8 => {
                    meshopt::ffi::meshopt_decodeFilterQuat(dst.as_mut_ptr().cast(), count, stride)
                }
                "EXPONENTIAL" if stride % 4 == 0 => {
                    meshopt::ffi::meshopt_decodeFilterExp(dst.as_mut_ptr().cast(), count, stride)
                }
                other => {
                    return Err(err(format!("filter {other:?} is unknown or does not fit byteStride {stride}")))
                }
            }
        }
    } else if filter != "NONE" {
        return Err(err(format!("filter {filter:?} is only allowed with ATTRIBUTES")));
    }
    Ok(dst)
}
