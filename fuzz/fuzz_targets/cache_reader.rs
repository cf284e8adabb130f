//! Fuzzes the `.crowd` reader the CLI uses: `CacheReader::open` on a file
//! (header and index), then `read_frame` for every frame (one block each),
//! and the in-memory reader `cache::binary::parse_bytes_named`; the two must
//! agree. Each input is also tried with its header, index and block CRCs
//! recomputed, so mutations get past the checksums to the structure behind
//! them. Any input must give an error, never a panic, a hang or an
//! allocation the file's size does not bound.
//! Run: `cargo +nightly fuzz run cache_reader` (from the repository root;
//! docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use throng::cache::binary::{HEADER_LEN, MAGIC};
use throng::cache::CacheReader;

fn file() -> &'static Path {
    static P: OnceLock<PathBuf> = OnceLock::new();
    P.get_or_init(|| std::env::temp_dir().join(format!("throng-fuzz-{}.crowd", std::process::id())))
}

fn put_crc(b: &mut [u8], start: usize, end: usize) {
    // `end` is where the stored CRC begins.
    let sum = crc32fast::hash(&b[start..end]);
    b[end..end + 4].copy_from_slice(&sum.to_le_bytes());
}

/// `data` with every checksum the layout implies rewritten.
fn fix_crcs(data: &[u8]) -> Option<Vec<u8>> {
    let head = HEADER_LEN as usize;
    if data.len() < head || data[..8] != MAGIC {
        return None;
    }
    let mut b = data.to_vec();
    put_crc(&mut b, 0, head - 4);
    let meta_len = u32::from_le_bytes(b[12..16].try_into().ok()?) as usize;
    let meta_end = head.checked_add(meta_len)?;
    if meta_len >= 4 && meta_end <= b.len() {
        put_crc(&mut b, head, meta_end - 4);
        // Blocks follow the index back to back: frame, count, records, CRC.
        let mut pos = meta_end;
        while pos + 12 <= b.len() {
            let agents = u32::from_le_bytes(b[pos + 4..pos + 8].try_into().ok()?) as usize;
            let Some(end) = agents.checked_mul(32).and_then(|r| r.checked_add(pos + 12)) else { break };
            if end > b.len() {
                break;
            }
            put_crc(&mut b, pos, end - 4);
            pos = end;
        }
    }
    (b != data).then_some(b)
}

fn check(bytes: &[u8]) {
    let path = file();
    let in_memory = throng::cache::binary::parse_bytes_named(path, bytes);
    if std::fs::write(path, bytes).is_err() {
        return;
    }
    let from_file = CacheReader::open(path).and_then(|r| {
        for &f in r.frames() {
            r.read_frame(f)?;
        }
        let _ = r.read_frame(i32::MIN);
        // What `throng cache info` prints.
        throng::cache::info(&r)?;
        r.read_all()
    });
    match (&in_memory, &from_file) {
        (Ok(a), Ok(b)) => assert_eq!(a, b, "file and in-memory readers disagree"),
        (Ok(_), Err(e)) => panic!("only the in-memory reader accepts this: {e}"),
        (Err(e), Ok(_)) => panic!("only the file reader accepts this: {e}"),
        (Err(_), Err(_)) => {}
    }
}

fuzz_target!(|data: &[u8]| {
    check(data);
    if let Some(fixed) = fix_crcs(data) {
        check(&fixed);
    }
});
