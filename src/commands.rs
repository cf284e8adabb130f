//! The glue between the command line and the stages: each `cmd_*` loads
//! what its verb needs, runs the stage and prints the result.

use std::fmt::Write as _;
use std::path::Path;

use glam::Vec3;
use serde::Serialize;

use crate::cache::AgentRecord;
use crate::cli::{BotinfoArgs, CastArgs};
use crate::error::{Error, Result};
use crate::pose::ShotCrowd;

/// One part row of the casting table.
#[derive(Debug, Clone, Serialize)]
pub struct PartRow {
    /// Rig slot.
    pub slot: String,
    /// Mesh name, or null for an empty slot.
    pub mesh: Option<String>,
    /// glTF file of the mesh.
    pub file: Option<String>,
    /// Material name.
    pub material: Option<String>,
}

/// One agent of the casting table.
#[derive(Debug, Serialize)]
pub struct CastRow {
    /// Cache id.
    pub id: u32,
    /// Rig.
    pub rig: String,
    /// Scheme.
    pub scheme: String,
    /// Height scale.
    pub height_scale: f32,
    /// Whether the height jitter applies.
    pub scaled: bool,
    /// Parts per slot.
    pub parts: Vec<PartRow>,
}

/// Instancing figures for `throng cast --stats`.
#[derive(Debug, Serialize)]
pub struct CastStats {
    /// Agents cast.
    pub agents: usize,
    /// Part instances (agents x filled slots).
    pub part_instances: usize,
    /// Unique part meshes.
    pub unique_parts: usize,
    /// Unique materials.
    pub unique_materials: usize,
    /// Bytes of unique part geometry.
    pub unique_geometry_bytes: usize,
    /// Bytes if every agent had its own copy of its parts.
    pub copied_geometry_bytes: usize,
}

fn cast_rows(crowd: &ShotCrowd) -> Vec<CastRow> {
    crowd.casting.values().map(|c| cast_row(crowd, c)).collect()
}

/// One agent's row: its scheme, height, and part and material per slot.
fn cast_row(crowd: &ShotCrowd, c: &crate::casting::AgentCast) -> CastRow {
    let lib = crowd.library();
    let parts = c
        .slots
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let dressed = crowd.dressed.get(&c.id).and_then(|d| d.iter().find(|p| p.slot == i));
            PartRow {
                slot: s.slot.clone(),
                mesh: s.part.as_ref().map(|p| p.mesh.clone()),
                file: s.part.as_ref().map(|p| p.file.display().to_string()),
                material: dressed.map(|d| lib.materials[d.material as usize].name.clone()),
            }
        })
        .collect();
    CastRow { id: c.id, rig: c.rig.clone(), scheme: c.scheme.clone(), height_scale: c.height_scale, scaled: c.scaled, parts }
}

/// Instancing figures for the whole cast.
pub fn cast_stats(crowd: &ShotCrowd) -> CastStats {
    let lib = crowd.library();
    let mut meshes = std::collections::BTreeSet::new();
    let mut materials = std::collections::BTreeSet::new();
    let mut copied = 0;
    let mut instances = 0;
    for parts in crowd.dressed.values() {
        for p in parts {
            meshes.insert(p.mesh);
            materials.insert(p.material);
            copied += lib.meshes[p.mesh as usize].bytes();
            instances += 1;
        }
    }
    CastStats {
        agents: crowd.casting.len(),
        part_instances: instances,
        unique_parts: meshes.len(),
        unique_materials: materials.len(),
        unique_geometry_bytes: meshes.iter().map(|&m| lib.meshes[m as usize].bytes()).sum(),
        copied_geometry_bytes: copied,
    }
}

