//! Integration tests for the cache stage: formats, round trips, random
//! access, bad input (library errors and CLI exit codes), JuPedSim import.

mod common;

use std::path::{Path, PathBuf};

use glam::Vec3;
use throng::cache::{self, binary, AgentSample, CacheReader, CrowdCache, FrameBlock, ImportOptions, HIDDEN, SEATED};

fn rec(id: u32, x: f32, z: f32, rig: u16, cycle: u16, cf: f32, flags: u8) -> AgentSample {
    AgentSample { id, position: Vec3::new(x, 0.0, z), heading: x * 0.1, rig, cycle, cycle_frame: cf, flags }
}

/// A crowd whose tables are in first-use order (what .crowd stores), with
/// awkward floats, agents entering and leaving, and an empty frame.
fn sample() -> CrowdCache {
    CrowdCache {
        rigs: vec!["bipedThinA".into(), "bipedTallB".into()],
        cycles: vec!["WalkA".into(), "SitA".into(), "IdleA".into()],
        frames: vec![
            FrameBlock {
                frame: -2,
                agents: vec![
                    rec(7, 0.1, -3.55, 0, 0, 0.0, 0),
                    rec(3, -0.0, 1e-40, 1, 1, 31.999998, SEATED),
                    AgentSample { heading: -std::f32::consts::PI, ..rec(1000000, 1.0e30, -7.25, 0, 2, 12.5, HIDDEN) },
                ],
            },
            FrameBlock { frame: 0, agents: vec![rec(3, 1.0 / 3.0, 2.0 / 3.0, 1, 1, 0.1, SEATED | HIDDEN)] },
            FrameBlock { frame: 5, agents: vec![] },
            FrameBlock {
                frame: 7,
                agents: vec![
                    rec(9, 4.5, -2.0, 1, 0, 3.25, 0),
                    rec(7, 0.2, -3.5, 0, 0, 1.0, 0),
                    rec(3, 5.0, 6.0, 1, 2, 2.0, 0),
                ],
            },
        ],
    }
}

use common::throng;

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

fn err_text<T: std::fmt::Debug>(r: throng::error::Result<T>) -> String {
    match r {
        Ok(v) => panic!("expected an error, got {v:?}"),
        Err(e) => e.to_string(),
    }
}

fn assert_has(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "message {msg:?} lacks {p:?}");
    }
}

// --- round trips ---------------------------------------------------------

#[test]
fn binary_write_read_equal() {
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("a.crowd");
    cache::write(&p, &sample()).unwrap();
    assert_eq!(cache::read(&p).unwrap(), sample());
    // Negative zero and subnormals keep their bits.
    let back = cache::read(&p).unwrap();
    assert_eq!(back.frames[0].agents[1].position.x.to_bits(), (-0.0f32).to_bits());
    assert_eq!(back.frames[0].agents[1].position.z, 1e-40);
}

#[test]
fn csv_write_read_equal() {
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("a.csv");
    cache::write(&p, &sample()).unwrap();
    assert_eq!(cache::read(&p).unwrap(), sample());
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(text.starts_with("frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n"));
    assert!(text.contains("\n5,,,,,,,,,\n"), "empty frame row: {text}");
    assert!(text.contains(",seated|hidden\n"));
}

#[test]
fn binary_csv_binary_is_byte_identical() {
    let dir = common::tempdir().unwrap();
    let (a, c, b) = (dir.path().join("a.crowd"), dir.path().join("a.csv"), dir.path().join("b.crowd"));
    cache::write(&a, &sample()).unwrap();
    // Through the CLI, as a lighter would.
    assert!(throng(&["cache", "convert", s(&a), s(&c)]).status.success());
    assert!(throng(&["cache", "convert", s(&c), s(&b)]).status.success());
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    // And CSV -> binary -> CSV.
    let c2 = dir.path().join("c2.csv");
    cache::write(&c2, &cache::read(&b).unwrap()).unwrap();
    assert_eq!(std::fs::read(&c).unwrap(), std::fs::read(&c2).unwrap());
}

