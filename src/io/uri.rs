//! Where a glTF file's buffer and image URIs lead: each is percent-decoded, resolved against
//! the rig's folder and judged inside or outside it, so that a rig reads only its own folder
//! unless outside paths are allowed.
//!
//! A URI is outside when it is an absolute path, a `file:` URI or a Windows drive path, when
//! `..` climbs above the folder, or when a symbolic link on the way (the file itself or a
//! folder) leads out of it: the folder and the file are canonicalized and the file's path
//! must start with the folder's. `data:` URIs are not file names and are not judged here.

use std::path::{Path, PathBuf};

/// Why a URI's file lies outside the rig's folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outside {
    /// An absolute path (`/srv/x.bin`, `\\server\share\x.bin`).
    Absolute,
    /// A `file:` URI (`file:///srv/x.bin`).
    FileUri,
    /// A Windows drive path (`C:/x.bin`, `C:\x.bin`).
    DrivePath,
    /// `..` climbs above the folder.
    Climbs,
    /// A symbolic link on the way (the file or a folder) leads to this path, outside.
    Symlink(PathBuf),
}

impl std::fmt::Display for Outside {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Outside::Absolute => write!(f, "it is an absolute path"),
            Outside::FileUri => write!(f, "it is a file: URI (an absolute path)"),
            Outside::DrivePath => write!(f, "it is a Windows drive path"),
            Outside::Climbs => write!(f, "'..' climbs out of the folder"),
            Outside::Symlink(p) => {
                write!(f, "a symbolic link on the way leads to {}", p.display())
            }
        }
    }
}

/// Why a URI gives no file to read.
#[derive(Debug)]
pub enum Refusal {
    /// A remote URI (`https://…`, `file://host/…`): furrow reads local files only.
    Remote,
    /// The file lies outside the rig's folder (`folder`, canonical when it exists).
    Outside {
        /// The rig's folder.
        folder: PathBuf,
        /// What leads out of it.
        why: Outside,
    },
    /// The file (or the rig's folder) cannot be found or resolved.
    Unresolved {
        /// The file as the URI names it, joined to the rig's folder.
        path: PathBuf,
        /// What the file system said.
        error: std::io::Error,
    },
}

/// A URI's file: where furrow reads it, and the path the URI names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Resolved {
    /// The file to read: canonical when it was judged against the folder.
    pub path: PathBuf,
    /// The path as the URI names it, joined to the rig's folder (its extension tells the
    /// file's type even when a link inside the folder leads to a file named otherwise).
    pub named: PathBuf,
}

