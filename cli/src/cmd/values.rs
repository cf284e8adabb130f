//! Typed flag values, parsed by clap so a bad value is refused at parse time.

/// `--frames`: a frame list such as `1001-1010`, `1001-1100x2` or `1001,1005`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameList(pub Vec<i32>);

/// Parses a frame list.
pub fn frame_list(s: &str) -> Result<FrameList, String> {
    throng::shot::parse_frame_list(s).map(FrameList)
}

/// `--pixel X,Y`: 0,0 is the top-left pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pixel {
    /// Column.
    pub x: u32,
    /// Row from the top.
    pub y: u32,
}

/// Parses `X,Y` pixel coordinates.
pub fn pixel(s: &str) -> Result<Pixel, String> {
    let bad = || format!("bad --pixel `{s}` (use X,Y, e.g. 480,270; 0,0 is the top-left pixel)");
    let (x, y) = s.split_once(',').ok_or_else(bad)?;
    Ok(Pixel { x: x.trim().parse().map_err(|_| bad())?, y: y.trim().parse().map_err(|_| bad())? })
}

/// `--resolution WIDTHxHEIGHT`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Resolution(pub [u32; 2]);

use throng::shot::{MAX_PIXELS, MAX_RESOLUTION, MAX_SPP};

/// Parses `WIDTHxHEIGHT`.
pub fn resolution(s: &str) -> Result<Resolution, String> {
    let bad =
        || format!("bad resolution `{s}` (use e.g. 480x270; at most {MAX_RESOLUTION} a side and {MAX_PIXELS} pixels)");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (w.trim().parse().map_err(|_| bad())?, h.trim().parse().map_err(|_| bad())?);
    throng::shot::check_resolution(w, h).map_err(|_| bad())?;
    Ok(Resolution([w, h]))
}

/// `--spp`: 1 to [`MAX_SPP`] samples per pixel (0 is refused, never replaced).
pub fn spp(s: &str) -> Result<u32, String> {
    let bad = || format!("bad --spp `{s}` (a whole number from 1 to {MAX_SPP})");
    let n: u32 = s.trim().parse().map_err(|_| bad())?;
    throng::shot::check_spp(n).map_err(|_| bad())?;
    Ok(n)
}

/// A rate in frames per second (`--fps`): finite and > 0, at most 10000.
pub fn fps(s: &str) -> Result<f32, String> {
    let bad = || format!("bad fps `{s}` (a number of frames per second above 0, at most 10000)");
    let v: f32 = s.trim().parse().map_err(|_| bad())?;
    if !(v > 0.0 && v <= 10000.0) {
        return Err(bad());
    }
    Ok(v)
}

/// Most render threads `--threads` accepts.
pub const MAX_THREADS: usize = 4096;

/// `--threads`: 1 to [`MAX_THREADS`] (0 is refused; leave the flag out for all cores).
pub fn threads(s: &str) -> Result<usize, String> {
    let bad = || format!("bad --threads `{s}` (1 to {MAX_THREADS}; leave it out to use every core)");
    let n: usize = s.trim().parse().map_err(|_| bad())?;
    if n == 0 || n > MAX_THREADS {
        return Err(bad());
    }
    Ok(n)
}

/// `--budget`: a byte size such as `2.8GB` (checked here, kept as written for the manifest).
pub fn budget(s: &str) -> Result<String, String> {
    throng::shot::parse_bytes(s)?;
    Ok(s.to_string())
}

/// `--shutter`: `OPEN,CLOSE` in frames relative to the frame (e.g.
/// `-0.25,0.25`, a 180-degree shutter centred on the frame), or `off`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShutterFlag(pub Option<[f32; 2]>);

/// Parses `OPEN,CLOSE` or `off`.
pub fn shutter(s: &str) -> Result<ShutterFlag, String> {
    if s.trim().eq_ignore_ascii_case("off") {
        return Ok(ShutterFlag(None));
    }
    let bad = |why: String| format!("bad --shutter `{s}`: {why} (use OPEN,CLOSE in frames, e.g. -0.25,0.25, or off)");
    let (a, b) = s.split_once(',').ok_or_else(|| bad("expected two numbers".into()))?;
    let open: f32 = a.trim().parse().map_err(|_| bad(format!("`{}` is not a number", a.trim())))?;
    let close: f32 = b.trim().parse().map_err(|_| bad(format!("`{}` is not a number", b.trim())))?;
    throng::shot::check_shutter([open, close]).map_err(bad)?;
    Ok(ShutterFlag(Some([open, close])))
}

