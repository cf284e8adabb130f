//! Dumps every named Cryptomatte matte of an EXR, decoded by throng, as raw
//! little-endian f32 files `<out>/<type>__<name with / as __>.f32` (row-major),
//! for cross-checking against third-party decoders (docs/cryptomatte.md).
//!
//! `cargo run --example crypto_dump -- IN.exr OUT_DIR`

use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(input), Some(out)) = (args.get(1), args.get(2)) else {
        return Err("usage: crypto_dump IN.exr OUT_DIR".into());
    };
    let out = PathBuf::from(out);
    std::fs::create_dir_all(&out)?;
    for m in throng::render::exr::mattes::read(input.as_ref())? {
        for name in m.manifest.keys() {
            let bytes: Vec<u8> = m.matte(name).iter().flat_map(|v| v.to_le_bytes()).collect();
            std::fs::write(out.join(format!("{}__{}.f32", m.name, name.replace('/', "__"))), bytes)?;
        }
        println!("{}: {} names, {} ranks, {}x{}", m.name, m.manifest.len(), m.ranks, m.width, m.height);
    }
    Ok(())
}
