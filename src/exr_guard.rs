//! Limits on reading OpenEXR files, shared by every reader (render's layer
//! files, scene's HDRI domes): the exr crate allocates every channel of every
//! part from the header before it reads a pixel, so headers are checked
//! against the file's size first.

use std::path::Path;

use crate::error::{Error, Result};

/// How many times its own size an EXR may decode to. No EXR compression
/// comes near: deflate (ZIP, ZIPS, PXR24) stops at about 1032:1, RLE at
/// 64:1, PIZ at a few hundred, B44 at about 11:1.
pub(crate) const MAX_EXR_EXPANSION: u64 = 4096;

/// Refuses an EXR whose headers describe more pixel data than its size can
/// hold ([`MAX_EXR_EXPANSION`]). The exr crate allocates every channel of
/// every part from the header before it reads a pixel, so a corrupt data
/// window or channel list would otherwise ask for gigabytes.
pub(crate) fn check_decoded_size(path: &Path) -> Result<()> {
    crate::error::check_readable_file(path)?;
    let file_len = std::fs::metadata(path).map_err(|e| Error::io(path, e))?.len();
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| exr_error(path, e))?;
    let mut bytes = 0u64;
    for header in meta.headers.iter().filter(|h| !h.deep) {
        let (w, h) = (header.layer_size.width() as u64, header.layer_size.height() as u64);
        for c in &header.channels.list {
            let (sx, sy) = (c.sampling.width().max(1) as u64, c.sampling.height().max(1) as u64);
            let samples = (w / sx).saturating_mul(h / sy);
            bytes = bytes.saturating_add(samples.saturating_mul(c.sample_type.bytes_per_sample() as u64));
        }
    }
    if bytes > file_len.saturating_mul(MAX_EXR_EXPANSION) {
        return Err(Error::invalid(
            path,
            format!(
                "OpenEXR: the headers describe {bytes} bytes of pixels, more than a {file_len}-byte file can hold \
                 ({MAX_EXR_EXPANSION} times its size): the data window or channel list is corrupt"
            ),
        ));
    }
    Ok(())
}

/// An exr crate error as ours: I/O as I/O, the rest as invalid input.
pub(crate) fn exr_error(path: &Path, e: exr::error::Error) -> Error {
    match e {
        exr::error::Error::Io(io) => Error::io(path, io),
        other => Error::invalid(path, format!("OpenEXR: {other}")),
    }
}