/// What a decoded URI names before the file system is asked.
enum Named<'a> {
    /// A host other than this machine.
    Remote,
    /// A path relative to the folder that stays inside it (as written).
    Relative(&'a str),
    /// A path that leads out of the folder as written.
    Outside(&'a str, Outside),
}

/// The folder a rig's relative URIs are resolved against: the folder of `rig` (`.` for a
/// bare file name).
pub fn folder_of(rig: &Path) -> &Path {
    match rig.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Resolve the URI `uri` (not a `data:` URI) of the rig at `rig` to the file furrow reads.
/// Unless `allow_outside` is set, a file outside the rig's folder is refused, and the file
/// must exist (it is canonicalized to follow its links); with `allow_outside` the path is
/// only joined to the folder.
pub fn resolve(rig: &Path, uri: &str, allow_outside: bool) -> Result<Resolved, Refusal> {
    let folder = folder_of(rig);
    let decoded = percent_decode(uri);
    let (written, outside) = match name(&decoded) {
        Named::Remote => return Err(Refusal::Remote),
        Named::Relative(p) => (p, None),
        Named::Outside(p, why) => (p, Some(why)),
    };
    let named = folder.join(written);
    if allow_outside {
        return Ok(Resolved {
            path: named.clone(),
            named,
        });
    }
    if let Some(why) = outside {
        let folder = folder
            .canonicalize()
            .unwrap_or_else(|_| folder.to_path_buf());
        return Err(Refusal::Outside { folder, why });
    }
    let unresolved = |error| Refusal::Unresolved {
        path: named.clone(),
        error,
    };
    let root = folder.canonicalize().map_err(unresolved)?;
    let real = named.canonicalize().map_err(unresolved)?;
    if !real.starts_with(&root) {
        return Err(Refusal::Outside {
            folder: root,
            why: Outside::Symlink(real),
        });
    }
    Ok(Resolved { path: real, named })
}

/// What the decoded URI `d` names, judged on its text alone.
fn name(d: &str) -> Named<'_> {
    if let Some(rest) = d
        .get(..5)
        .filter(|s| s.eq_ignore_ascii_case("file:"))
        .map(|_| &d[5..])
    {
        return match rest.strip_prefix("//") {
            Some(after) => {
                let host = &after[..after.find('/').unwrap_or(after.len())];
                if host.is_empty() || host.eq_ignore_ascii_case("localhost") {
                    Named::Outside(file_uri_path(&after[host.len()..]), Outside::FileUri)
                } else {
                    Named::Remote
                }
            }
            None => Named::Outside(rest, Outside::FileUri),
        };
    }
    if d.contains("://") {
        return Named::Remote;
    }
    let b = d.as_bytes();
    if b.len() >= 2 && b[0].is_ascii_alphabetic() && b[1] == b':' {
        return Named::Outside(d, Outside::DrivePath);
    }
    if d.starts_with(['/', '\\']) {
        return Named::Outside(d, Outside::Absolute);
    }
    if climbs(d) {
        return Named::Outside(d, Outside::Climbs);
    }
    Named::Relative(d)
}

/// The path of a `file://` URI after its (empty or `localhost`) host: on Windows the slash
/// before a drive letter (`/C:/x.bin`) is dropped.
fn file_uri_path(p: &str) -> &str {
    let b = p.as_bytes();
    if cfg!(windows) && b.len() >= 3 && b[0] == b'/' && b[1].is_ascii_alphabetic() && b[2] == b':' {
        &p[1..]
    } else {
        p
    }
}

/// Whether `..` in the relative path `p` climbs above its start (either slash separates).
fn climbs(p: &str) -> bool {
    let mut depth = 0usize;
    for part in p.split(['/', '\\']) {
        match part {
            "" | "." => {}
            ".." if depth == 0 => return true,
            ".." => depth -= 1,
            _ => depth += 1,
        }
    }
    false
}

/// Decode `%XX` escapes in a URI (bytes that do not form UTF-8 become U+FFFD).
pub fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let hex = |c: u8| (c as char).to_digit(16);
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
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

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.bin"), "a b.bin");
        assert_eq!(percent_decode("plain.bin"), "plain.bin");
        assert_eq!(percent_decode("bad%2"), "bad%2");
        assert_eq!(percent_decode("%2e%2E%2fx.bin"), "../x.bin");
        // A multi-byte character after '%' is kept, not split.
        assert_eq!(percent_decode("%€x"), "%€x");
    }

    #[test]
    fn names_are_judged_on_their_text() {
        let why = |d: &str| match name(d) {
            Named::Remote => Some(None),
            Named::Relative(_) => None,
            Named::Outside(_, w) => Some(Some(w)),
        };
        assert!(why("x.bin").is_none());
        assert!(why("sub/x.bin").is_none());
        assert!(why("sub/../x.bin").is_none());
        assert!(why("./sub/./x.bin").is_none());
        assert_eq!(why("../x.bin"), Some(Some(Outside::Climbs)));
        assert_eq!(why("sub/../../x.bin"), Some(Some(Outside::Climbs)));
        assert_eq!(why("..\\x.bin"), Some(Some(Outside::Climbs)));
        assert_eq!(why("/srv/x.bin"), Some(Some(Outside::Absolute)));
        assert_eq!(why("\\\\host\\x.bin"), Some(Some(Outside::Absolute)));
        assert_eq!(why("C:/x.bin"), Some(Some(Outside::DrivePath)));
        assert_eq!(why("c:x.bin"), Some(Some(Outside::DrivePath)));
        assert_eq!(why("file:///srv/x.bin"), Some(Some(Outside::FileUri)));
        assert_eq!(why("FILE://localhost/x.bin"), Some(Some(Outside::FileUri)));
        assert_eq!(why("file:x.bin"), Some(Some(Outside::FileUri)));
        assert_eq!(why("file://host/x.bin"), Some(None));
        assert_eq!(why("https://host/x.bin"), Some(None));
        match name("file:///srv/x.bin") {
            Named::Outside(p, _) => assert_eq!(p, "/srv/x.bin"),
            _ => unreachable!(),
        }
    }

    #[test]
    fn a_bare_file_name_resolves_in_the_working_folder() {
        assert_eq!(folder_of(Path::new("rig.gltf")), Path::new("."));
        assert_eq!(folder_of(Path::new("a/rig.gltf")), Path::new("a"));
    }
}