/// `throng cast`.
pub fn cmd_cast(args: &CastArgs) -> Result<()> {
    let crowd = ShotCrowd::load(&args.shot)?;
    let rows = cast_rows(&crowd);
    if args.json {
        #[derive(Serialize)]
        struct Out<'a> {
            version: u32,
            shot: &'a str,
            seed: u64,
            agents: &'a [CastRow],
            #[serde(skip_serializing_if = "Option::is_none")]
            stats: Option<CastStats>,
        }
        let out = Out {
            version: 1,
            shot: &crowd.shot.name,
            seed: crowd.shot.seed,
            agents: &rows,
            stats: args.stats.then(|| cast_stats(&crowd)),
        };
        println!("{}", serde_json::to_string_pretty(&out).map_err(|e| Error::Usage(e.to_string()))?);
        return Ok(());
    }
    if args.stats {
        print!("{}", format_stats(&cast_stats(&crowd)));
        return Ok(());
    }
    println!("{:>6}  {:<12} {:<20} {:>6}  {:<16} {}", "id", "rig", "scheme", "height", "head", "parts");
    for r in &rows {
        let head = crowd.casting[&r.id]
            .slots
            .iter()
            .find(|s| s.part.as_ref().is_some_and(|p| p.uniform))
            .and_then(|s| s.part.as_ref())
            .map_or("-", |p| p.mesh.as_str());
        let filled = r.parts.iter().filter(|p| p.mesh.is_some()).count();
        println!(
            "{:>6}  {:<12} {:<20} {:>6.3}  {:<16} {}/{}",
            r.id,
            r.rig,
            r.scheme,
            r.height_scale,
            head,
            filled,
            r.parts.len()
        );
    }
    Ok(())
}

fn mib(b: usize) -> String {
    format!("{:.2} MiB", b as f64 / (1024.0 * 1024.0))
}

/// Human-readable instancing figures.
pub fn format_stats(s: &CastStats) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "agents               {}", s.agents);
    let _ = writeln!(o, "part instances       {}", s.part_instances);
    let _ = writeln!(o, "unique parts         {}", s.unique_parts);
    let _ = writeln!(o, "unique materials     {}", s.unique_materials);
    let _ = writeln!(o, "unique geometry      {}", mib(s.unique_geometry_bytes));
    let _ = writeln!(
        o,
        "if copied per agent  {}  ({:.0}x more)",
        mib(s.copied_geometry_bytes),
        s.copied_geometry_bytes as f64 / s.unique_geometry_bytes.max(1) as f64
    );
    o
}

/// Everything botinfo says about one agent.
#[derive(Debug, Serialize)]
pub struct BotInfo {
    /// Cache id ("Robot ID").
    pub id: u32,
    /// Rig.
    pub rig: String,
    /// Cycle at the frame.
    pub cycle: String,
    /// Cycle frame at the frame.
    pub cycle_frame: f32,
    /// Shot frame asked about.
    pub shot_frame: i32,
    /// Wardrobe scheme.
    pub scheme: String,
    /// Height scale.
    pub height_scale: f32,
    /// Foot position.
    pub position: [f32; 3],
    /// Heading in degrees.
    pub heading_deg: f32,
    /// Distance from the camera to the agent, metres.
    pub distance: f32,
    /// Seated at this frame.
    pub seated: bool,
    /// Removed in the shot.
    pub removed: bool,
    /// Layer, once the shot has a layer manifest.
    pub layer: Option<String>,
    /// LOD, once the shot has a layer manifest.
    pub lod: Option<String>,
    /// Parts per slot.
    pub parts: Vec<PartRow>,
}

/// Ids closest to `id` among those that exist, for "did you mean".
pub fn nearest_ids(existing: impl Iterator<Item = u32>, id: u32, n: usize) -> Vec<u32> {
    let mut all: Vec<u32> = existing.collect();
    all.sort_by_key(|&e| ((e as i64 - id as i64).abs(), e));
    all.truncate(n);
    all
}