/// A byte size such as `512MB` or `2GiB` (`review --cache`); at least 16 MiB.
pub fn bytes(s: &str) -> Result<u64, String> {
    let b = throng::shot::parse_bytes(s)?;
    if b < 16 << 20 {
        return Err(format!("`{s}` is too small: at least 16MiB"));
    }
    Ok(b)
}

/// An agent id (`botinfo SHOT ID...`): the agent's id in the cache, as `throng cast` lists them.
pub fn agent_id(s: &str) -> Result<u32, String> {
    s.trim().parse().map_err(|_| {
        format!(
            "`{s}` is not an agent id (a whole number 0-{}: the agent's id in the cache, as `throng cast` lists them)",
            u32::MAX
        )
    })
}

/// A shot frame (`--frame`, `--ref-frame`): a whole number, e.g. 1001.
pub fn frame(s: &str) -> Result<i32, String> {
    s.trim().parse().map_err(|_| format!("`{s}` is not a frame (a whole shot frame number, e.g. 1001)"))
}

/// A count of 1 or more (`--chunk`, `--workers`, `layers --count`); the
/// stage checks its own upper bound.
pub fn count(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(format!("`{s}` is not a count (a whole number, 1 or more)")),
    }
}

/// A whole number (`--workers`); the stage checks its range.
pub fn whole(s: &str) -> Result<usize, String> {
    s.trim().parse().map_err(|_| format!("`{s}` is not a whole number"))
}

/// A plain number (`--cutoffs`, `--lod-px`, gait lengths); the stage checks its range.
pub fn number(s: &str) -> Result<f32, String> {
    s.trim().parse().map_err(|_| format!("`{s}` is not a number (e.g. 12 or 0.5)"))
}

/// A TCP port (`review --port`): 0-65535 (0: any free port).
pub fn port(s: &str) -> Result<u16, String> {
    s.trim().parse().map_err(|_| format!("`{s}` is not a port (a whole number 0-65535)"))
}

/// An IP address to listen on (`review --bind`).
pub fn ip(s: &str) -> Result<std::net::IpAddr, String> {
    s.trim().parse().map_err(|_| format!("`{s}` is not an IP address (e.g. 127.0.0.1, 0.0.0.0 or ::1)"))
}

/// A render pass name (`render --passes`), checked at parse time against
/// the names the renderer knows, before any file is read.
pub fn pass_name(s: &str) -> Result<String, String> {
    throng::scene::passes::PassSet::parse(&[s], "--passes").map_err(|e| {
        let e = e.to_string();
        e.strip_prefix("--passes: ").map(str::to_string).unwrap_or(e)
    })?;
    Ok(s.trim().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_number_says_what_the_argument_takes() {
        assert_eq!(agent_id("17"), Ok(17));
        assert!(agent_id("abc").unwrap_err().contains("not an agent id (a whole number"));
        assert!(agent_id("-1").is_err());
        assert!(frame("10x").unwrap_err().contains("not a frame"));
        assert_eq!(frame("-4"), Ok(-4));
        assert!(count("0").unwrap_err().contains("1 or more"));
        assert!(number("fast").unwrap_err().contains("not a number"));
        assert!(port("99999").unwrap_err().contains("0-65535"));
        assert!(ip("localhost").unwrap_err().contains("not an IP address"));
    }

    #[test]
    fn pass_names_are_checked_at_parse_time() {
        assert_eq!(pass_name("diffuse_direct").as_deref(), Ok("diffuse_direct"));
        assert_eq!(pass_name("all").as_deref(), Ok("all"));
        let e = pass_name("difuse_direct").unwrap_err();
        assert!(e.contains("unknown pass `difuse_direct`") && e.contains("diffuse_direct"), "{e}");
    }
}
