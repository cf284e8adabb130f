//! Fuzzes the CSV cache import alone (cache_reader also tries the binary
//! reader). Run: `cargo +nightly fuzz run csv_import`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = throng::cache::csv::parse_str(std::path::Path::new("<fuzz>.csv"), text);
    }
});
