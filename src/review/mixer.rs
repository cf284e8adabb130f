//! The light mixer (docs/review.md, "The mixer"): a frame's light-group
//! passes regraded by gain x tint and summed, as the render of the shot
//! with those gains would give (docs/shot.md, "Light-group gains"), and
//! the regrade saved as a new shot file beside the shot.

use std::path::{Path, PathBuf};

use glam::{Mat3, Vec3};

use crate::render::colour::{self, Colourspace};
use crate::render::Film;
use crate::scene::light_gains::{LightGain, LightGains};

/// The prefix of a light group's pass (`lg_<group>`).
pub(crate) const GROUP_PREFIX: &str = "lg_";

/// Most entries a mix names (a render writes at most 64 groups).
const MAX_ENTRIES: usize = crate::scene::passes::MAX_LIGHT_GROUPS;

/// Parses a mix, `group:gain:r:g:b` entries joined by `,` (empty: none);
/// each gain and tint checked as the shot checks them.
pub(crate) fn parse(mix: &str) -> Result<LightGains, String> {
    let mut out = LightGains::new();
    for entry in mix.split(',').filter(|e| !e.is_empty()) {
        if out.len() == MAX_ENTRIES {
            return Err(format!("a mix names at most {MAX_ENTRIES} groups"));
        }
        let parts: Vec<&str> = entry.split(':').collect();
        let [name, gain, r, g, b] = parts[..] else {
            return Err(format!("mix entry `{entry}` is not group:gain:r:g:b"));
        };
        crate::scene::passes::check_group_name(name, "mix").map_err(|e| e.to_string())?;
        let num = |s: &str| s.trim().parse::<f32>().map_err(|_| format!("mix entry `{entry}`: `{s}` is not a number"));
        let gain = LightGain { gain: num(gain)?, tint: [num(r)?, num(g)?, num(b)?] };
        gain.check().map_err(|(k, m)| format!("mix entry `{entry}`: {k} {m}"))?;
        if out.insert(name.to_string(), gain).is_some() {
            return Err(format!("mix names group `{name}` twice"));
        }
    }
    Ok(out)
}

/// The matrix a group's pass takes in a film of working space `space`:
/// gain x C diag(tint) C^-1 (C: Rec.709 to `space`), as the render applies
/// the tint to the light's Rec.709 colour before converting it.
fn matrix(space: Colourspace, gain: &LightGain) -> Mat3 {
    let column = |e: Vec3| colour::input(space, Vec3::from(gain.tint) * colour::to_rec709(space, e)) * gain.gain;
    Mat3::from_cols(column(Vec3::X), column(Vec3::Y), column(Vec3::Z))
}

/// The light-group names of `film` (its `lg_*` passes, in file order).
pub(crate) fn groups(film: &Film) -> Vec<&str> {
    film.passes.iter().filter_map(|p| p.name.strip_prefix(GROUP_PREFIX)).collect()
}

/// The regraded light of `film` per pixel: the sum over its groups of each
/// group's matrix x its pass (groups the mix does not name: x 1). Err: the
/// film has no groups, or the mix names a group it lacks.
pub(crate) fn mix(film: &Film, space: Colourspace, gains: &LightGains) -> Result<Vec<[f32; 3]>, String> {
    let names = groups(film);
    if names.is_empty() {
        return Err(NO_GROUPS.into());
    }
    if let Some(g) = gains.keys().find(|g| !names.contains(&g.as_str())) {
        return Err(format!("no light group `{g}` in this image; it has {}", names.join(", ")));
    }
    let mut out = vec![Vec3::ZERO; film.width as usize * film.height as usize];
    for pass in film.passes.iter().filter(|p| p.name.starts_with(GROUP_PREFIX)) {
        let name = &pass.name[GROUP_PREFIX.len()..];
        let m = matrix(space, gains.get(name).unwrap_or(&LightGain::default()));
        if m == Mat3::ZERO {
            continue;
        }
        for (o, p) in out.iter_mut().zip(&pass.data) {
            *o += m * Vec3::from(*p);
        }
    }
    Ok(out.into_iter().map(|v| v.to_array()).collect())
}

/// What the page says when an image has no light groups to mix.
pub(crate) const NO_GROUPS: &str = "this image has no light-group passes to mix: render it with the \
     light_groups pass (docs/review.md, \"The mixer\")";

/// A file name the lighter gave for the saved shot: plain (no folder), not
/// hidden, `.toml` added when missing.
pub(crate) fn shot_file_name(name: &str) -> Result<String, String> {
    let name = name.trim();
    let ok = !name.is_empty()
        && name.len() <= 200
        && !name.starts_with('.')
        && name.chars().all(|c| c.is_alphanumeric() || matches!(c, '_' | '-' | '.' | ' '));
    if !ok {
        return Err(format!(
            "`{name}` is not a plain file name (letters, digits, `_`, `-`, `.`, space; no folder, not hidden): \
             the shot is saved beside the original"
        ));
    }
    Ok(if name.to_ascii_lowercase().ends_with(".toml") { name.to_string() } else { format!("{name}.toml") })
}

