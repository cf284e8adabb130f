//! Fuzzes the cache readers with arbitrary bytes: they must return an error,
//! never panic, hang or allocate beyond the input's size.
//! Run: `cargo +nightly fuzz run cache_reader` (from the repository root).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let _ = throng::cache::binary::parse_bytes(data);
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = throng::cache::csv::parse_str(Path::new("<fuzz>"), text);
    }
});