/// The botInfo block of agents at a frame.
pub fn bot_info(crowd: &ShotCrowd, ids: &[u32], frame: i32) -> Result<Vec<BotInfo>> {
    let block = crowd.agents_at(frame)?;
    let camera = crowd.camera(frame)?;
    let mut out = Vec::new();
    for &id in ids {
        let Some(cast) = crowd.casting.get(&id) else {
            let near = nearest_ids(crowd.casting.keys().copied(), id, 5);
            return Err(Error::Usage(format!(
                "agent {id} is not in shot {} (frames {}-{}); nearest ids: {}",
                crowd.shot.name,
                crowd.shot.frames.start,
                crowd.shot.frames.end,
                near.iter().map(u32::to_string).collect::<Vec<_>>().join(", ")
            )));
        };
        let rec: Option<&AgentRecord> = block.agents.iter().find(|a| a.id == id);
        let Some(a) = rec else {
            return Err(Error::Usage(format!(
                "agent {id} is in shot {} but not at frame {frame}; try another --frame",
                crowd.shot.name
            )));
        };
        let height = crowd.agent_height(id).unwrap_or(1.8);
        let (distance, _, _) =
            crate::layers::measure(&camera, crowd.shot.render.resolution[1], a.position, height);
        out.push(BotInfo {
            id,
            rig: cast.rig.clone(),
            cycle: crowd.cycle_name(a).to_string(),
            cycle_frame: a.cycle_frame,
            shot_frame: frame,
            scheme: cast.scheme.clone(),
            height_scale: cast.height_scale,
            position: a.position.to_array(),
            heading_deg: a.heading.to_degrees(),
            distance,
            seated: a.seated(),
            removed: crowd.shot.removed.contains(&id),
            layer: None,
            lod: None,
            parts: cast_row(crowd, cast).parts,
        });
    }
    Ok(out)
}

/// Fills in each agent's layer and LOD from a layer manifest.
pub fn add_layers(infos: &mut [BotInfo], manifest: &crate::layers::Manifest) {
    for b in infos {
        if let Some(a) = manifest.agent(b.id) {
            b.layer = manifest.layers.get(a.layer).map(|l| l.name.clone());
            b.lod = Some(format!("{:?}", a.lod_at(b.shot_frame)).to_lowercase());
        }
    }
}

/// The aligned, botInfo-style block.
pub fn format_bot_info(b: &BotInfo) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "Robot ID  {}", b.id);
    let _ = writeln!(o, "Rig       {}", b.rig);
    let _ = writeln!(o, "Cycle     {}", b.cycle);
    let _ = writeln!(o, "Frame     {:.2}  (cycle frame at shot frame {})", b.cycle_frame, b.shot_frame);
    let _ = writeln!(o, "Scheme    {}", b.scheme);
    let _ = writeln!(o, "Height    {:.3}{}", b.height_scale, if b.seated { "  (seated)" } else { "" });
    let _ = writeln!(o, "Position  {:.2} {:.2} {:.2}", b.position[0], b.position[1], b.position[2]);
    let _ = writeln!(o, "Heading   {:.1} deg", b.heading_deg);
    let _ = writeln!(o, "Distance  {:.2} m", b.distance);
    if let (Some(l), Some(lod)) = (&b.layer, &b.lod) {
        let _ = writeln!(o, "Layer     {l}  (LOD {lod}){}", if b.removed { "  REMOVED" } else { "" });
    } else if b.removed {
        let _ = writeln!(o, "Layer     -  REMOVED");
    }
    let _ = writeln!(o, "Parts");
    for p in &b.parts {
        let _ = writeln!(
            o,
            "  {:<12} {:<22} {}",
            p.slot,
            p.mesh.as_deref().unwrap_or("-"),
            p.material.as_deref().unwrap_or("-")
        );
    }
    o
}

/// Parses `X,Y` pixel coordinates.
pub fn parse_pixel(s: &str) -> Result<(u32, u32)> {
    let bad = || Error::Usage(format!("bad --pixel `{s}` (use X,Y, e.g. 480,270; 0,0 is the top-left pixel)"));
    let (x, y) = s.split_once(',').ok_or_else(bad)?;
    Ok((x.trim().parse().map_err(|_| bad())?, y.trim().parse().map_err(|_| bad())?))
}

