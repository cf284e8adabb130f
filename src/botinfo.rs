//! botInfo: everything known about one agent at a frame (rig, cycle, scheme,
//! parts, props, distance, layer), as the Robots lighters' botInfo tool printed it.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use crate::cache::AgentSample;
use crate::casting::table::{cast_row, PartRow, PropRow};
use crate::casting::ShotCrowd;
use crate::error::{Error, Result};
use crate::layers::Manifest;

/// Everything botinfo says about one agent.
#[derive(Debug, Serialize)]
pub struct BotInfo {
    /// Cache id ("Agent ID").
    pub id: u32,
    /// Rig.
    pub(crate) rig: String,
    /// The rig's kind: `slots` (rigid parts on nodes), `skinned` or `rigid`.
    pub(crate) kind: &'static str,
    /// Cycle at the frame.
    pub(crate) cycle: String,
    /// Cycle frame at the frame.
    pub(crate) cycle_frame: f32,
    /// Shot frame asked about.
    pub(crate) shot_frame: i32,
    /// Wardrobe scheme.
    pub(crate) scheme: String,
    /// Height scale.
    pub(crate) height_scale: f32,
    /// The body it plays, when its rig has proportions (docs/wardrobes.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) body: Option<BodyRow>,
    /// Foot position.
    pub(crate) position: [f32; 3],
    /// Heading in degrees.
    pub(crate) heading_deg: f32,
    /// Distance from the camera to the agent, metres.
    pub distance: f32,
    /// Seated at this frame.
    pub(crate) seated: bool,
    /// Removed in the shot.
    pub(crate) removed: bool,
    /// Layer, once the shot has a layer manifest.
    pub(crate) layer: Option<String>,
    /// LOD, once the shot has a layer manifest.
    pub(crate) lod: Option<String>,
    /// Parts per slot.
    pub(crate) parts: Vec<PartRow>,
    /// The props it carries, each with what it hangs on.
    pub(crate) props: Vec<PropRow>,
    /// The shared pose a skinned agent plays (`rig/cycle/<step>of<steps>`);
    /// absent for slot rigs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) pose: Option<String>,
    /// Where a UsdSkel crowd's agent comes from (docs/usd.md, "UsdSkel crowds").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) usd: Option<UsdSkelRow>,
}

/// A UsdSkel agent's prims and the time code it is read at.
#[derive(Debug, Clone, serde::Serialize)]
pub(crate) struct UsdSkelRow {
    /// The SkelRoot prim.
    pub(crate) prim: String,
    /// Its Skeleton prim.
    pub(crate) skeleton: String,
    /// The SkelAnimation bound to it (`None`: it holds the rest pose).
    pub(crate) animation: Option<String>,
    /// The stage time code of the shot frame.
    pub(crate) time_code: i32,
}

/// Each UsdSkel agent's prims by id, when the shot's cache is a UsdSkel
/// crowd: the agents the shot read with it, else read from the file.
fn usd_prims(crowd: &ShotCrowd) -> Result<std::collections::HashMap<u32, crate::cache::usdskel::SkelAgent>> {
    if let Some(agents) = crowd.usd_agents() {
        return Ok(agents.iter().map(|a| (a.id, a.clone())).collect());
    }
    let path = &crowd.shot().cache.path;
    if crate::cache::Format::of(path).ok() != Some(crate::cache::Format::Usd)
        || !crate::cache::usdskel::has_skel_roots(path)?
    {
        return Ok(Default::default());
    }
    Ok(crate::cache::usdskel::agent_prims(path)?.into_iter().map(|a| (a.id, a)).collect())
}

/// An agent's body: which of the rig's bodies, and its draws.
#[derive(Debug, Clone, serde::Serialize)]
pub(crate) struct BodyRow {
    /// Body index, 1 to `of` (0: as modelled, a seated or no-scale agent).
    pub(crate) index: u16,
    /// Bodies the rig draws.
    pub(crate) of: u16,
    /// Per joint group: (group, length factor, girth factor).
    pub(crate) groups: Vec<(String, f32, f32)>,
}

/// Ids closest to `id` among those that exist, for "did you mean".
pub(crate) fn nearest_ids(existing: impl Iterator<Item = u32>, id: u32, n: usize) -> Vec<u32> {
    let mut all: Vec<u32> = existing.collect();
    all.sort_by_key(|&e| ((e as i64 - id as i64).abs(), e));
    all.truncate(n);
    all
}