#[test]
fn tables_are_stored_in_first_use_order() {
    // Unused and out-of-order names: the binary keeps each agent's names
    // but stores the tables as CSV would rebuild them.
    let mut crowd = sample();
    crowd.rigs = vec!["unused".into(), "bipedTallB".into(), "bipedThinA".into()];
    for b in &mut crowd.frames {
        for a in &mut b.agents {
            a.rig = if a.rig == 0 { 2 } else { 1 };
        }
    }
    let dir = common::tempdir().unwrap();
    let (a, c, b) = (dir.path().join("a.crowd"), dir.path().join("a.csv"), dir.path().join("b.crowd"));
    cache::write(&a, &crowd).unwrap();
    let back = cache::read(&a).unwrap();
    assert_eq!(back, sample());
    assert_eq!(back, cache::canonical(&crowd));
    cache::write(&c, &crowd).unwrap();
    cache::write(&b, &cache::read(&c).unwrap()).unwrap();
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

#[test]
fn writes_are_deterministic() {
    let dir = common::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.crowd"), dir.path().join("b.crowd"));
    cache::write(&a, &sample()).unwrap();
    cache::write(&b, &sample()).unwrap();
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    assert_eq!(binary::parse_bytes(&std::fs::read(&a).unwrap()).unwrap(), sample());
}

#[test]
fn random_access_equals_full_read() {
    let dir = common::tempdir().unwrap();
    for name in ["a.crowd", "a.csv"] {
        let p = dir.path().join(name);
        cache::write(&p, &sample()).unwrap();
        let full = cache::read(&p).unwrap();
        let r = CacheReader::open(&p).unwrap();
        assert_eq!(r.frames(), &[-2, 0, 5, 7]);
        assert_eq!(r.rigs(), &full.rigs[..]);
        assert_eq!(r.cycles(), &full.cycles[..]);
        // Backwards, to show order does not matter.
        for b in full.frames.iter().rev() {
            assert_eq!(&r.read_frame(b.frame).unwrap(), b);
        }
        assert_has(&err_text(r.read_frame(3)), &[name, "no frame 3", "-2-7"]);
    }
}

#[test]
fn binary_reader_reads_only_the_frame_asked_for() {
    // Corrupt the last block: opening and reading other frames still work,
    // so neither reads the whole file.
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("a.crowd");
    cache::write(&p, &sample()).unwrap();
    let mut bytes = std::fs::read(&p).unwrap();
    let n = bytes.len();
    bytes[n - 10] ^= 0xff;
    std::fs::write(&p, &bytes).unwrap();
    let r = CacheReader::open(&p).unwrap();
    assert_eq!(r.read_frame(0).unwrap(), sample().frames[1]);
    assert_has(&err_text(r.read_frame(7)), &["a.crowd", "frame 7", "checksum mismatch"]);
}

#[test]
fn info_counts() {
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("a.crowd");
    cache::write(&p, &sample()).unwrap();
    let i = cache::info(&CacheReader::open(&p).unwrap()).unwrap();
    assert_eq!((i.frame_first, i.frame_last, i.frames), (Some(-2), Some(7), 4));
    assert_eq!((i.agents, i.agent_frames), (4, 7));
    assert_eq!((i.agents_per_frame_min, i.agents_per_frame_max), (0, 3));
    assert_eq!((i.seated_agents, i.seated_agent_frames, i.hidden_agent_frames), (1, 2, 2));
    let rigs: Vec<_> = i.rigs.iter().map(|n| (n.name.as_str(), n.agent_frames, n.agents)).collect();
    assert_eq!(rigs, [("bipedThinA", 3, 2), ("bipedTallB", 4, 2)]);
    let cycles: Vec<_> = i.cycles.iter().map(|n| (n.name.as_str(), n.agent_frames, n.agents)).collect();
    assert_eq!(cycles, [("WalkA", 3, 2), ("SitA", 2, 1), ("IdleA", 2, 2)]);
    let b = i.bounds.unwrap();
    assert_eq!((b.min[0], b.max[0], b.min[2], b.max[2]), (-0.0, 1.0e30, -7.25, 6.0));

    let out = throng(&["cache", "info", s(&p), "--json"]);
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in ["file", "format", "frame_first", "frame_last", "frames", "agents", "agent_frames"] {
        assert!(v.get(key).is_some(), "--json lacks {key}");
    }
    assert_eq!(v["format"], "crowd");
    assert_eq!(v["rigs"][1]["name"], "bipedTallB");
    let out = throng(&["cache", "info", s(&p)]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert_has(&text, &["frames   -2-7 (4 frames)", "agents   4 (0-3 per frame, 7 agent-frames)"]);
}

// --- bad binary input ------------------------------------------------------

/// Recomputes every CRC of a .crowd file from its documented layout, so a
/// test can plant bad values that only the content checks catch.
fn fix_crcs(b: &mut [u8]) {
    let u32_at = |b: &[u8], o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    let h = crc32fast::hash(&b[..28]);
    b[28..32].copy_from_slice(&h.to_le_bytes());
    let meta_len = u32_at(b, 12) as usize;
    let frames = u32_at(b, 16) as usize;
    let index_start = 32 + meta_len - 4 - 24 * frames;
    for i in 0..frames {
        let e = index_start + 24 * i;
        let off = u64::from_le_bytes(b[e + 8..e + 16].try_into().unwrap()) as usize;
        let len = u64::from_le_bytes(b[e + 16..e + 24].try_into().unwrap()) as usize;
        let c = crc32fast::hash(&b[off..off + len - 4]);
        b[off + len - 4..off + len].copy_from_slice(&c.to_le_bytes());
    }
    let c = crc32fast::hash(&b[32..32 + meta_len - 4]);
    b[32 + meta_len - 4..32 + meta_len].copy_from_slice(&c.to_le_bytes());
}

/// Byte offset of record `agent` in the block of index entry `entry`.
fn record_at(p: &Path, entry: usize, agent: usize) -> usize {
    let r = binary::BinaryReader::open(p).unwrap();
    r.index()[entry].offset as usize + 8 + 32 * agent
}

/// Writes the sample, lets `edit` change its bytes, and returns the reader
/// error and the CLI's stderr for the result.
fn corrupt(name: &str, edit: impl FnOnce(&Path, &mut Vec<u8>)) -> (String, String) {
    let dir = common::tempdir().unwrap();
    let p = dir.path().join(name);
    cache::write(&p, &sample()).unwrap();
    let mut bytes = std::fs::read(&p).unwrap();
    edit(&p, &mut bytes);
    std::fs::write(&p, &bytes).unwrap();
    let lib = err_text(cache::read(&p));
    // The fuzz entry point agrees without panicking.
    assert!(binary::parse_bytes(&bytes).is_err());
    let out = throng(&["cache", "info", s(&p)]);
    assert!(!out.status.success(), "exit 0 for {name}");
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_has(&stderr, &["throng: error:", name]);
    (lib, stderr)
}

#[test]
fn truncated_binary() {
    let full = {
        let dir = common::tempdir().unwrap();
        let p = dir.path().join("x.crowd");
        cache::write(&p, &sample()).unwrap();
        std::fs::read(&p).unwrap().len()
    };
    for cut in [0, 5, 20, 31, 40, full - 70, full - 1] {
        let (msg, _) = corrupt("cut.crowd", |_, b| b.truncate(cut));
        assert_has(&msg, &["cut.crowd", "truncated"]);
    }
    // Cut inside the last block: the error names that frame.
    let (msg, _) = corrupt("cut.crowd", |_, b| b.truncate(full - 1));
    assert_has(&msg, &["frame 7", "truncated"]);
    let (msg, _) = corrupt("long.crowd", |_, b| b.push(0));
    assert_has(&msg, &["trailing bytes"]);
}

#[test]
fn wrong_magic_unknown_version_and_checksums() {
    let (msg, _) = corrupt("magic.crowd", |_, b| b[0] = b'X');
    assert_has(&msg, &["magic.crowd", "not a throng .crowd cache", "magic"]);
    let (msg, _) = corrupt("version.crowd", |_, b| b[8] = 2);
    assert_has(&msg, &["version.crowd", "unknown .crowd version 2"]);
    let (msg, _) = corrupt("header.crowd", |_, b| b[16] ^= 1);
    assert_has(&msg, &["header.crowd", "header checksum mismatch"]);
    let (msg, _) = corrupt("index.crowd", |_, b| b[34] ^= 1);
    assert_has(&msg, &["index.crowd", "index checksum mismatch"]);
    let (msg, stderr) = corrupt("block.crowd", |p, b| {
        let at = record_at(p, 3, 1);
        b[at + 4] ^= 1
    });
    assert_has(&msg, &["block.crowd", "frame 7", "frame block checksum mismatch"]);
    assert_has(&stderr, &["frame 7"]);
    // A header whose counts promise more than the file holds.
    let (msg, _) = corrupt("counts.crowd", |_, b| {
        b[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
        fix_crcs_header(b);
    });
    assert_has(&msg, &["counts.crowd", "corrupt header"]);
    let (msg, _) = corrupt("metalen.crowd", |_, b| {
        b[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        fix_crcs_header(b);
    });
    assert_has(&msg, &["metalen.crowd", "truncated"]);
}

fn fix_crcs_header(b: &mut [u8]) {
    let h = crc32fast::hash(&b[..28]);
    b[28..32].copy_from_slice(&h.to_le_bytes());
}

#[test]
fn bad_records_in_binary() {
    // Frame 7 (index entry 3) holds agents 9, 7, 3.
    let (msg, stderr) = corrupt("nan.crowd", |p, b| {
        let at = record_at(p, 3, 1) + 4;
        b[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        fix_crcs(b);
    });
    assert_has(&msg, &["nan.crowd", "frame 7", "agent 7", "field `x`", "finite"]);
    assert_has(&stderr, &["frame 7", "agent 7"]);

    let (msg, _) = corrupt("inf.crowd", |p, b| {
        let at = record_at(p, 3, 2) + 8;
        b[at..at + 4].copy_from_slice(&f32::INFINITY.to_le_bytes());
        fix_crcs(b);
    });
    assert_has(&msg, &["inf.crowd", "frame 7", "agent 3", "field `y`", "inf"]);

    let (msg, _) = corrupt("heading.crowd", |p, b| {
        let at = record_at(p, 3, 0) + 16;
        b[at..at + 4].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
        fix_crcs(b);
    });
    assert_has(&msg, &["frame 7", "agent 9", "heading"]);

    let (msg, _) = corrupt("dup.crowd", |p, b| {
        let at = record_at(p, 3, 2);
        b[at..at + 4].copy_from_slice(&9u32.to_le_bytes());
        fix_crcs(b);
    });
    assert_has(&msg, &["dup.crowd", "frame 7", "agent 9", "appears twice"]);

    let (msg, _) = corrupt("rig.crowd", |p, b| {
        let at = record_at(p, 3, 1) + 20;
        b[at..at + 2].copy_from_slice(&5u16.to_le_bytes());
        fix_crcs(b);
    });
    assert_has(&msg, &["rig.crowd", "frame 7", "agent 7", "unknown rig index 5"]);

    let (msg, _) = corrupt("cycle.crowd", |p, b| {
        let at = record_at(p, 3, 1) + 22;
        b[at..at + 2].copy_from_slice(&3u16.to_le_bytes());
        fix_crcs(b);
    });
    assert_has(&msg, &["frame 7", "agent 7", "unknown cycle index 3"]);

    let (msg, _) = corrupt("order.crowd", |p, b| {
        // Frame 5 -> 0: index entry and block header both, checksums fixed.
        let r = binary::BinaryReader::open(p).unwrap();
        let e = r.index()[2];
        let meta_len = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
        let entry = 32 + meta_len - 4 - 24 * (4 - 2);
        b[entry..entry + 4].copy_from_slice(&0i32.to_le_bytes());
        b[e.offset as usize..e.offset as usize + 4].copy_from_slice(&0i32.to_le_bytes());
        fix_crcs(b);
    });
    assert_has(&msg, &["order.crowd", "frame 0 follows frame 0", "frames must increase"]);
}

// --- bad CSV input ---------------------------------------------------------

const HEADER: &str = "frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags";

fn csv_error(body: &str) -> (String, String) {
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("bad.csv");
    std::fs::write(&p, format!("{HEADER}\n{body}")).unwrap();
    let lib = err_text(cache::read(&p));
    let out_path = dir.path().join("out.crowd");
    let out = throng(&["cache", "convert", s(&p), s(&out_path)]);
    assert_eq!(out.status.code(), Some(2));
    // No output, not even a temporary file, after a failed convert.
    assert!(!out_path.exists());
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, vec![std::ffi::OsString::from("bad.csv")]);
    (lib, String::from_utf8(out.stderr).unwrap())
}

#[test]
fn bad_csv_lines() {
    let ok = "1,4,0,0,0,0,R,C,0,\n";
    let (msg, stderr) = csv_error(&format!("{ok}1,5,0,0,0,R,C,0,\n"));
    assert_has(&msg, &["bad.csv:3", "expected 10 columns, found 9"]);
    assert_has(&stderr, &["bad.csv:3"]);

    let (msg, _) = csv_error(&format!("{ok}1,5,0,abc,0,0,R,C,0,\n"));
    assert_has(&msg, &["bad.csv:3", "column 4 (y)", "`abc`", "field `y`", "agent 5", "frame 1"]);

    let (msg, _) = csv_error("x1,5,0,0,0,0,R,C,0,\n");
    assert_has(&msg, &["bad.csv:2", "column 1 (frame)"]);

    let (msg, _) = csv_error("1,-5,0,0,0,0,R,C,0,\n");
    assert_has(&msg, &["bad.csv:2", "column 2 (id)", "agent id"]);

    let (msg, _) = csv_error(&format!("{ok}1,5,0,0,0,0,R,C,0,sitting\n"));
    assert_has(&msg, &["bad.csv:3", "unknown flag `sitting`", "field `flags`"]);

    let (msg, _) = csv_error(&format!("{ok}1,5,NaN,0,0,0,R,C,0,\n"));
    assert_has(&msg, &["bad.csv:3", "frame 1", "agent 5", "field `x`", "finite"]);

    let (msg, _) = csv_error(&format!("{ok}1,5,0,0,0,0,R,C,inf,\n"));
    assert_has(&msg, &["bad.csv:3", "agent 5", "cycle_frame"]);

    let (msg, _) = csv_error(&format!("{ok}1,4,1,0,0,0,R,C,0,\n"));
    assert_has(&msg, &["bad.csv:3", "frame 1", "agent 4", "appears twice"]);

    let (msg, _) = csv_error(&format!("{ok}2,4,0,0,0,0,R,C,0,\n0,4,0,0,0,0,R,C,0,\n"));
    assert_has(&msg, &["bad.csv:4", "frame 0 follows frame 2"]);

    let (msg, _) = csv_error(&format!("{ok}1,5,0,0,0,0,,C,0,\n"));
    assert_has(&msg, &["bad.csv:3", "column 7 (rig)", "empty name"]);

    let dir = common::tempdir().unwrap();
    let p = dir.path().join("head.csv");
    std::fs::write(&p, "frame,id,x,y,z\n1,2,3,4,5\n").unwrap();
    assert_has(&err_text(cache::read(&p)), &["head.csv:1", "expected the header"]);
    std::fs::write(&p, b"frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n1,2,\xff").unwrap();
    assert_has(&err_text(cache::read(&p)), &["head.csv:2", "not UTF-8"]);
    // Reordered columns and quoted fields are read; errors name the file's column.
    std::fs::write(&p, "id,frame,\"x\",y,z,heading,rig,cycle,cycle_frame,flags\n4,1,\"0.5\",0,0,0,\"R\",C,0,\n")
        .unwrap();
    let c = cache::read(&p).unwrap();
    assert_eq!((c.frames[0].frame, c.frames[0].agents[0].id, c.frames[0].agents[0].position.x), (1, 4, 0.5));
    assert_eq!(c.rigs, vec!["R".to_string()]);
    std::fs::write(&p, "id,frame,x,y,z,heading,rig,cycle,cycle_frame,flags\n4,1,0,q,0,0,R,C,0,\n").unwrap();
    assert_has(&err_text(cache::read(&p)), &["head.csv:2", "column 4 (y)", "`q`"]);
    std::fs::write(&p, "frame,agent_id,x,y,z,heading_radians,speed\n0,1,0,0,0,0,1\n").unwrap();
    assert_has(
        &err_text(cache::read(&p)),
        &["head.csv:1", "found `frame,agent_id,x,y,z,heading_radians,speed`", "preset or columns"],
    );
    // CRLF and a BOM are accepted.
    std::fs::write(&p, format!("\u{feff}{HEADER}\r\n{ok}").replace('\n', "\r\n")).unwrap();
    assert_eq!(cache::read(&p).unwrap().frames[0].agents[0].id, 4);
}

// --- usage errors ------------------------------------------------------------

#[test]
fn usage_errors() {
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("a.crowd");
    cache::write(&p, &sample()).unwrap();
    let out = throng(&["cache", "convert", s(&p), s(&dir.path().join("a.sqlite"))]);
    assert_eq!(out.status.code(), Some(2));
    assert_has(&String::from_utf8(out.stderr).unwrap(), &["read only"]);
    let out = throng(&["cache", "info", s(&dir.path().join("a.txt"))]);
    assert_has(&String::from_utf8(out.stderr).unwrap(), &["a.txt", "needs its layout", "preset"]);
    let out = throng(&["cache", "info", s(&dir.path().join("a.xyz"))]);
    assert_has(&String::from_utf8(out.stderr).unwrap(), &["a.xyz", "unknown cache format"]);
    let out = throng(&["cache", "info", s(&dir.path().join("missing.crowd"))]);
    assert_eq!(out.status.code(), Some(2));
    assert_has(&String::from_utf8(out.stderr).unwrap(), &["missing.crowd"]);
    let out = throng(&["cache", "info", s(&fixture()), "--rig-file", "rig.glb"]);
    assert_eq!(out.status.code(), Some(2));
    assert_has(&String::from_utf8(out.stderr).unwrap(), &["rig.glb"]);
    let out = throng(&["cache", "info", s(&fixture()), "--stride", "0"]);
    assert_has(&String::from_utf8(out.stderr).unwrap(), &["--stride: must be a positive number"]);
    // Writing a NaN is refused before any file appears.
    let mut bad = sample();
    bad.frames[1].agents[0].position.y = f32::NAN;
    let q = dir.path().join("nan.crowd");
    assert_has(&err_text(cache::write(&q, &bad)), &["nan.crowd", "frame 0", "agent 3"]);
    assert!(!q.exists());
}

// --- JuPedSim ----------------------------------------------------------------

fn fixture() -> PathBuf {
    common::fixture("jupedsim_small.sqlite")
}

/// (frame, id) -> (pos_x, pos_y, ori_x, ori_y) straight from SQLite.
fn raw_rows(p: &Path) -> std::collections::BTreeMap<(i32, u32), [f64; 4]> {
    let conn = rusqlite::Connection::open(p).unwrap();
    let mut st = conn.prepare("SELECT frame, id, pos_x, pos_y, ori_x, ori_y FROM trajectory_data").unwrap();
    let rows =
        st.query_map([], |r| Ok(((r.get(0)?, r.get(1)?), [r.get(2)?, r.get(3)?, r.get(4)?, r.get(5)?]))).unwrap();
    rows.map(|r| r.unwrap()).collect()
}

#[test]
fn jupedsim_fixture_import() {
    let crowd = cache::read(fixture()).unwrap();
    assert_eq!(crowd.rigs, ["bipedThinA"]);
    assert_eq!(crowd.cycles, ["WalkA"]);
    assert_eq!(crowd.frames.len(), 50);
    assert_eq!((crowd.frames[0].frame, crowd.frames[49].frame), (0, 49));
    assert!(crowd.frames.iter().all(|b| b.agents.len() == 5));
    let raw = raw_rows(&fixture());
    for b in &crowd.frames {
        for a in &b.agents {
            let [x, y, ox, oy] = raw[&(b.frame, a.id)];
            // (x, y) -> (x, 0, -y), and the heading's direction matches ori.
            assert_eq!(a.position, Vec3::new(x as f32, 0.0, -y as f32));
            if ox != 0.0 || oy != 0.0 {
                let (dx, dz) = (a.heading.sin(), a.heading.cos());
                assert!((dx as f64 - ox).abs() < 1e-5 && (dz as f64 + oy).abs() < 1e-5, "heading {}", a.heading);
            }
        }
    }
    // Frame 0 has ori (0, 0): heading from the agent's next movement.
    for a in &crowd.frames[0].agents {
        let [x0, y0, ox, oy] = raw[&(0, a.id)];
        assert_eq!((ox, oy), (0.0, 0.0));
        let [x1, y1, ..] = raw[&(1, a.id)];
        let want = ((x1 - x0) as f32).atan2(-(y1 - y0) as f32);
        assert!((a.heading - want).abs() < 1e-5, "agent {} heading {} want {want}", a.id, a.heading);
    }
}

#[test]
fn jupedsim_heading_from_motion_and_cycle_advance() {
    // Zero one agent's orientation mid-walk: the heading follows its motion.
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("edit.sqlite");
    std::fs::copy(fixture(), &p).unwrap();
    let conn = rusqlite::Connection::open(&p).unwrap();
    conn.execute("UPDATE trajectory_data SET ori_x = 0, ori_y = 0 WHERE id = 2 AND frame = 20", []).unwrap();
    drop(conn);
    let opts = ImportOptions { stride: Some(0.7), cycle_length: Some(24.0), ..ImportOptions::default() };
    let crowd = cache::read_with(&p, &opts).unwrap();
    let raw = raw_rows(&p);
    let a20 = crowd.frames[20].agents.iter().find(|a| a.id == 2).unwrap();
    let ([x19, y19, ..], [x20, y20, ..]) = (raw[&(19, 2)], raw[&(20, 2)]);
    let want = ((x20 - x19) as f32).atan2(-(y20 - y19) as f32);
    assert!((a20.heading - want).abs() < 1e-5);

    // The cycle frame advances by distance / stride * length (mod length).
    for id in 1..=5u32 {
        for f in 1..50usize {
            let find = |b: &FrameBlock| *b.agents.iter().find(|a| a.id == id).unwrap();
            let (a, b) = (find(&crowd.frames[f - 1]), find(&crowd.frames[f]));
            let dist = (b.position - a.position).length();
            let got = (b.cycle_frame - a.cycle_frame).rem_euclid(24.0);
            let want = dist / 0.7 * 24.0;
            assert!((got - want).abs() < 1e-3, "agent {id} frame {f}: {got} vs {want}");
            assert!((0.0..24.0).contains(&b.cycle_frame));
        }
    }
    // Options reach the tables.
    let opts = ImportOptions { rig: "bipedTallB".into(), cycle: "WalkB".into(), ..ImportOptions::default() };
    let crowd = cache::read_with(fixture(), &opts).unwrap();
    assert_eq!((crowd.rigs[0].as_str(), crowd.cycles[0].as_str()), ("bipedTallB", "WalkB"));
}

/// The import flags of `throng cache` as the library takes them.
struct ImportFlags {
    rig: String,
    cycle: String,
    cycle_length: Option<f32>,
    stride: Option<f32>,
    rig_file: Option<std::path::PathBuf>,
}

fn import_args(rig: &str, cycle: &str, rig_file: Option<&str>) -> ImportFlags {
    ImportFlags {
        rig: rig.into(),
        cycle: cycle.into(),
        cycle_length: None,
        stride: None,
        rig_file: rig_file.map(|f| Path::new(env!("CARGO_MANIFEST_DIR")).join(f)),
    }
}

fn options(f: &ImportFlags) -> throng::error::Result<ImportOptions> {
    ImportOptions::new(&f.rig, &f.cycle, f.stride, f.cycle_length, None)?;
    let clip = f
        .rig_file
        .as_deref()
        .map(|p| throng::casting::rig::import_clip(p, &f.rig, &f.cycle, None, None))
        .transpose()?;
    ImportOptions::new(&f.rig, &f.cycle, f.stride, f.cycle_length, clip)
}

/// Cycle frame advance per frame == distance / stride * length (mod length).
fn assert_feet_planted(crowd: &CrowdCache, stride: f32, length: f32) {
    let mut checked = 0;
    for w in crowd.frames.windows(2) {
        for (a, b) in w[0].agents.iter().zip(&w[1].agents) {
            assert_eq!(a.id, b.id);
            let dist = (b.position - a.position).length();
            let got = (b.cycle_frame - a.cycle_frame).rem_euclid(length);
            let want = (dist / stride * length).rem_euclid(length);
            assert!((got - want).abs() < 1e-3, "agent {} frame {}: {got} vs {want}", b.id, w[1].frame);
            assert!((0.0..length).contains(&b.cycle_frame));
            checked += (dist > 0.0) as usize;
        }
    }
    assert!(checked > 100, "{checked} moving agent-frames");
}

/// A skinned character as the import's rig: stride from its root joint's
/// travel, length from the clip, its options as the shot's `[rigs.X]` keys
/// (library) or the `--rig-*` flags (command line).
#[test]
fn skinned_rig_file_gives_stride_and_length() {
    use throng::casting::rig::import_clip;
    use throng::shot::SkinOptions;
    let walker = Path::new(env!("CARGO_MANIFEST_DIR")).join("demo/rigs/walker.glb");
    let figure = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/assets/gltf/RiggedFigure/RiggedFigure.gltf");
    let hips = SkinOptions {
        root: Some("hips".into()),
        cycles: [("WalkA".to_string(), "Walk".to_string())].into(),
        ..Default::default()
    };
    // The demo shot's walker: WalkA plays Walk, hips 1.4 m in 32 frames.
    let clip = import_clip(&walker, "walker", "WalkA", Some(&hips), None).unwrap();
    let o = ImportOptions::new("walker", "WalkA", None, None, Some(clip)).unwrap();
    assert!((o.stride() - 1.4).abs() < 1e-3 && (o.cycle_length() - 32.0).abs() < 1e-3, "{}", o.describe());
    // Detected as skinned without options; with no root joint the walk does not walk.
    let e = err_text(import_clip(&walker, "walker", "Walk", None, None));
    assert_has(&e, &["walker.glb", "field `cycle`", "cycle `Walk` walks 0 m in 32 frames", "root"]);
    let e = err_text(import_clip(&walker, "walker", "Idle", Some(&hips), None));
    assert_has(&e, &["walker.glb", "cycle `Idle` walks 0 m in 48 frames"]);
    let e = err_text(import_clip(&walker, "walker", "RunZ", Some(&hips), None));
    assert_has(&e, &["walker.glb", "no cycle `RunZ`", "WalkA (clip Walk)"]);
    // RiggedFigure (clip #0, 30 frames) has no joint that travels.
    let torso = SkinOptions { root: Some("torso_joint_1".into()), ..Default::default() };
    let e = err_text(import_clip(&figure, "figure", "#0", Some(&torso), None));
    assert_has(&e, &["RiggedFigure.gltf", "cycle `#0` walks 0 m in 30 frames"]);

    // The command line: --rig-root and --rig-cycle are the shot's `root` and `cycles`.
    let out = throng(&[
        "cache",
        "info",
        s(&fixture()),
        "--rig",
        "walker",
        "--cycle",
        "WalkA",
        "--rig-file",
        s(&walker),
        "--rig-root",
        "hips",
        "--rig-cycle",
        "WalkA=Walk",
        "--json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!((v["import"]["stride"].as_f64().unwrap() - 1.4).abs() < 1e-3, "{v}");
    assert!((v["import"]["cycle_length"].as_f64().unwrap() - 32.0).abs() < 1e-3, "{v}");
    let dir = common::tempdir().unwrap();
    let outp = dir.path().join("w.crowd");
    let out = throng(&[
        "cache",
        "convert",
        s(&fixture()),
        s(&outp),
        "--rig",
        "walker",
        "--cycle",
        "Walk",
        "--rig-file",
        s(&walker),
        "--rig-root",
        "hips",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_feet_planted(&cache::read(&outp).unwrap(), 1.4, 32.0);
    // A table import takes the walk and the idle cycle's length from the skinned rig too.
    let table = common::fixture("tabular/eth_obsmat.txt");
    let out = throng(&[
        "cache",
        "info",
        s(&table),
        "--preset",
        "eth-ucy",
        "--rig",
        "walker",
        "--cycle",
        "Walk",
        "--idle-cycle",
        "Idle",
        "--rig-file",
        s(&walker),
        "--rig-root",
        "hips",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_has(
        &String::from_utf8(out.stdout).unwrap(),
        &["rig walker, cycle Walk, stride 1.4 m, cycle length 32 frames"],
    );
    // No root: exit 2 naming the file and the cycle, and nothing written.
    let none = dir.path().join("none.crowd");
    let out = throng(&["cache", "convert", s(&fixture()), s(&none), "--cycle", "Walk", "--rig-file", s(&walker)]);
    assert_eq!(out.status.code(), Some(2));
    assert_has(&String::from_utf8_lossy(&out.stderr), &["walker.glb", "cycle `Walk` walks 0 m"]);
    assert!(!none.exists());
    // The --rig-* flags need --rig-file and read well-formed values.
    let input = fixture();
    for bad in [&["--rig-root", "hips"][..], &["--rig-file", s(&walker), "--rig-cycle", "Walk"]] {
        let mut args = vec!["cache", "info", s(&input)];
        args.extend_from_slice(bad);
        assert_eq!(throng(&args).status.code(), Some(2), "{bad:?}");
    }
}

#[test]
fn jupedsim_rig_file_gives_stride_and_length() {
    // bipedThinA's WalkA: 1.5 m per cycle, 32 frames at the shot's 24 fps
    // (not JuPedSim's 25: cycle frames are shot frames, driven by distance).
    let opts = options(&import_args("bipedThinA", "WalkA", Some("demo/rigs/bipedThinA.glb"))).unwrap();
    assert!((opts.stride() - 1.5).abs() < 1e-4 && (opts.cycle_length() - 32.0).abs() < 1e-3, "{}", opts.describe());
    assert_has(&opts.describe(), &["stride 1.5", "bipedThinA.glb"]);
    let crowd = cache::read_with(fixture(), &opts).unwrap();
    assert_eq!((crowd.rigs[0].as_str(), crowd.cycles[0].as_str()), ("bipedThinA", "WalkA"));
    assert_feet_planted(&crowd, opts.stride(), opts.cycle_length());

    // Another clip of the same rig: WalkB, 1.9 m in 40 frames.
    let opts = options(&import_args("bipedThinA", "WalkB", Some("demo/rigs/bipedThinA.glb"))).unwrap();
    assert!((opts.stride() - 1.9).abs() < 1e-4 && (opts.cycle_length() - 40.0).abs() < 1e-3);
    assert_feet_planted(&cache::read_with(fixture(), &opts).unwrap(), 1.9, 40.0);

    // --stride and --cycle-length override the rig, each on its own.
    let mut args = import_args("bipedThinA", "WalkA", Some("demo/rigs/bipedThinA.glb"));
    args.stride = Some(0.7);
    let opts = options(&args).unwrap();
    assert_eq!((opts.stride(), opts.cycle_length()), (0.7, 32.0));
    assert_has(&opts.describe(), &["stride 0.7 m,", "32 frames (rig file"]);
    args.cycle_length = Some(24.0);
    let opts = options(&args).unwrap();
    assert_eq!((opts.stride(), opts.cycle_length()), (0.7, 24.0));
    assert_feet_planted(&cache::read_with(fixture(), &opts).unwrap(), 0.7, 24.0);

    // Errors name the rig file and what is wrong.
    let e = err_text(options(&import_args("bipedThinA", "IdleA", Some("demo/rigs/bipedThinA.glb"))));
    assert_has(&e, &["bipedThinA.glb", "IdleA", "stride 0", "give the stride"]);
    let e = err_text(options(&import_args("bipedThinA", "RunZ", Some("demo/rigs/bipedThinA.glb"))));
    assert_has(&e, &["bipedThinA.glb", "RunZ", "WalkA"]);
    let e = err_text(options(&import_args("bipedTallB", "WalkA", Some("demo/rigs/bipedThinA.glb"))));
    assert_has(&e, &["bipedThinA.glb", "import it as rig `bipedThinA`"]);

    // The command line: settings and their source are reported.
    let rig = Path::new(env!("CARGO_MANIFEST_DIR")).join("demo/rigs/bipedTallB.glb");
    let out = throng(&["cache", "info", s(&fixture()), "--rig", "bipedTallB", "--rig-file", s(&rig), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!((v["import"]["stride"].as_f64().unwrap() - 1.7).abs() < 1e-4, "{v}");
    assert!((v["import"]["cycle_length"].as_f64().unwrap() - 32.0).abs() < 1e-3, "{v}");
    assert!(v["import"]["rig_file"].as_str().unwrap().ends_with("bipedTallB.glb"), "{v}");
    let dir = common::tempdir().unwrap();
    let outp = dir.path().join("j.crowd");
    let out = throng(&["cache", "convert", s(&fixture()), s(&outp), "--rig", "bipedTallB", "--rig-file", s(&rig)]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_has(&String::from_utf8(out.stdout).unwrap(), &["stride 1.7", "(rig file"]);
    assert_feet_planted(&cache::read(&outp).unwrap(), 1.7, 32.0);
}

fn sqlite_error(name: &str, setup: &str) -> String {
    let dir = common::tempdir().unwrap();
    let p = dir.path().join(name);
    std::fs::copy(fixture(), &p).unwrap();
    rusqlite::Connection::open(&p).unwrap().execute_batch(setup).unwrap();
    let msg = err_text(cache::read(&p));
    let out = throng(&["cache", "info", s(&p)]);
    assert_eq!(out.status.code(), Some(2));
    assert_has(&String::from_utf8(out.stderr).unwrap(), &[name]);
    msg
}

#[test]
fn bad_jupedsim_files() {
    let msg = sqlite_error("notraj.sqlite", "DROP TABLE trajectory_data;");
    assert_has(&msg, &["notraj.sqlite", "no `trajectory_data` table"]);
    let msg = sqlite_error("nocol.sqlite", "ALTER TABLE trajectory_data DROP COLUMN ori_y;");
    assert_has(&msg, &["nocol.sqlite", "ori_y"]);
    let msg = sqlite_error("inf.sqlite", "UPDATE trajectory_data SET pos_x = 1e999 WHERE id = 3 AND frame = 7;");
    assert_has(&msg, &["inf.sqlite", "frame 7", "agent 3", "field `x`", "finite"]);
    let msg = sqlite_error("text.sqlite", "UPDATE trajectory_data SET pos_y = 'abc' WHERE id = 4 AND frame = 9;");
    assert_has(&msg, &["text.sqlite", "frame 9", "agent 4", "pos_y"]);
    let msg = sqlite_error(
        "dup.sqlite",
        "INSERT INTO trajectory_data SELECT * FROM trajectory_data WHERE id = 2 AND frame = 5;",
    );
    assert_has(&msg, &["dup.sqlite", "frame 5", "agent 2", "appears twice"]);
    let msg = sqlite_error("ver.sqlite", "UPDATE metadata SET value = '9' WHERE key = 'version';");
    assert_has(&msg, &["ver.sqlite", "version 9"]);

    let dir = common::tempdir().unwrap();
    let p = dir.path().join("junk.sqlite");
    std::fs::write(&p, b"this is not a database, just text that is long enough to have a header").unwrap();
    assert_has(&err_text(cache::read(&p)), &["junk.sqlite", "JuPedSim SQLite"]);
}

/// The done criterion, on the real file from ../shared.
#[test]
fn real_jupedsim_file_info() {
    let real = common::shared_asset("crowd/jupedsim_bottleneck_200/bottleneck_200.sqlite");
    let out = throng(&["cache", "info", s(&real), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["agents"], 200);
    assert_eq!(
        (v["frame_first"].as_i64(), v["frame_last"].as_i64(), v["frames"].as_i64()),
        (Some(0), Some(999), Some(1000))
    );
    assert_eq!(v["agents_per_frame_max"], 200);
    assert_eq!(v["agent_frames"], 171336);
    assert_eq!(v["bounds"]["min"][1], 0.0);
    assert_eq!(v["import"]["stride"].as_f64(), Some(1.4));
}

/// Timings for the report: `cargo test --test cache -- --ignored --nocapture`.
#[test]
#[ignore]
fn timings_on_real_file() {
    let real = common::shared_asset("crowd/jupedsim_bottleneck_200/bottleneck_200.sqlite");
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("real.crowd");
    let t = std::time::Instant::now();
    let crowd = cache::read(&real).unwrap();
    eprintln!("import sqlite: {:?}", t.elapsed());
    let t = std::time::Instant::now();
    cache::write(&p, &crowd).unwrap();
    eprintln!("write .crowd: {:?} ({} bytes)", t.elapsed(), std::fs::metadata(&p).unwrap().len());
    let t = std::time::Instant::now();
    let r = CacheReader::open(&p).unwrap();
    let b = r.read_frame(500).unwrap();
    eprintln!("open + read frame 500 ({} agents): {:?}", b.agents.len(), t.elapsed());
    let t = std::time::Instant::now();
    let all = cache::read(&p).unwrap();
    eprintln!("read whole .crowd ({} frames): {:?}", all.frames.len(), t.elapsed());
    assert_eq!(all, crowd);
}

/// Issue 27 item 7: no imported recording turns faster than the turn rate
/// between consecutive frames (tables at the shot's 24 fps, JuPedSim at its 25).
#[test]
fn imported_recordings_turn_no_faster_than_a_person() {
    use throng::cache::tabular::{self, Preset, TabularOptions, TabularSpec};
    let fixtures = common::fixture("tabular");
    let check = |crowd: &CrowdCache, fps: f32, rate_deg: f32, what: &str| {
        let step = rate_deg.to_radians() / fps;
        let mut last: std::collections::HashMap<u32, (i32, f32)> = Default::default();
        let mut pairs = 0;
        for b in &crowd.frames {
            for a in &b.agents {
                if let Some((f, h)) = last.get(&a.id).copied().filter(|(f, _)| f + 1 == b.frame) {
                    let d =
                        (a.heading - h + std::f32::consts::PI).rem_euclid(std::f32::consts::TAU) - std::f32::consts::PI;
                    assert!(d.abs() <= step + 1e-4, "{what}: agent {} turns {d} rad at frame {f}->{}", a.id, b.frame);
                    pairs += 1;
                }
                last.insert(a.id, (b.frame, a.heading));
            }
        }
        assert!(pairs > 0, "{what}: no consecutive frames checked");
    };
    for (file, preset) in [("petrack_cm.txt", Preset::PeTrack), ("eth_obsmat.txt", Preset::Eth)] {
        for rate in [None, Some(90.0)] {
            let spec = TabularSpec { preset: Some(preset), turn_rate: rate, ..Default::default() };
            let o = TabularOptions::resolve(&spec, 24.0).unwrap();
            let (crowd, _) = tabular::read(&fixtures.join(file), &o).unwrap();
            check(&crowd, 24.0, rate.unwrap_or(360.0), file);
        }
    }
    let real = common::shared_asset("crowd/jupedsim_bottleneck_200/bottleneck_200.sqlite");
    for (file, rate) in [(common::fixture("jupedsim_small.sqlite"), 360.0), (real.clone(), 360.0), (real.clone(), 90.0)]
    {
        let opts = ImportOptions::default().with_turn_rate(Some(rate)).unwrap();
        let crowd = cache::read_with(&file, &opts).unwrap();
        check(&crowd, 25.0, rate, &file.display().to_string());
    }
    // The recording as written snaps (a held heading resuming turns 90
    // degrees and more in a frame); imported at the default rate it turns
    // through the frames between. Drawn: target/tmp/recording_turns.png.
    // As written: no turn limit and no hold (hold_speed 0).
    let read = |rate: f32, hold_speed: f32| {
        let o = ImportOptions { hold_speed, ..ImportOptions::default() }.with_turn_rate(Some(rate)).unwrap();
        cache::read_with(&real, &o).unwrap()
    };
    let (raw, turned) = (read(1e9, 0.0), read(360.0, 0.0));
    let snaps = plot_turns(&raw, &turned, &Path::new(env!("CARGO_TARGET_TMPDIR")).join("recording_turns.png"));
    // 6465 of them: JuPedSim's orientation flips for a frame in the crush.
    assert!(snaps >= 1000, "{snaps} snaps of over 90 degrees in a frame in the recording as written");
    // A rate that is no rate is refused, naming the key.
    let e = ImportOptions::default().with_turn_rate(Some(0.0)).unwrap_err().to_string();
    assert!(e.contains("turn_rate"), "{e}");
}

/// Each agent's samples in frame order: (frame, x, z, heading).
fn tracks(crowd: &CrowdCache) -> std::collections::BTreeMap<u32, Vec<(i32, f32, f32, f32)>> {
    let mut out: std::collections::BTreeMap<u32, Vec<(i32, f32, f32, f32)>> = Default::default();
    for b in &crowd.frames {
        for a in &b.agents {
            out.entry(a.id).or_default().push((b.frame, a.position.x, a.position.z, a.heading));
        }
    }
    out
}

/// A heading change wrapped into [-pi, pi).
fn turn(from: f32, to: f32) -> f32 {
    (to - from + std::f32::consts::PI).rem_euclid(std::f32::consts::TAU) - std::f32::consts::PI
}

/// Draws a recording imported twice, unlimited (`raw`) and at a turn rate
/// (`turned`), to `png`: on the left, top-down, every third agent's path (a
/// hue per agent) with its heading as a dark tick every 25 frames; on the
/// right, for the six agents with the largest one-frame snap in `raw`, the
/// heading from 20 frames before that snap to 60 after it, turned in the
/// agent's hue and raw in grey (within half a turn of the turned one), each
/// in a band of its own (half a turn is 45 pixels). Gives the number of snaps over 90 degrees in a frame in `raw`.
fn plot_turns(raw: &CrowdCache, turned: &CrowdCache, png: &Path) -> usize {
    use tiny_skia::{Color, Paint, PathBuilder, Pixmap, Stroke, Transform};
    let (raw, turned) = (tracks(raw), tracks(turned));
    let (w, h) = (1200u32, 600u32);
    let mut pm = Pixmap::new(w, h).unwrap();
    pm.fill(Color::from_rgba8(250, 250, 247, 255));
    let hue = |id: u32| {
        let a = id as f32 * 2.399_963;
        let c = |k: f32| (120.0 + 100.0 * (a + k).cos()) as u8;
        (c(0.0), c(2.1), c(4.2))
    };
    let line = |pm: &mut Pixmap, pts: &[(f32, f32)], rgb: (u8, u8, u8), alpha: u8, width: f32| {
        let mut pb = PathBuilder::new();
        pb.move_to(pts[0].0, pts[0].1);
        for p in &pts[1..] {
            pb.line_to(p.0, p.1);
        }
        let Some(path) = pb.finish() else { return };
        let mut paint = Paint::default();
        paint.set_color_rgba8(rgb.0, rgb.1, rgb.2, alpha);
        paint.anti_alias = true;
        pm.stroke_path(&path, &paint, &Stroke { width, ..Default::default() }, Transform::identity(), None);
    };
    // Left: the floor, x across and z down, fitted with a margin and centred.
    let (mut lo, mut hi) = ((f32::MAX, f32::MAX), (f32::MIN, f32::MIN));
    for &(_, x, z, _) in turned.values().flatten() {
        lo = (lo.0.min(x), lo.1.min(z));
        hi = (hi.0.max(x), hi.1.max(z));
    }
    let scale = (560.0 / (hi.0 - lo.0)).min(560.0 / (hi.1 - lo.1));
    let top = (h as f32 - (hi.1 - lo.1) * scale) / 2.0;
    let at = |x: f32, z: f32| (20.0 + (x - lo.0) * scale, top + (z - lo.1) * scale);
    for (&id, t) in turned.iter().filter(|(id, _)| *id % 3 == 0) {
        let pts: Vec<(f32, f32)> = t.iter().map(|&(_, x, z, _)| at(x, z)).collect();
        if pts.len() > 1 {
            line(&mut pm, &pts, hue(id), 230, 1.5);
        }
        for &(_, x, z, heading) in t.iter().filter(|s| s.0 % 25 == 0) {
            let (sx, sz) = (heading.sin() * 0.3, heading.cos() * 0.3);
            line(&mut pm, &[at(x, z), at(x + sx, z + sz)], (20, 20, 30), 255, 1.5);
        }
    }
    line(&mut pm, &[(600.0, 0.0), (600.0, h as f32)], (120, 120, 120), 255, 1.0);
    // Right: the six worst snaps.
    let mut snaps = 0;
    let mut worst: Vec<(f32, u32, i32)> = Vec::new();
    for (&id, t) in &raw {
        let mut biggest = (0.0f32, 0);
        for p in t.windows(2).filter(|p| p[0].0 + 1 == p[1].0) {
            let d = turn(p[0].3, p[1].3).abs();
            snaps += (d > std::f32::consts::FRAC_PI_2) as usize;
            if d > biggest.0 {
                biggest = (d, p[1].0);
            }
        }
        worst.push((biggest.0, id, biggest.1));
    }
    worst.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    for (band, &(_, id, snap)) in worst.iter().take(6).enumerate() {
        let mid = 50.0 + band as f32 * 100.0;
        line(&mut pm, &[(610.0, mid + 50.0), (1190.0, mid + 50.0)], (215, 215, 215), 255, 1.0);
        let x = |f: i32| 610.0 + (f - snap + 20) as f32 * 580.0 / 80.0;
        line(&mut pm, &[(x(snap), mid - 45.0), (x(snap), mid + 45.0)], (225, 225, 225), 255, 1.0);
        // The turned heading unwrapped; the raw one drawn within half a turn
        // of it, so a one-frame flip is a spike, not a lasting turn.
        let raw_at: std::collections::BTreeMap<i32, f32> = raw[&id].iter().map(|s| (s.0, s.3)).collect();
        let window: Vec<_> = turned[&id].iter().filter(|s| (snap - 20..=snap + 60).contains(&s.0)).collect();
        let (mut unwrapped, mut last) = (0.0f32, window[0].3);
        let (mut raw_pts, mut turned_pts) = (Vec::new(), Vec::new());
        for &&(f, _, _, heading) in &window {
            unwrapped += turn(last, heading);
            last = heading;
            let y = |a: f32| mid - a / std::f32::consts::PI * 45.0;
            turned_pts.push((x(f), y(unwrapped)));
            if let Some(&r) = raw_at.get(&f) {
                raw_pts.push((x(f), y(unwrapped + turn(heading, r))));
            }
        }
        line(&mut pm, &raw_pts, (165, 165, 165), 255, 3.0);
        line(&mut pm, &turned_pts, hue(id), 255, 2.5);
    }
    pm.save_png(png).unwrap();
    snaps
}

/// Issue 27 item 7: a JuPedSim import refuses each table key it cannot
/// apply, naming it (it used to ignore them), and applies the ones it can.
#[test]
fn jupedsim_refuses_the_keys_it_cannot_apply() {
    let dir = common::tempdir().unwrap();
    let out_path = dir.path().join("j.crowd");
    for (flag, value) in [("--heading", "motion"), ("--idle-cycle", "IdleA"), ("--units", "cm")] {
        let out = throng(&["cache", "convert", s(&fixture()), s(&out_path), flag, value]);
        assert_eq!(out.status.code(), Some(2), "{flag}");
        assert_has(&String::from_utf8(out.stderr).unwrap(), &[flag, "JuPedSim", "cannot apply"]);
        assert!(!out_path.exists(), "{flag}: no output");
    }
    let out = throng(&["cache", "convert", s(&fixture()), s(&out_path), "--turn-rate", "90", "--rotate", "90"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for applies in [
        cache::TabularSpec { turn_rate: Some(90.0), ..Default::default() },
        cache::TabularSpec { hold_speed: Some(0.5), ..Default::default() },
    ] {
        assert_eq!(applies.jupedsim_refuses(), None);
    }
}

/// Issue 49 item 5: `hold_speed` holds JuPedSim headings on every path
/// that imports one (`cache convert --hold-speed`, a shot's `[cache]`
/// key), as it does for tables; it used to be refused, so a standing
/// crowd could not be made to spin less (or more) than the default.
#[test]
fn jupedsim_hold_speed_is_applied_from_the_flag_and_the_shot() {
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("standing.sqlite");
    standing_jupedsim(&p);
    // The flag: 0 never holds (the standing agents spin), the default holds.
    let convert = |extra: &[&str]| {
        let out_path = dir.path().join("standing.crowd");
        let mut args = vec!["cache", "convert", s(&p), s(&out_path)];
        args.extend_from_slice(extra);
        let out = throng(&args);
        assert!(out.status.success(), "{extra:?}: {}", String::from_utf8_lossy(&out.stderr));
        slow_turning(&cache::read(&out_path).unwrap(), 25.0).0
    };
    let (never, default) = (convert(&["--hold-speed", "0"]), convert(&[]));
    assert!(never > 50.0 && default < 1.0, "--hold-speed 0: {never:.1} %, default: {default:.1} %");
    // The shot's key, through casting's import.
    let mut shot = throng::shot::Shot::load(&common::demo_shot()).unwrap();
    shot.cache.path = p.clone();
    shot.cache.import = cache::TabularSpec { hold_speed: Some(0.0), ..Default::default() };
    let never = throng::casting::shot_cache::open(&shot).unwrap().read_all().unwrap();
    assert!(slow_turning(&never, 25.0).0 > 50.0, "shot hold_speed = 0 is applied");
    shot.cache.import = cache::TabularSpec { hold_speed: Some(-1.0), ..Default::default() };
    let e = throng::casting::shot_cache::open(&shot).unwrap_err().to_string();
    assert_has(&e, &["cache.hold_speed", "0 or more"]);
}

/// Issue 27 item 7, issue 49 item A: `cache info` warns, naming the likely
/// unit, when speeds and spacing together are not a person's.
#[test]
fn info_warns_of_speeds_and_spacing_people_do_not_have() {
    let crowd = |spacing: f32, speed: f32| CrowdCache {
        rigs: vec!["bipedThinA".into()],
        cycles: vec!["WalkA".into()],
        frames: (0..30)
            .map(|f| FrameBlock {
                frame: f,
                agents: (0..12)
                    .map(|i| AgentSample {
                        id: i,
                        position: Vec3::new(i as f32 * spacing, 0.0, f as f32 * speed / 24.0),
                        heading: 0.0,
                        rig: 0,
                        cycle: 0,
                        cycle_frame: 0.0,
                        flags: 0,
                    })
                    .collect(),
            })
            .collect(),
    };
    assert_eq!(cache::bounds_warnings(&crowd(1.0, 1.4)), Vec::<String>::new());
    // Twelve people 10 cm apart: metres read as feet, say spacing and speed together.
    let close = cache::bounds_warnings(&crowd(0.1, 1.4));
    assert!(close.len() == 1 && close[0].contains("m read as ft") && close[0].contains("nearest"), "{close:?}");
    // Centimetres read as metres: too fast and too far apart.
    let fast = cache::bounds_warnings(&crowd(100.0, 140.0));
    assert!(fast.len() == 1 && fast[0].contains("median speed 140") && fast[0].contains("units = \"cm\""), "{fast:?}");
    // Issue 49 item A: slow is no wolf: people 1 m apart shuffling at 5 cm/s are people.
    assert_eq!(cache::bounds_warnings(&crowd(1.0, 0.05)), Vec::<String>::new());
    // The PeTrack fixture read in metres, not its centimetres: `cache info` says so.
    let petrack = common::fixture("tabular").join("petrack_cm.txt");
    let out = throng(&["cache", "info", s(&petrack), "--preset", "petrack", "--units", "m"]);
    assert!(out.status.success());
    assert_has(&String::from_utf8(out.stderr).unwrap(), &["median speed 100", "units = \"cm\""]);
    let out = throng(&["cache", "info", s(&petrack), "--preset", "petrack"]);
    assert!(!String::from_utf8(out.stderr).unwrap().contains("warning"));
}

/// Percent of slow agent-frames (under 0.25 m/s between consecutive frames
/// at `fps`) whose heading turns more than 5 degrees in that frame, and
/// how many there are.
fn slow_turning(crowd: &CrowdCache, fps: f32) -> (f64, usize) {
    let (mut slow, mut turning) = (0usize, 0usize);
    for t in tracks(crowd).values() {
        for w in t.windows(2) {
            let ((f0, x0, z0, h0), (f1, x1, z1, h1)) = (w[0], w[1]);
            if f1 != f0 + 1 || (x1 - x0).hypot(z1 - z0) * fps >= 0.25 {
                continue;
            }
            slow += 1;
            turning += usize::from(turn(h0, h1).abs() > 5f32.to_radians());
        }
    }
    (100.0 * turning as f64 / slow.max(1) as f64, slow)
}

/// A JuPedSim file of 20 agents standing with +-5 mm position jitter (their
/// orientation following the jitter, as JuPedSim writes it) and 4 walking
/// +x at 1.2 m/s, 100 frames at 25 fps.
fn standing_jupedsim(p: &Path) {
    let db = rusqlite::Connection::open(p).unwrap();
    db.execute_batch(
        "CREATE TABLE metadata(key TEXT NOT NULL UNIQUE PRIMARY KEY, value TEXT NOT NULL);
         INSERT INTO metadata VALUES ('version', '2'), ('fps', '25');
         CREATE TABLE trajectory_data(frame INTEGER NOT NULL, id INTEGER NOT NULL, pos_x REAL NOT NULL,
             pos_y REAL NOT NULL, ori_x REAL NOT NULL, ori_y REAL NOT NULL);",
    )
    .unwrap();
    let mut seed = 49u64;
    let mut jitter = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((seed >> 33) as f64 / (1u64 << 31) as f64 - 0.5) * 0.01
    };
    let mut last = std::collections::HashMap::new();
    for frame in 0..100 {
        for id in 1..=24u32 {
            let (x, y) = if id <= 20 {
                (f64::from(id % 5) * 0.6 + jitter(), f64::from(id / 5) * 0.6 + jitter())
            } else {
                (f64::from(frame) * 1.2 / 25.0, f64::from(id) * 0.6)
            };
            let (px, py) = last.insert(id, (x, y)).unwrap_or((x, y));
            let (dx, dy) = (x - px, y - py);
            let n = dx.hypot(dy).max(1e-12);
            db.execute(
                "INSERT INTO trajectory_data VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                rusqlite::params![frame, id, x, y, dx / n, dy / n],
            )
            .unwrap();
        }
    }
}

/// Issue 49 item B: JuPedSim agents standing with position jitter hold
/// their heading below the hold speed (the tables' rule), where they used
/// to turn at the turn cap on every frame; walkers still face their
/// orientation. The figures before (hold_speed 0, the old import) and
/// after, on this file and on the real bottleneck recording, are printed.
#[test]
fn jupedsim_agents_standing_with_jitter_hold_their_heading() {
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("standing.sqlite");
    standing_jupedsim(&p);
    let before = cache::read_with(&p, &ImportOptions { hold_speed: 0.0, ..ImportOptions::default() }).unwrap();
    let after = cache::read(&p).unwrap();
    let (b, n) = slow_turning(&before, 25.0);
    let (a, _) = slow_turning(&after, 25.0);
    eprintln!("synthetic standing agents: {n} slow agent-frames, {b:.1} % turn > 5 deg/frame before, {a:.1} % after");
    assert!(n > 1000 && b > 50.0 && a < 1.0, "before {b:.1} %, after {a:.1} % of {n}");
    // Walkers face their orientation (+x: heading 90 degrees) from the first frame on.
    for f in &after.frames {
        let w = f.agents.iter().find(|a| a.id == 22).unwrap();
        assert!((w.heading - std::f32::consts::FRAC_PI_2).abs() < 1e-3, "frame {}: {}", f.frame, w.heading);
    }
    let real = common::shared_asset("crowd/jupedsim_bottleneck_200/bottleneck_200.sqlite");
    let before = cache::read_with(&real, &ImportOptions { hold_speed: 0.0, ..ImportOptions::default() }).unwrap();
    let (b, n) = slow_turning(&before, 25.0);
    let (a, _) = slow_turning(&cache::read(&real).unwrap(), 25.0);
    eprintln!("bottleneck_200.sqlite: {n} slow agent-frames, {b:.1} % turn > 5 deg/frame before, {a:.1} % after");
    assert!(a < b / 4.0, "real recording: before {b:.1} %, after {a:.1} %");
}