/// Fills each block's layer and LOD from the shot's default layer manifest,
/// when there is one for this shot.
/// `throng botinfo`: by ids, or by `--exr FILE --pixel X,Y` (the agent at
/// that pixel of a rendered layer or comp, at the file's frame).
pub fn cmd_botinfo(args: &BotinfoArgs) -> Result<()> {
    if args.exr.is_some() && args.pixel.is_none() {
        return Err(Error::Usage("--exr needs --pixel X,Y".into()));
    }
    let picked = match (&args.exr, &args.pixel) {
        (Some(exr_path), Some(pixel)) => {
            if !args.ids.is_empty() {
                return Err(Error::Usage("give agent ids or --pixel, not both".into()));
            }
            let (x, y) = parse_pixel(pixel)?;
            let (film, meta) = crate::render::exr::read_layer(exr_path)?;
            let Some(shot) = &args.shot else {
                return Err(Error::Usage(format!(
                    "botinfo --exr needs the shot file too: {} is from shot `{}` (throng botinfo SHOT --exr FILE --pixel X,Y)",
                    exr_path.display(),
                    meta.shot
                )));
            };
            if x >= film.width || y >= film.height {
                return Err(Error::Usage(format!(
                    "pixel {x},{y} is outside {} ({}x{}; 0,0 is the top-left pixel)",
                    exr_path.display(),
                    film.width,
                    film.height
                )));
            }
            if args.frame.is_some_and(|f| f != meta.frame) {
                return Err(Error::Usage(format!(
                    "--frame {} disagrees with {}, which is frame {}",
                    args.frame.unwrap_or_default(),
                    exr_path.display(),
                    meta.frame
                )));
            }
            let id = film.agent_id[film.index(x, y)];
            if id == 0 {
                println!("no agent at pixel {x},{y} (set or sky) in {} frame {}", exr_path.display(), meta.frame);
                return Ok(());
            }
            Some((Path::new(shot).to_path_buf(), id - 1, meta, exr_path.clone()))
        }
        _ => None,
    };
    let Some(shot) = &args.shot else {
        return Err(Error::Usage("botinfo needs a shot file".into()));
    };
    if picked.is_none() && args.ids.is_empty() {
        return Err(Error::Usage("name at least one agent id (or --exr FILE --pixel X,Y)".into()));
    }
    let crowd = ShotCrowd::load(Path::new(shot))?;
    let (ids, frame) = match &picked {
        Some((_, id, meta, exr_path)) => {
            if meta.shot != crowd.shot.name {
                return Err(Error::invalid(
                    exr_path,
                    format!("EXR is from shot `{}` but {} is shot `{}`", meta.shot, Path::new(shot).display(), crowd.shot.name),
                )
                .field("throng/shot"));
            }
            (vec![*id], meta.frame)
        }
        None => (args.ids.clone(), args.frame.unwrap_or(crowd.shot.frames.start)),
    };
    if !crowd.shot.frames.contains(frame) {
        return Err(Error::Usage(format!(
            "frame {frame} is outside shot {} ({}-{})",
            crowd.shot.name, crowd.shot.frames.start, crowd.shot.frames.end
        )));
    }
    let mut infos = bot_info(&crowd, &ids, frame)?;
    let manifest_path = crate::layers::default_manifest_path(&crowd.shot.path, &crowd.shot.name);
    if manifest_path.exists() {
        let manifest = crate::layers::read_manifest(&manifest_path)?;
        if manifest.shot == crowd.shot.name {
            add_layers(&mut infos, &manifest);
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&infos).map_err(|e| Error::Usage(e.to_string()))?);
    } else {
        if let (Some((_, _, meta, exr_path)), Some(pixel)) = (&picked, &args.pixel) {
            println!("pixel {pixel} of {} (layer {}, frame {})", exr_path.display(), meta.layer, meta.frame);
        }
        let blocks: Vec<String> = infos.iter().map(format_bot_info).collect();
        print!("{}", blocks.join("\n"));
    }
    Ok(())
}

