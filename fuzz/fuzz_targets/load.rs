//! Fuzz the glTF loader: any bytes must give a rig or a clean error, never a panic or abort.
//! A rig that loads is also blended at its first frame and written back decoded (the path the
//! export reads every view through, meshopt and sparse accessors included).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("/nonexistent-fuzz-dir/input.glb");
    if let Ok(rig) = furrow::io::load::load_bytes(path, data, &Default::default()) {
        let w = rig.frame_weights(30.0);
        if let Some(first) = w.first() {
            let _ = rig.blend(first);
        }
        let _ = furrow::io::export::decoded_glb(&rig);
    }
});
