//! What the review server may read: files under the shot's folder and the
//! renders folder, nothing else. Every path is checked twice: the request's
//! relative path must be plain names (no `..`, `.`, empty, absolute or
//! backslashed parts, after percent-decoding), and the joined path,
//! canonicalised (symlinks resolved), must still lie under the root's
//! canonical path and be a regular file.

use std::path::{Component, Path, PathBuf};

/// A folder the server reads from, canonicalised once.
#[derive(Debug, Clone)]
pub(crate) struct Root {
    /// The canonical folder.
    pub(crate) dir: PathBuf,
}

impl Root {
    /// The folder `dir`, which must exist.
    pub(crate) fn new(dir: &Path) -> std::io::Result<Root> {
        Ok(Root { dir: dir.canonicalize()? })
    }

    /// The file at `rel` (slash-separated, already percent-decoded) under
    /// the root, or why not: an HTTP status (400 not a plain path, 403
    /// outside the root, 404 no such file) and a message.
    pub(crate) fn file(&self, rel: &str) -> Result<PathBuf, (u16, String)> {
        let plain = !rel.is_empty()
            && !rel.contains('\0')
            && !rel.contains('\\')
            && rel.split('/').all(|part| !part.is_empty() && part != "." && part != "..")
            && Path::new(rel).components().all(|c| matches!(c, Component::Normal(_)));
        if !plain {
            return Err((400, format!("`{rel}` is not a plain relative path (no empty, `.` or `..` parts)")));
        }
        self.confine(&self.dir.join(rel))
    }

    /// `path` itself, when it resolves (symlinks followed) to a regular file
    /// under the root; else why not (403 outside, 404 missing).
    pub(crate) fn confine(&self, path: &Path) -> Result<PathBuf, (u16, String)> {
        let real = path.canonicalize().map_err(|_| (404, format!("no such file: {}", self.shown(path))))?;
        if !real.starts_with(&self.dir) {
            return Err((403, format!("{} is outside the folders this server reads", self.shown(path))));
        }
        if !real.is_file() {
            return Err((404, format!("{} is not a file", self.shown(path))));
        }
        Ok(real)
    }

    /// A path as the error messages show it: relative to the root when under it.
    fn shown(&self, path: &Path) -> String {
        path.strip_prefix(&self.dir).unwrap_or(path).display().to_string()
    }
}

/// Percent-decodes a URL path or query part (`+` is a space in a query).
/// `None` for a bad escape or bytes that are not UTF-8.
pub(crate) fn percent_decode(s: &str, plus_is_space: bool) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'%' => {
                let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
                out.push(u8::from_str_radix(hex, 16).ok()?);
                i += 3;
            }
            b'+' if plus_is_space => {
                out.push(b' ');
                i += 1;
            }
            c => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_escapes_and_refuses_bad_ones() {
        assert_eq!(percent_decode("%2e%2E/a+b", false).as_deref(), Some("../a+b"));
        assert_eq!(percent_decode("a+b%20c", true).as_deref(), Some("a b c"));
        assert_eq!(percent_decode("%zz", false), None);
        assert_eq!(percent_decode("%2", false), None);
        assert_eq!(percent_decode("%ff", false), None);
    }

    #[test]
    fn plain_names_only() {
        let dir = std::env::temp_dir().join(format!("throng-review-safe-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        std::fs::write(dir.join("sub/a.txt"), "a").unwrap();
        let root = Root::new(&dir).unwrap();
        assert!(root.file("sub/a.txt").is_ok());
        for bad in ["", "../x", "sub/../sub/a.txt", "./sub/a.txt", "/etc/passwd", "sub//a.txt", "sub\\a.txt", "sub"] {
            assert!(root.file(bad).is_err(), "{bad} was accepted");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