/// `throng export`.
pub fn cmd_export(args: &crate::cli::ExportArgs) -> Result<()> {
    let crowd = ShotCrowd::load(&args.shot)?;
    if !crowd.shot.frames.contains(args.frame) {
        return Err(Error::Usage(format!(
            "frame {} is outside shot {} ({}-{})",
            args.frame, crowd.shot.name, crowd.shot.frames.start, crowd.shot.frames.end
        )));
    }
    // --layer: only that crowd layer's agents, from the manifest beside the shot.
    let only = match &args.layer {
        None => None,
        Some(layer) => {
            let path = crate::layers::default_manifest_path(&crowd.shot.path, &crowd.shot.name);
            if !path.exists() {
                return Err(Error::Usage(format!(
                    "--layer needs the layer manifest {}: run `throng layers {}` first",
                    path.display(),
                    args.shot.display()
                )));
            }
            let m = crate::layers::read_manifest(&path)?;
            let index = m.layers.iter().position(|l| &l.name == layer).ok_or_else(|| {
                let names: Vec<&str> = m.layers.iter().map(|l| l.name.as_str()).collect();
                Error::Usage(format!("no crowd layer `{layer}` in {} (layers: {})", path.display(), names.join(", ")))
            })?;
            Some(m.agents.iter().filter(|a| a.layer == index && !a.removed).map(|a| a.id).collect())
        }
    };
    let s = crate::export::export_frame(&crowd, args.frame, only.as_ref(), &args.out)?;
    println!(
        "wrote {}: {} agents, {} mesh nodes sharing {} meshes, {} instanced triangles",
        args.out.display(),
        s.agents,
        s.mesh_nodes,
        s.meshes,
        s.instanced_triangles
    );
    Ok(())
}

/// World bounds of the set's instances, for the layer map.
pub fn set_bounds(crowd: &ShotCrowd) -> Option<(Vec3, Vec3)> {
    let lib = crowd.library();
    crowd
        .set
        .iter()
        .flat_map(|i| {
            let (lo, hi) = lib.meshes[i.mesh as usize].bounds();
            crate::scene::box_corners(lo, hi).map(|p| i.world_from_object.transform_point3(p))
        })
        .fold(None, |acc: Option<(Vec3, Vec3)>, p| Some(acc.map_or((p, p), |(lo, hi)| (lo.min(p), hi.max(p)))))
}

/// Builds the layer manifest of a cast shot with `args` over the shot's `[layers]`.
pub fn build_layers(crowd: &ShotCrowd, args: &crate::cli::LayersArgs) -> Result<crate::layers::Manifest> {
    use crate::layers;
    let (settings, options) = layers::settings_with_args(&crowd.shot.layers, args)?;
    let lib = crowd.library();
    // How many part instances share each mesh: shared geometry is split between its users.
    let mut users: std::collections::HashMap<u32, u64> = Default::default();
    for parts in crowd.dressed.values() {
        for p in parts {
            *users.entry(p.mesh).or_default() += 1;
        }
    }
    let all = crowd.shot_crowd()?;
    let cameras = match crowd.shot.keyed_camera(crowd.shot.frames.start as f32) {
        Some(_) => None,
        None => Some(crowd.shot.frames.iter().map(|f| crowd.camera(f)).collect::<Result<Vec<_>>>()?),
    };
    let input = layers::shot_input(&crowd.shot, &all, cameras, settings, options, |id| {
        // Every agent of the shot's frames was cast; others never reach here.
        let Some(height) = crowd.agent_height(id) else { return (1.8, 0, 0) };
        let parts = crowd.dressed.get(&id).map(Vec::as_slice).unwrap_or(&[]);
        let costs: Vec<layers::PartCost> = parts
            .iter()
            .map(|p| {
                let m = &lib.meshes[p.mesh as usize];
                layers::PartCost {
                    mesh_bytes: m.bytes() as u64,
                    triangles: m.triangle_count() as u64,
                    users: users.get(&p.mesh).copied().unwrap_or(1),
                }
            })
            .collect();
        let proxies = parts.iter().filter(|p| p.proxy).count();
        (
            height,
            layers::estimate_agent_memory(&costs),
            layers::estimate_proxy_memory(proxies),
        )
    })?;
    layers::build_manifest(&input)
}

