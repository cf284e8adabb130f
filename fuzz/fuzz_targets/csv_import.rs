//! Fuzzes the text cache imports the CLI uses on a file: throng's own CSV
//! (`cache::import` on a `.csv`: gzip sniffing, UTF-8 and BOM handling in
//! `tabular::read_text`, then `cache::csv::parse_str`), and the same bytes
//! as a foreign trajectory table (`tabular::read`, with resampling to the
//! shot's rate) under each preset and a headed CSV with named columns.
//! Run: `cargo +nightly fuzz run csv_import` (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use throng::cache::tabular::{self, Column, ColumnChoices, Preset, TabularOptions};
use throng::cache::{Import, TabularSpec};

fn file() -> &'static Path {
    static P: OnceLock<PathBuf> = OnceLock::new();
    P.get_or_init(|| std::env::temp_dir().join(format!("throng-fuzz-{}.csv", std::process::id())))
}

/// The layouts tried: the three table presets and a headed CSV by column names.
fn layouts() -> &'static [TabularOptions] {
    static L: OnceLock<Vec<TabularOptions>> = OnceLock::new();
    L.get_or_init(|| {
        let mut out: Vec<TabularOptions> = [Preset::PeTrack, Preset::Eth, Preset::EthUcy]
            .into_iter()
            .map(|p| TabularOptions::resolve(&TabularSpec { preset: Some(p), ..Default::default() }, 24.0).unwrap())
            .collect();
        let name = |role: &str, col: &str| (role.to_string(), Some(Column::Name(col.into())));
        let spec = TabularSpec {
            columns: ColumnChoices(vec![
                name("frame", "frame"),
                name("id", "agent_id"),
                name("x", "x"),
                name("y", "y"),
                name("z", "z"),
                name("heading", "heading_radians"),
            ]),
            source_fps: Some(25.0),
            ..Default::default()
        };
        out.push(TabularOptions::resolve(&spec, 24.0).unwrap());
        out
    })
}

fuzz_target!(|data: &[u8]| {
    let path = file();
    if std::fs::write(path, data).is_err() {
        return;
    }
    let _ = throng::cache::import(path, &Import::default());
    for o in layouts() {
        let _ = tabular::read(path, o);
    }
});
