//! Reading Cryptomatte back from EXR headers and channels: the manifest
//! JSON (header or sidecar) and the rank channels of each matte type. The
//! EXR side owns decoding so the dependency runs one way: this module uses
//! `render::cryptomatte`'s model (`Cryptomatte`, the hash and conversion
//! names), and `render::cryptomatte` knows nothing of files.

use std::collections::BTreeMap;
use std::path::Path;

use super::RawPart;
use crate::error::{Error, IoContext, Result};
use crate::render::cryptomatte::{Cryptomatte, CONVERSION, HASH};

/// Parses a manifest (header value or sidecar file): a JSON object of
/// name -> 8-hex-digit float bits. `what` names the source in errors.
pub fn parse_manifest(json: &str, what: &Path) -> Result<BTreeMap<String, u32>> {
    let map: BTreeMap<String, serde_json::Value> = serde_json::from_str(json)
        .map_err(|e| Error::invalid(what, format!("cryptomatte manifest is not a JSON object: {e}")))?;
    let mut out = BTreeMap::new();
    for (name, v) in map {
        let hex = v.as_str().ok_or_else(|| {
            Error::invalid(what, format!("cryptomatte manifest entry `{name}` is not a hex string")).field("manifest")
        })?;
        let bits = u32::from_str_radix(hex, 16).map_err(|_| {
            Error::invalid(what, format!("cryptomatte manifest entry `{name}`: `{hex}` is not hex")).field("manifest")
        })?;
        out.insert(name, bits);
    }
    Ok(out)
}

/// Decodes every Cryptomatte type described in one EXR part's header.
/// `exr_path` resolves sidecar manifests (`manif_file`, relative to the
/// EXR's directory). Types whose rank channels are missing are errors.
/// Sorted by type name.
pub(crate) fn decode_part(part: &RawPart, exr_path: &Path) -> Result<Vec<Cryptomatte>> {
    // Keys as `cryptomatte/<key>/<field>`; tolerate Nuke's `exr/` prefix.
    let mut types: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    for (k, v) in &part.attributes {
        let k = k.strip_prefix("exr/").unwrap_or(k);
        let Some(rest) = k.strip_prefix("cryptomatte/") else { continue };
        if let Some((key, field)) = rest.split_once('/') {
            types.entry(key.to_string()).or_default().insert(field.to_string(), v.clone());
        }
    }
    let n = part.width as usize * part.height as usize;
    let mut out = Vec::new();
    for (key, fields) in types {
        let field = |f: &str| fields.get(f).map(String::as_str);
        let err = |msg: String| Error::invalid(exr_path, msg).field(format!("cryptomatte/{key}"));
        let Some(name) = field("name") else { return Err(err("cryptomatte type has no `name`".into())) };
        if let Some(h) = field("hash").filter(|&h| h != HASH) {
            return Err(err(format!("cryptomatte `{name}` uses hash `{h}`; only {HASH} is supported")));
        }
        if let Some(c) = field("conversion").filter(|&c| c != CONVERSION) {
            return Err(err(format!("cryptomatte `{name}` uses conversion `{c}`; only {CONVERSION} is supported")));
        }
        // Rank channels: {name}00.R/G/B/A, {name}01..., in order; writers
        // spell the suffixes R, r or red (and so on).
        let channel = |level: usize, c: char| {
            let long = match c {
                'R' => "red",
                'G' => "green",
                'B' => "blue",
                _ => "alpha",
            };
            [c.to_string(), c.to_ascii_lowercase().to_string(), long.to_string()]
                .iter()
                .find_map(|suffix| part.channels.get(&format!("{name}{level:02}.{suffix}")))
        };
        let mut levels: Vec<[&Vec<f32>; 4]> = Vec::new();
        while let (Some(r), Some(g), Some(b), Some(a)) = (
            channel(levels.len(), 'R'),
            channel(levels.len(), 'G'),
            channel(levels.len(), 'B'),
            channel(levels.len(), 'A'),
        ) {
            levels.push([r, g, b, a]);
        }
        if levels.is_empty() {
            return Err(err(format!("cryptomatte `{name}` has no `{name}00.R/G/B/A` channels")));
        }
        if levels.iter().flatten().any(|c| c.len() != n) {
            return Err(err(format!("cryptomatte `{name}` channels do not match the image size")));
        }
        let ranks = levels.len() * 2;
        let mut m = Cryptomatte::new(name, part.width, part.height, ranks);
        for (l, [r, g, b, a]) in levels.iter().enumerate() {
            for i in 0..n {
                m.pairs[i * ranks + 2 * l] = [r[i], g[i]];
                m.pairs[i * ranks + 2 * l + 1] = [b[i], a[i]];
            }
        }
        if let Some(json) = field("manifest") {
            m.manifest = parse_manifest(json, exr_path)?;
        } else if let Some(file) = field("manif_file") {
            let dir = exr_path.parent().unwrap_or(Path::new(""));
            let side = dir.join(file);
            let text = std::fs::read_to_string(&side).at(&side)?;
            m.manifest = parse_manifest(&text, &side)?;
        }
        out.push(m);
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

/// Reads every Cryptomatte type of every part of an EXR.
pub fn read(path: &Path) -> Result<Vec<Cryptomatte>> {
    let mut out = Vec::new();
    for part in super::read_parts(path, |_| true)? {
        out.extend(decode_part(&part, path)?);
    }
    Ok(out)
}