/// `throng layers`.
pub fn cmd_layers(args: &crate::cli::LayersArgs) -> Result<()> {
    use crate::layers;
    let crowd = ShotCrowd::load(&args.shot)?;
    let manifest = build_layers(&crowd, args)?;
    let out = args.out.clone().unwrap_or_else(|| layers::default_manifest_path(&crowd.shot.path, &crowd.shot.name));
    layers::write_manifest(&out, &manifest)?;
    if let Some(map) = &args.map {
        layers::draw_map(&manifest, &layers::MapOptions { size: (1600, 900), set_bounds: set_bounds(&crowd) }, map)?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&manifest.summary_json()).map_err(|e| Error::Usage(e.to_string()))?);
    } else {
        print!("{}", layers::summary(&manifest));
        println!("manifest  {}", out.display());
        if let Some(map) = &args.map {
            println!("map       {}", map.display());
        }
    }
    Ok(())
}

/// Parses `WIDTHxHEIGHT`.
pub fn parse_resolution(s: &str) -> Result<[u32; 2]> {
    let bad = || Error::Usage(format!("bad resolution `{s}` (use e.g. 480x270)"));
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (w.trim().parse().map_err(|_| bad())?, h.trim().parse().map_err(|_| bad())?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(bad());
    }
    Ok([w, h])
}

/// `throng render`.
pub fn cmd_render(args: &crate::cli::RenderArgs) -> Result<()> {
    use crate::render::job::{self, RenderJob, FULL_LAYER};
    let crowd = ShotCrowd::load(&args.shot)?;
    let manifest_path = args
        .manifest
        .clone()
        .unwrap_or_else(|| crate::layers::default_manifest_path(&crowd.shot.path, &crowd.shot.name));
    let manifest = if manifest_path.exists() {
        Some(crate::layers::read_manifest(&manifest_path)?)
    } else if args.layer == FULL_LAYER {
        None
    } else {
        return Err(Error::Usage(format!(
            "no layer manifest at {}: run `throng layers {}` first (or render --layer full)",
            manifest_path.display(),
            args.shot.display()
        )));
    };
    if let Some(m) = &manifest {
        if m.shot != crowd.shot.name {
            return Err(Error::invalid(&manifest_path, format!("manifest is for shot `{}`, not `{}`", m.shot, crowd.shot.name)));
        }
    }
    let layers = match (args.layer.as_str(), &manifest) {
        ("all", Some(m)) => job::all_layers(m),
        (l, _) => vec![l.to_string()],
    };
    let frames = match &args.frames {
        Some(f) => crate::shot::parse_frame_list(f).map_err(Error::Usage)?,
        None => crowd.shot.frames.iter().collect(),
    };
    let job = RenderJob {
        layers,
        frames,
        spp: args.spp.unwrap_or(crowd.shot.render.spp).max(1),
        threads: args.threads.unwrap_or(0),
        out: args.out.clone(),
        resume: args.resume,
        png: args.png,
        resolution: args.resolution.as_deref().map(parse_resolution).transpose()?,
        cryptomatte: match args.cryptomatte.as_str() {
            "header" => job::CryptoOutput::Header,
            "sidecar" => job::CryptoOutput::Sidecar,
            "off" => job::CryptoOutput::Off,
            other => {
                return Err(Error::Usage(format!("--cryptomatte `{other}`: expected header, sidecar or off")))
            }
        },
    };
    let done = job::run(&crowd, manifest.as_ref(), &job)?;
    let rendered = done.iter().filter(|d| !d.skipped).count();
    let secs: f64 = done.iter().map(|d| d.seconds).sum();
    println!(
        "rendered {rendered} layer-frames ({} skipped as complete) in {secs:.1} s into {}",
        done.len() - rendered,
        args.out.display()
    );
    Ok(())
}