/// The shot's text with its `[lights.gains]` table replaced by `gains`
/// (those of the shot x those of the mix, so the saved shot renders what
/// the page showed of a render of this shot). Err where the shot spells
/// the table some other way than a `[lights.gains]` header.
pub(crate) fn with_gains(text: &str, shot: &LightGains, mix: &LightGains) -> Result<String, String> {
    let header = |l: &str| l.split('#').next().unwrap_or("").trim().replace(' ', "") == "[lights.gains]";
    let mut out = String::new();
    let mut skipping = false;
    for line in text.lines() {
        let t = line.trim_start();
        if header(line) {
            skipping = true;
            continue;
        }
        if skipping && t.starts_with('[') {
            skipping = false;
        }
        if skipping {
            continue;
        }
        if t.starts_with("[lights.gains.") || t.contains("gains =") || t.contains("gains.") {
            return Err("the shot spells its gains other than as a `[lights.gains]` table: edit it by hand".into());
        }
        out.push_str(line);
        out.push('\n');
    }
    let merged = merged(shot, mix);
    if !merged.is_empty() {
        out.push_str("\n[lights.gains]\n");
        for (name, g) in &merged {
            out.push_str(&format!(
                "{name} = {{ gain = {:?}, tint = [{:?}, {:?}, {:?}] }}\n",
                g.gain, g.tint[0], g.tint[1], g.tint[2]
            ));
        }
    }
    Ok(out)
}

/// The gains of a shot whose own are `shot` regraded by `mix` (each
/// group's gain and tint multiplied; groups left at 1 dropped).
pub(crate) fn merged(shot: &LightGains, mix: &LightGains) -> LightGains {
    let mut merged = shot.clone();
    for (name, g) in mix {
        let base = shot.get(name).copied().unwrap_or_default();
        let tint = [0, 1, 2].map(|i| base.tint[i] * g.tint[i]);
        merged.insert(name.clone(), LightGain { gain: base.gain * g.gain, tint });
    }
    merged.retain(|_, g| *g != LightGain::default());
    merged
}

/// Writes `text` as `dir/name`, never over a file that is there: written
/// whole under a temporary name, then linked to its name (which fails if
/// it exists), so no partial file ever has the final name.
pub(crate) fn write_new(dir: &Path, name: &str, text: &str) -> Result<PathBuf, (u16, String)> {
    let path = dir.join(name);
    if path.exists() {
        return Err((409, format!("{} exists: the mixer never writes over a file; name another", path.display())));
    }
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let io = |e: std::io::Error| (500, format!("cannot write {}: {e}", path.display()));
    std::fs::write(&tmp, text).map_err(io)?;
    let linked = std::fs::hard_link(&tmp, &path);
    let _ = std::fs::remove_file(&tmp);
    match linked {
        Ok(()) => Ok(path),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            Err((409, format!("{} exists: the mixer never writes over a file; name another", path.display())))
        }
        Err(e) => Err(io(e)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_checks_and_saves_a_mix() {
        let m = parse("lamp_1:1.5:1:0.9:0.8,dome:0:1:1:1").unwrap();
        assert_eq!(m["lamp_1"], LightGain { gain: 1.5, tint: [1.0, 0.9, 0.8] });
        for bad in
            ["lamp_1:1", "lamp_1:-1:1:1:1", "lamp_1:nan:1:1:1", "lamp 1:1:1:1:1", "a:1:1:1:1,a:2:1:1:1", "a:x:1:1:1"]
        {
            assert!(parse(bad).is_err(), "{bad}");
        }
        assert!(shot_file_name("../x").is_err() && shot_file_name("a/b").is_err() && shot_file_name(".x").is_err());
        assert_eq!(shot_file_name("warm look").unwrap(), "warm look.toml");
        // The shot's own gains times the mix's; a table already there is replaced.
        let shot = parse("dome:2:1:1:1").unwrap();
        let text = "version = 1\n[lights.gains]\ndome = { gain = 2.0 }\n[render]\nspp = 4\n";
        let out = with_gains(text, &shot, &m).unwrap();
        assert!(out.contains("[render]\nspp = 4\n"), "{out}");
        assert_eq!(out.matches("[lights.gains]").count(), 1, "{out}");
        assert!(
            out.contains("dome = { gain = 0.0,") && out.contains("lamp_1 = { gain = 1.5, tint = [1.0, 0.9, 0.8] }")
        );
        let saved: toml::Value = toml::from_str(&out).unwrap();
        assert_eq!(saved["render"]["spp"].as_integer(), Some(4));
        assert!(with_gains("[lights]\ngains = {}\n", &shot, &m).is_err());
    }

    #[test]
    fn a_grey_tint_is_a_gain_in_any_space_and_a_mix_sums_the_groups() {
        let g = LightGain { gain: 2.0, tint: [0.5; 3] };
        let m = matrix(Colourspace::Acescg, &g);
        assert!((m * Vec3::new(0.3, 0.2, 0.1) - Vec3::new(0.3, 0.2, 0.1)).abs().max_element() < 1e-5);
        let mut f = Film::new(1, 1);
        f.passes = vec![
            crate::render::film::Pass { name: "lg_a".into(), channels: ["R", "G", "B"], data: vec![[1.0, 2.0, 3.0]] },
            crate::render::film::Pass { name: "lg_b".into(), channels: ["R", "G", "B"], data: vec![[0.5, 0.5, 0.5]] },
        ];
        let out = mix(&f, Colourspace::Rec709, &parse("a:2:1:0.5:0").unwrap()).unwrap();
        assert_eq!(out, vec![[2.5, 2.5, 0.5]]);
        assert!(mix(&f, Colourspace::Rec709, &parse("c:1:1:1:1").unwrap()).is_err());
        assert!(mix(&Film::new(1, 1), Colourspace::Rec709, &LightGains::new()).unwrap_err().contains("light_groups"));
    }
}
