//! A rig reads only its own folder: buffer and image URIs that lead out of it (absolute paths,
//! `file:` URIs, `..`, percent-encoded `..`, symbolic links out) are refused with a message
//! naming the rig, the URI and what is wrong, unless outside paths are allowed.

mod common;

use furrow::io::{load, LoadOptions};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A rig's folder `root/rig` and beside it the tiny rig's buffer as `root/secret.bin`, and
/// under `root/outside/secret.bin`.
struct Layout {
    _keep: tempfile::TempDir,
    root: PathBuf,
    rig_dir: PathBuf,
    bin: Vec<u8>,
}

fn layout() -> Layout {
    let keep = tempfile::tempdir().unwrap();
    let root = keep.path().to_path_buf();
    let rig_dir = root.join("rig");
    std::fs::create_dir_all(&rig_dir).unwrap();
    std::fs::create_dir_all(root.join("outside")).unwrap();
    let (_, bin) = common::tiny_rig();
    std::fs::write(root.join("secret.bin"), &bin).unwrap();
    std::fs::write(root.join("outside/secret.bin"), &bin).unwrap();
    Layout {
        _keep: keep,
        root,
        rig_dir,
        bin,
    }
}

/// Write `rig.gltf` into `dir` with its buffer at `uri` (and `images`, if given).
fn write_rig(dir: &Path, uri: &str, images: Option<serde_json::Value>) -> PathBuf {
    let (mut j, _) = common::tiny_rig();
    j["buffers"][0]["uri"] = json!(uri);
    if let Some(im) = images {
        j["images"] = im;
    }
    let p = dir.join("rig.gltf");
    std::fs::write(&p, serde_json::to_vec_pretty(&j).unwrap()).unwrap();
    p
}

fn allowed() -> LoadOptions {
    LoadOptions {
        allow_outside_paths: true,
        ..Default::default()
    }
}

fn accepted(p: &Path, opts: &LoadOptions) {
    let rig = load(p, opts).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(rig.face().positions.len(), 4);
}

/// The rig at `p` is refused by default, the message naming it, `uri` and `words`.
fn refused(p: &Path, uri: &str, words: &[&str]) {
    let e = load(p, &LoadOptions::default())
        .err()
        .expect("refused")
        .to_string();
    for w in [
        "rig.gltf",
        &format!("'{uri}'"),
        "outside the rig's folder",
        "--allow-outside-paths",
    ]
    .iter()
    .chain(words)
    {
        assert!(e.contains(w), "message lacks {w:?}: {e}");
    }
}

#[test]
fn relative_uri_inside_the_folder_is_accepted() {
    let l = layout();
    std::fs::write(l.rig_dir.join("tiny.bin"), &l.bin).unwrap();
    accepted(
        &write_rig(&l.rig_dir, "tiny.bin", None),
        &Default::default(),
    );
}

#[test]
fn uri_in_a_subfolder_is_accepted() {
    let l = layout();
    std::fs::create_dir_all(l.rig_dir.join("data")).unwrap();
    std::fs::write(l.rig_dir.join("data/tiny.bin"), &l.bin).unwrap();
    accepted(
        &write_rig(&l.rig_dir, "data/tiny.bin", None),
        &Default::default(),
    );
}

#[test]
fn parent_folder_is_refused() {
    let l = layout();
    let p = write_rig(&l.rig_dir, "../secret.bin", None);
    refused(&p, "../secret.bin", &["buffer 0", "'..' climbs out"]);
}

#[test]
fn parent_folder_is_accepted_with_the_option() {
    let l = layout();
    accepted(&write_rig(&l.rig_dir, "../secret.bin", None), &allowed());
}

#[test]
fn absolute_path_is_refused() {
    let l = layout();
    let abs = l.root.join("secret.bin").display().to_string();
    let p = write_rig(&l.rig_dir, &abs, None);
    refused(&p, &abs, &["buffer 0"]);
}

#[test]
fn absolute_path_is_accepted_with_the_option() {
    let l = layout();
    let abs = l.root.join("secret.bin").display().to_string();
    accepted(&write_rig(&l.rig_dir, &abs, None), &allowed());
}

#[cfg(unix)]
#[test]
fn file_uri_is_refused() {
    let l = layout();
    let uri = format!("file://{}", l.root.join("secret.bin").display());
    let p = write_rig(&l.rig_dir, &uri, None);
    refused(&p, &uri, &["file: URI"]);
}

