//! The one fingerprint of throng: what a layer manifest was made from
//! (`made_from`), what a layer file was rendered with
//! (`throng/renderFingerprint`) and what a farm plan was planned from
//! (`fingerprint`) are all FNV-1a 64, written as 16 hex digits.
//!
//! FNV-1a 64 is defined by two constants, so it gives the same value on
//! every platform and in every version, and needs no dependency. It is a
//! change detector, not a defence against tampering. Unlike a CRC it has no
//! residue: a `.crowd` cache ends with the CRC-32 of its own bytes, so the
//! CRC-32 of every `.crowd` file is one constant, but their FNV-1a differ.
//!
//! Files are read in fixed blocks ([`BLOCK_BYTES`]), never whole, since a
//! cache may be many GB. Structured values go through a [`Fingerprinter`],
//! fed named fields: each name and value is followed by its length, so no
//! two different sequences of fields feed the same bytes.

use std::fmt::Debug;
use std::io::Read;
use std::path::Path;

use serde::Serialize;

use crate::error::{IoContext, Result};

/// The algorithm's name, as manifests and plans record it.
pub(crate) const ALGORITHM: &str = "fnv1a64";

/// Bytes read from a file at a time.
pub(crate) const BLOCK_BYTES: usize = 1 << 20;

/// FNV-1a 64's starting state (the hash of no bytes).
pub(crate) const FNV_OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
const PRIME: u64 = 0x0000_0100_0000_01b3;

/// FNV-1a 64 continued over `bytes` from the state `h` (the hash of what
/// came before; [`FNV_OFFSET_BASIS`] for nothing). The keyed draws hash
/// their purpose names with it too (`crate::seed`).
pub(crate) fn fnv1a_continued(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(PRIME);
    }
    h
}

/// FNV-1a 64 of `bytes`.
#[cfg(test)] // the tests check the FNV-1a reference values
pub(crate) fn hash_bytes(bytes: &[u8]) -> u64 {
    fnv1a_continued(FNV_OFFSET_BASIS, bytes)
}

/// A hash as it is written: 16 hex digits.
pub(crate) fn hex(h: u64) -> String {
    format!("{h:016x}")
}

/// A file's content hash and length.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileHash {
    /// FNV-1a 64 of the file's bytes.
    pub hash: u64,
    /// The file's length.
    pub bytes: u64,
}

/// Hashes a file's bytes, read in blocks of [`BLOCK_BYTES`].
pub fn hash_file(path: &Path) -> Result<FileHash> {
    crate::error::check_readable_file(path)?;
    let mut f = std::fs::File::open(path).at(path)?;
    let mut buf = vec![0u8; BLOCK_BYTES];
    let (mut hash, mut bytes) = (FNV_OFFSET_BASIS, 0u64);
    loop {
        let n = match f.read(&mut buf) {
            Ok(0) => return Ok(FileHash { hash, bytes }),
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e).at(path),
        };
        hash = fnv1a_continued(hash, &buf[..n]);
        bytes += n as u64;
    }
}

/// Feeds a serializer's output into a fingerprint, counting it.
struct Stream<'a> {
    f: &'a mut Fingerprinter,
    bytes: u64,
}

impl std::io::Write for Stream<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.f.put(buf);
        self.bytes += buf.len() as u64;
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Hashes a structured value fed as named fields.
#[derive(Debug, Clone)]
pub(crate) struct Fingerprinter {
    h: u64,
}

impl Default for Fingerprinter {
    fn default() -> Self {
        Fingerprinter { h: FNV_OFFSET_BASIS }
    }
}

impl Fingerprinter {
    /// An empty fingerprint.
    pub(crate) fn new() -> Fingerprinter {
        Fingerprinter::default()
    }

    fn put(&mut self, bytes: &[u8]) {
        self.h = fnv1a_continued(self.h, bytes);
    }

    /// Feeds the field `name` with raw bytes.
    pub(crate) fn bytes(&mut self, name: &str, value: &[u8]) -> &mut Self {
        self.named(name, |f| {
            f.put(value);
            value.len() as u64
        })
    }

    /// Feeds the field `name` with numbers, little-endian, streamed (the
    /// same bytes as [`Fingerprinter::bytes`] of them all, never held: a
    /// dome's millions of texels are not copied).
    pub(crate) fn floats(&mut self, name: &str, values: impl IntoIterator<Item = f32>) -> &mut Self {
        self.named(name, |f| {
            let mut n = 0u64;
            for v in values {
                f.put(&v.to_le_bytes());
                n += 4;
            }
            n
        })
    }