/// The botInfo block of agents at a frame.
pub fn bot_info(crowd: &ShotCrowd, ids: &[u32], frame: i32) -> Result<Vec<BotInfo>> {
    let (found, missing) = bot_info_each(crowd, ids, frame)?;
    match missing.into_iter().next() {
        Some(e) => Err(e),
        None => Ok(found),
    }
}

/// As [`bot_info`], for every id on its own: the agents found, in the
/// order asked, and for each id that is not there (not in the shot, or
/// not at `frame`) the error saying so.
pub fn bot_info_each(crowd: &ShotCrowd, ids: &[u32], frame: i32) -> Result<(Vec<BotInfo>, Vec<Error>)> {
    let block = crowd.agents_at(frame)?;
    let camera = crowd.camera(frame)?;
    let mut out = Vec::new();
    let mut missing = Vec::new();
    let usd = usd_prims(crowd)?;
    for &id in ids {
        let Some(cast) = crowd.cast(id) else {
            let near = nearest_ids(crowd.casting().ids(), id, 5);
            missing.push(Error::Usage(format!(
                "agent {id} is not in shot {} (frames {}-{}); nearest ids: {}",
                crowd.shot().name,
                crowd.shot().frames.start,
                crowd.shot().frames.end,
                near.iter().map(u32::to_string).collect::<Vec<_>>().join(", ")
            )));
            continue;
        };
        let rec: Option<&AgentSample> = block.agents.iter().find(|a| a.id == id);
        let Some(a) = rec else {
            missing.push(Error::setting(
                "frame",
                format!("agent {id} is in shot {} but not at frame {frame}; try another frame", crowd.shot().name),
            ));
            continue;
        };
        let row = cast_row(crowd, cast);
        let height = crowd.agent_height(id).unwrap_or(1.8);
        let (distance, _, _) = crate::layers::measure(&camera, crowd.shot().render.resolution[1], a.position, height);
        out.push(BotInfo {
            id,
            rig: cast.rig.to_string(),
            kind: match crowd.rigs().get(&cast.rig) {
                Some(crate::casting::ShotRig::Skinned(rig)) => rig.kind(),
                _ => "slots",
            },
            cycle: crowd.cycle_name(a).to_string(),
            cycle_frame: a.cycle_frame,
            shot_frame: frame,
            scheme: cast.scheme.to_string(),
            height_scale: cast.height_scale,
            body: crowd.rigs().skinned(&cast.rig).filter(|r| r.body_count() > 0).map(|r| BodyRow {
                index: cast.body,
                of: r.body_count(),
                groups: r.body(cast.body).map(|b| b.draws.clone()).unwrap_or_default(),
            }),
            position: a.position.to_array(),
            heading_deg: a.heading.to_degrees(),
            distance,
            seated: a.seated(),
            removed: crowd.shot().removed.contains(&id),
            layer: None,
            lod: None,
            parts: row.parts,
            props: row.props,
            pose: crowd.pose_key(a),
            usd: usd.get(&id).map(|u| UsdSkelRow {
                prim: u.prim.clone(),
                skeleton: u.skeleton.clone(),
                animation: u.animation.clone(),
                time_code: crowd.shot().cache.cache_frame(frame),
            }),
        });
    }
    Ok((out, missing))
}

/// The layer manifest botinfo reads for a shot when none is named:
/// `<shot dir>/<shot>.layers.json`, when it exists and is this shot's.
pub fn shot_manifest(crowd: &ShotCrowd) -> Result<Option<Manifest>> {
    let path = crate::layers::default_manifest_path(&crowd.shot().path, &crowd.shot().name);
    if !path.exists() {
        return Ok(None);
    }
    let manifest = crate::layers::read_manifest(&path)?;
    Ok((manifest.shot == crowd.shot().name).then_some(manifest))
}

/// What `throng botinfo` says of agents at a shot frame: [`bot_info`], with
/// each agent's layer and LOD from `manifest` when it is this shot's.
/// `throng review`'s botInfo panel is this same call.
pub fn bot_info_with_layers(
    crowd: &ShotCrowd,
    ids: &[u32],
    frame: i32,
    manifest: Option<&Manifest>,
) -> Result<Vec<BotInfo>> {
    let (found, missing) = bot_info_with_layers_each(crowd, ids, frame, manifest)?;
    match missing.into_iter().next() {
        Some(e) => Err(e),
        None => Ok(found),
    }
}