/// `throng demo`: every stage on the bundled demo shot.
pub fn cmd_demo(args: &crate::cli::DemoArgs) -> Result<()> {
    use crate::render::job::{self, RenderJob, FULL_LAYER};
    use std::time::Instant;
    let started = Instant::now();
    let shot_path = match &args.shot {
        Some(p) => p.clone(),
        None => {
            // From the repository, or wherever the binary was built from.
            let here = std::path::PathBuf::from("demo/shot.toml");
            if here.exists() { here } else { Path::new(env!("CARGO_MANIFEST_DIR")).join("demo/shot.toml") }
        }
    };
    let out = &args.out;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    println!("throng demo: {}", shot_path.display());

    let t = Instant::now();
    let crowd = ShotCrowd::load(&shot_path)?;
    let info = crate::cache::info(&crowd.cache)?;
    println!(
        "  cache    {} agents over cache frames {}-{}, {} rigs, {} cycles",
        info.agents,
        info.frame_first.unwrap_or(0),
        info.frame_last.unwrap_or(0),
        info.rigs.len(),
        info.cycles.len()
    );
    let stats = cast_stats(&crowd);
    println!(
        "  cast     {} agents, {} part instances of {} unique parts and {} materials ({} shared vs {} copied)  [{:.2} s]",
        stats.agents,
        stats.part_instances,
        stats.unique_parts,
        stats.unique_materials,
        mib(stats.unique_geometry_bytes),
        mib(stats.copied_geometry_bytes),
        t.elapsed().as_secs_f64()
    );

    let t = Instant::now();
    let layer_args = crate::cli::LayersArgs { per_frame: true, ..crate::cli::LayersArgs::for_shot(shot_path.clone()) };
    let manifest = build_layers(&crowd, &layer_args)?;
    let manifest_path = out.join(format!("{}.layers.json", crowd.shot.name));
    crate::layers::write_manifest(&manifest_path, &manifest)?;
    let map = out.join("layers_map.png");
    crate::layers::draw_map(&manifest, &crate::layers::MapOptions { size: (1600, 900), set_bounds: set_bounds(&crowd) }, &map)?;
    println!(
        "  layers   {} crowd layers + set, ranked at frame {}: 0 pops fixed (per-frame ranking would pop {} agents)  [{:.2} s]",
        manifest.layers.len(),
        manifest.ref_frame,
        manifest.pops.agents_changed,
        t.elapsed().as_secs_f64()
    );

    let t = Instant::now();
    let glb = out.join(format!("{}.{}.glb", crowd.shot.name, manifest.ref_frame));
    let s = crate::export::export_frame(&crowd, manifest.ref_frame, None, &glb)?;
    println!("  export   {} agents, {} mesh nodes sharing {} meshes  [{:.2} s]", s.agents, s.mesh_nodes, s.meshes, t.elapsed().as_secs_f64());

    let t = Instant::now();
    let f = crowd.shot.frames;
    let mut layers = job::all_layers(&manifest);
    layers.push(FULL_LAYER.to_string());
    let render = RenderJob {
        layers,
        frames: vec![f.start, manifest.ref_frame, f.end],
        spp: args.spp,
        threads: 0,
        out: out.join("render"),
        resume: false,
        png: true,
        resolution: None,
        cryptomatte: job::CryptoOutput::Header,
    };
    let done = job::run(&crowd, Some(&manifest), &render)?;
    let [w, h] = crowd.shot.render.resolution;
    println!(
        "  render   {} layer-frames at {w}x{h}, {} spp  [{:.1} s]",
        done.len(),
        render.spp,
        t.elapsed().as_secs_f64()
    );

    println!("done in {:.1} s. Wrote under {}:", started.elapsed().as_secs_f64(), out.display());
    let rows = [
        (manifest_path.display().to_string(), "the layer manifest (docs/layers.md)".to_string()),
        (map.display().to_string(), "the layer map: who is in which layer".to_string()),
        (glb.display().to_string(), format!("frame {} as glTF (open in Blender)", manifest.ref_frame)),
        (
            format!("{}/<layer>/{}.<layer>.<frame>.exr", render.out.display(), crowd.shot.name),
            "EXR layers (docs/render.md), PNG previews beside them".to_string(),
        ),
    ];
    let width = rows.iter().map(|(p, _)| p.len()).max().unwrap_or(0);
    for (path, what) in &rows {
        println!("  {path:<width$}  {what}");
    }
    println!("Look at the PNGs, or the EXRs with `exrheader FILE` (Debian: openexr) or any compositor.");
    if let Some(a) = manifest.agents.iter().find(|a| a.layer == 0 && !a.removed) {
        println!("Ask about an agent: throng botinfo {} {} --frame {}", shot_path.display(), a.id, manifest.ref_frame);
    }
    Ok(())
}