    /// Feeds the field `name` with text.
    pub(crate) fn text(&mut self, name: &str, value: &str) -> &mut Self {
        self.bytes(name, value.as_bytes())
    }

    /// Feeds the field `name` with a value's JSON serialization (numbers,
    /// strings, whole structs: a field added to a struct is covered
    /// without touching this call). The JSON is streamed, never held: a
    /// manifest of a million agents is not copied.
    pub(crate) fn value<T: Serialize + ?Sized>(&mut self, name: &str, value: &T) -> &mut Self {
        self.named(name, |f| {
            let mut stream = Stream { f, bytes: 0 };
            // Serializing fails only for maps with non-string keys, which no
            // fingerprinted type has; the bytes fed so far still count.
            let _ = serde_json::to_writer(&mut stream, value);
            stream.bytes
        })
    }

    /// A field: its name, the name's length, its value (fed by `value`,
    /// which returns its length), the value's length. Read from the end,
    /// the lengths delimit every field, so no two different sequences of
    /// fields feed the same bytes.
    fn named(&mut self, name: &str, value: impl FnOnce(&mut Self) -> u64) -> &mut Self {
        self.put(name.as_bytes());
        self.put(&(name.len() as u64).to_le_bytes());
        let n = value(self);
        self.put(&n.to_le_bytes());
        self
    }

    /// Feeds the field `name` with a value's `Debug` text, for shot types
    /// that are not serializable (every field of the value is covered).
    pub(crate) fn debug<T: Debug + ?Sized>(&mut self, name: &str, value: &T) -> &mut Self {
        self.text(name, &format!("{value:?}"))
    }

    /// Feeds the field `name` with a file's content hash (not its path, so
    /// moving a shot folder changes nothing).
    pub(crate) fn file(&mut self, name: &str, path: &Path) -> Result<&mut Self> {
        let h = hash_file(path)?;
        Ok(self.bytes(name, &h.hash.to_le_bytes()))
    }

    /// The hash of every field fed so far.
    #[cfg(test)] // the tests compare hashes as numbers
    pub(crate) fn finish(&self) -> u64 {
        self.h
    }

    /// The hash of every field fed so far, as 16 hex digits.
    pub(crate) fn hex(&self) -> String {
        hex(self.h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streamed_floats_hash_as_their_bytes() {
        let values = [1.5f32, -0.0, 3e9, f32::MIN_POSITIVE];
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let (mut a, mut b) = (Fingerprinter::new(), Fingerprinter::new());
        assert_eq!(a.floats("dome", values).finish(), b.bytes("dome", &bytes).finish());
        assert_ne!(a.finish(), Fingerprinter::new().floats("dome", [1.5f32]).finish());
    }

    #[test]
    fn fnv1a64_matches_the_published_test_vectors() {
        // From the FNV reference (Fowler, Noll, Vo): fnv1a_64 of "", "a", "foobar".
        assert_eq!(hash_bytes(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(hash_bytes(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(hash_bytes(b"foobar"), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn a_file_hashes_as_its_bytes_across_blocks() {
        let dir = std::env::temp_dir().join(format!("throng-fingerprint-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("blocks.bin");
        // Two and a half blocks, so the last read is short.
        let bytes: Vec<u8> = (0..BLOCK_BYTES * 5 / 2).map(|i| (i * 7 % 251) as u8).collect();
        std::fs::write(&path, &bytes).unwrap();
        let h = hash_file(&path).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(h, FileHash { hash: hash_bytes(&bytes), bytes: bytes.len() as u64 });
    }

    #[test]
    fn fields_are_delimited_and_named() {
        let of = |fields: &[(&str, &str)]| {
            let mut f = Fingerprinter::new();
            for (name, value) in fields {
                f.text(name, value);
            }
            f.finish()
        };
        assert_ne!(of(&[("a", "bc")]), of(&[("a", "b"), ("", "c")]));
        assert_ne!(of(&[("ab", "c")]), of(&[("a", "bc")]));
        assert_ne!(of(&[("x", "1")]), of(&[("y", "1")]));
        assert_eq!(of(&[("x", "1"), ("y", "2")]), of(&[("x", "1"), ("y", "2")]));
        let mut f = Fingerprinter::new();
        f.value("v", &[1.5f32, 2.0]);
        assert_eq!(f.finish(), Fingerprinter::new().text("v", "[1.5,2.0]").finish());
    }
}