/// As [`bot_info_with_layers`], for every id on its own ([`bot_info_each`]).
pub fn bot_info_with_layers_each(
    crowd: &ShotCrowd,
    ids: &[u32],
    frame: i32,
    manifest: Option<&Manifest>,
) -> Result<(Vec<BotInfo>, Vec<Error>)> {
    let f = crowd.shot().frames;
    if !f.contains(frame) {
        return Err(Error::Usage(format!(
            "frame {frame} is outside shot {} ({}-{})",
            crowd.shot().name,
            f.start,
            f.end
        )));
    }
    let (mut infos, missing) = bot_info_each(crowd, ids, frame)?;
    if let Some(m) = manifest.filter(|m| m.shot == crowd.shot().name) {
        add_layers(&mut infos, m);
    }
    Ok((infos, missing))
}

/// The agent at pixel `(x, y)` of a rendered image's `agent.id` channel
/// (`width` x `height`, row-major, cache id + 1, 0 = none): `None` for the
/// set or sky. `what` names the image in the error for a pixel outside it.
pub fn agent_at_pixel(agent_id: &[u32], width: u32, height: u32, x: u32, y: u32, what: &Path) -> Result<Option<u32>> {
    if x >= width || y >= height {
        return Err(Error::Usage(format!(
            "pixel {x},{y} is outside {} ({width}x{height}; 0,0 is the top-left pixel)",
            what.display()
        )));
    }
    let i = y as usize * width as usize + x as usize;
    match agent_id.get(i) {
        Some(&id) => Ok(id.checked_sub(1)),
        None => Err(Error::invalid(what, "the agent.id channel is shorter than the image").field("agent.id")),
    }
}

/// Fills in each agent's layer and LOD from a layer manifest.
pub fn add_layers(infos: &mut [BotInfo], manifest: &Manifest) {
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
    let _ = writeln!(o, "Agent ID  {}", b.id);
    let _ = writeln!(o, "Rig       {}  ({})", b.rig, b.kind);
    let _ = writeln!(o, "Cycle     {}", b.cycle);
    let _ = writeln!(o, "Frame     {:.2}  (cycle frame at shot frame {})", b.cycle_frame, b.shot_frame);
    let _ = writeln!(o, "Scheme    {}", b.scheme);
    let _ = writeln!(o, "Height    {:.3}{}", b.height_scale, if b.seated { "  (seated)" } else { "" });
    if let Some(body) = &b.body {
        let groups: Vec<String> =
            body.groups.iter().map(|(g, l, w)| format!("{g} length {l:.3} girth {w:.3}")).collect();
        match body.index {
            0 => {
                let _ = writeln!(o, "Body      as modelled  (of {}: seated or no-scale)", body.of);
            }
            i => {
                let _ = writeln!(o, "Body      {i} of {}  {}", body.of, groups.join(", "));
            }
        }
    }
    let _ = writeln!(o, "Position  {:.2} {:.2} {:.2}", b.position[0], b.position[1], b.position[2]);
    let _ = writeln!(o, "Heading   {:.1} deg", b.heading_deg);
    let _ = writeln!(o, "Distance  {:.2} m", b.distance);
    if let (Some(l), Some(lod)) = (&b.layer, &b.lod) {
        let _ = writeln!(o, "Layer     {l}  (LOD {lod}){}", if b.removed { "  REMOVED" } else { "" });
    } else if b.removed {
        let _ = writeln!(o, "Layer     -  REMOVED");
    }
    if let Some(pose) = &b.pose {
        let _ = writeln!(o, "Pose      {pose}  (shared by every agent on it)");
    }
    if let Some(u) = &b.usd {
        let _ = writeln!(o, "USD prim  {}  (skeleton {})", u.prim, u.skeleton);
        let anim = u.animation.as_deref().unwrap_or("none: the rest pose");
        let _ = writeln!(o, "USD anim  {anim}  at time code {}", u.time_code);
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
    if !b.props.is_empty() {
        let _ = writeln!(o, "Props");
        for p in &b.props {
            let _ =
                writeln!(o, "  {:<12} {:<22} {:<22} {}", p.name, p.mesh, p.material.as_deref().unwrap_or("-"), p.on);
        }
    }
    o
}