#[cfg(unix)]
#[test]
fn file_uri_is_accepted_with_the_option() {
    let l = layout();
    let uri = format!("file://{}", l.root.join("secret.bin").display());
    accepted(&write_rig(&l.rig_dir, &uri, None), &allowed());
}

#[test]
fn percent_encoded_parent_folder_is_refused() {
    let l = layout();
    for uri in ["%2e%2e/secret.bin", "..%2fsecret.bin"] {
        let p = write_rig(&l.rig_dir, uri, None);
        refused(&p, uri, &["decoded '../secret.bin'", "'..' climbs out"]);
    }
}

#[test]
fn percent_encoded_parent_folder_is_accepted_with_the_option() {
    let l = layout();
    accepted(
        &write_rig(&l.rig_dir, "%2e%2e%2Fsecret.bin", None),
        &allowed(),
    );
}

#[cfg(unix)]
#[test]
fn symlinked_file_pointing_outside_is_refused() {
    let l = layout();
    std::os::unix::fs::symlink(l.root.join("secret.bin"), l.rig_dir.join("link.bin")).unwrap();
    let p = write_rig(&l.rig_dir, "link.bin", None);
    refused(&p, "link.bin", &["symbolic link", "secret.bin"]);
}

#[cfg(unix)]
#[test]
fn symlinked_file_pointing_outside_is_accepted_with_the_option() {
    let l = layout();
    std::os::unix::fs::symlink(l.root.join("secret.bin"), l.rig_dir.join("link.bin")).unwrap();
    accepted(&write_rig(&l.rig_dir, "link.bin", None), &allowed());
}

#[cfg(unix)]
#[test]
fn symlinked_folder_pointing_outside_is_refused() {
    let l = layout();
    std::os::unix::fs::symlink(l.root.join("outside"), l.rig_dir.join("shared")).unwrap();
    let p = write_rig(&l.rig_dir, "shared/secret.bin", None);
    refused(&p, "shared/secret.bin", &["symbolic link"]);
    // `..` after a link out climbs from where the link leads, not from the folder.
    std::fs::write(l.rig_dir.join("secret.bin"), &l.bin).unwrap();
    let p = write_rig(&l.rig_dir, "shared/../secret.bin", None);
    refused(&p, "shared/../secret.bin", &["symbolic link"]);
}

#[cfg(unix)]
#[test]
fn symlinked_folder_pointing_outside_is_accepted_with_the_option() {
    let l = layout();
    std::os::unix::fs::symlink(l.root.join("outside"), l.rig_dir.join("shared")).unwrap();
    accepted(
        &write_rig(&l.rig_dir, "shared/secret.bin", None),
        &allowed(),
    );
}

#[cfg(unix)]
#[test]
fn symlink_that_stays_inside_the_folder_is_accepted() {
    let l = layout();
    std::fs::create_dir_all(l.rig_dir.join("data")).unwrap();
    std::fs::write(l.rig_dir.join("data/tiny.bin"), &l.bin).unwrap();
    std::os::unix::fs::symlink("data/tiny.bin", l.rig_dir.join("link.bin")).unwrap();
    accepted(
        &write_rig(&l.rig_dir, "link.bin", None),
        &Default::default(),
    );
}

#[test]
fn missing_buffer_file_names_the_file() {
    let l = layout();
    let e = load(
        &write_rig(&l.rig_dir, "gone.bin", None),
        &Default::default(),
    )
    .err()
    .expect("refused")
    .to_string();
    assert!(
        e.contains("rig.gltf") && e.contains("buffer 0") && e.contains("gone.bin"),
        "{e}"
    );
}

/// Bytes standing in for a PNG (the export embeds them without decoding).
const IMAGE: &[u8] = b"\x89PNG\r\n\x1a\nfurrow-test-image-bytes";

fn contains(hay: &[u8], needle: &[u8]) -> bool {
    hay.windows(needle.len()).any(|w| w == needle)
}

#[test]
fn image_inside_the_folder_is_embedded_by_the_export() {
    let l = layout();
    std::fs::write(l.rig_dir.join("tiny.bin"), &l.bin).unwrap();
    std::fs::write(l.rig_dir.join("skin%.png"), IMAGE).unwrap();
    let p = write_rig(
        &l.rig_dir,
        "tiny.bin",
        Some(json!([{ "uri": "skin%25.png" }])),
    );
    let rig = load(&p, &Default::default()).unwrap();
    let glb = furrow::io::export::decoded_glb(&rig).unwrap();
    assert!(contains(&glb, IMAGE));
    assert!(contains(&glb, b"image/png"));
}

#[test]
fn image_outside_the_folder_is_refused() {
    let l = layout();
    std::fs::write(l.rig_dir.join("tiny.bin"), &l.bin).unwrap();
    std::fs::write(l.root.join("skin.png"), IMAGE).unwrap();
    let p = write_rig(
        &l.rig_dir,
        "tiny.bin",
        Some(json!([{ "uri": "../skin.png" }])),
    );
    refused(&p, "../skin.png", &["image 0"]);
}

#[test]
fn image_outside_the_folder_is_embedded_with_the_option() {
    let l = layout();
    std::fs::write(l.rig_dir.join("tiny.bin"), &l.bin).unwrap();
    std::fs::write(l.root.join("skin.png"), IMAGE).unwrap();
    let p = write_rig(
        &l.rig_dir,
        "tiny.bin",
        Some(json!([{ "uri": "../skin.png" }])),
    );
    let rig = load(&p, &allowed()).unwrap();
    let glb = furrow::io::export::decoded_glb(&rig).unwrap();
    assert!(contains(&glb, IMAGE));
}

#[test]
fn missing_image_is_refused_by_the_export_only() {
    let l = layout();
    std::fs::write(l.rig_dir.join("tiny.bin"), &l.bin).unwrap();
    let p = write_rig(&l.rig_dir, "tiny.bin", Some(json!([{ "uri": "gone.png" }])));
    let rig = load(&p, &Default::default()).unwrap();
    let e = format!("{:#}", furrow::io::export::decoded_glb(&rig).unwrap_err());
    assert!(
        e.contains("rig.gltf") && e.contains("image 0") && e.contains("gone.png"),
        "{e}"
    );
}

/// Run `furrow animate` on `rig` with a scene that refuses the tiny rig quickly (too coarse
/// for a whole simulated skin), writing `out`.
fn animate(rig: &Path, out: &Path, extra: &[&str]) -> (Option<i32>, String) {
    let scene = out.with_file_name("all.toml");
    std::fs::write(&scene, "[skin]\nsimulate = \"all\"\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .args(["--quiet", "animate"])
        .arg(rig)
        .arg("--scene")
        .arg(&scene)
        .arg("-o")
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn cli_refuses_a_rig_reaching_out_of_its_folder() {
    let l = layout();
    let rig = write_rig(&l.rig_dir, "../secret.bin", None);
    let out = l.root.join("out.glb");
    let (code, e) = animate(&rig, &out, &[]);
    assert_eq!(code, Some(2), "{e}");
    for w in [
        "rig.gltf",
        "buffer 0's uri '../secret.bin' lies outside the rig's folder",
        "--allow-outside-paths",
    ] {
        assert!(e.contains(w), "stderr lacks {w:?}: {e}");
    }
    assert!(!e.contains("panicked"), "{e}");
    assert!(!out.exists(), "an output was written");
}

#[test]
fn cli_with_allow_outside_paths_gets_past_the_check() {
    let l = layout();
    let rig = write_rig(&l.rig_dir, "../secret.bin", None);
    let out = l.root.join("out.glb");
    let (_, e) = animate(&rig, &out, &["--allow-outside-paths"]);
    assert!(!e.contains("outside the rig's folder"), "{e}");
    assert!(!e.contains("panicked"), "{e}");
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .args(["inspect", "--allow-outside-paths"])
        .arg(&rig)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn every_subcommand_that_loads_a_rig_has_the_flag() {
    for cmd in [
        &["animate"][..],
        &["batch"],
        &["merge"],
        &["demo"],
        &["fit"],
        &["inspect"],
        &["report", "tradeoff"],
        &["bench", "select"],
        &["bench", "skin"],
        &["bench", "muscles"],
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
            .args(cmd)
            .arg("--help")
            .output()
            .unwrap();
        let help = String::from_utf8_lossy(&o.stdout);
        let words = help.split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(
            words.contains(
                "--allow-outside-paths Read buffer and image files outside the rig's folder \
                 (absolute paths, `..`, symlinks out); refused by default"
            ),
            "{cmd:?}: {help}"
        );
    }
}
