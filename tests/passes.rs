//! Passes end to end (docs/render.md, "Passes"): the demo (an HDRI dome,
//! four sphere lamps, lit shop windows) rendered through the CLI with
//! `--passes all` and a shutter, every layer and `throng comp` of them: the
//! light-path passes and the light groups each add up to the beauty on every
//! pixel, in every layer and in the comp; `P` comes from the layer whose Z
//! wins; `render --json` gives each pass's bytes; botinfo reads an agent's
//! pixel from a file full of passes; bad pass names are refused.

mod common;

use std::path::Path;

use common::{run, tempdir};
use glam::Vec3;
use throng::render::exr;
use throng::render::Film;
use throng::scene::passes::LightPath;

const FRAME: i32 = 1024;

fn light_paths(film: &Film) -> Vec<&throng::render::film::Pass> {
    film.passes.iter().filter(|p| LightPath::ALL.iter().any(|l| l.name() == p.name)).collect()
}

fn light_groups(film: &Film) -> Vec<&throng::render::film::Pass> {
    film.passes.iter().filter(|p| p.name.starts_with("lg_")).collect()
}

/// Each family of `film`'s passes sums to its beauty on every pixel, within
/// `roundings` half roundings (docs/render.md, "In the comp"). A value
/// rounded to half once is off by at most u = 2^-11 of itself (and light is
/// never negative), so after one rounding (a layer file, or the comp stacked
/// in memory from the layers' half values: over is linear with the same
/// weights `1 - A` for every pass and the beauty) |sum - beauty| <=
/// u (sum + beauty); the comp's file rounds the stacked values once more,
/// adding u (sum + beauty) again. f32 arithmetic (the over, this sum) adds
/// 2^-18 of it at most; the absolute 1e-6 per rounding covers half denormals.
fn assert_adds_up(film: &Film, what: &str, roundings: f32) {
    let (paths, groups) = (light_paths(film), light_groups(film));
    // The demo is in clear air: `all` leaves out the air's pass (PassSet::in_air).
    let want = LightPath::ALL.iter().filter(|&&p| p != LightPath::Atmosphere).count();
    assert_eq!(paths.len(), want, "{what}: light-path passes");
    assert!(!film.passes.iter().any(|p| p.name.starts_with("atmosphere")), "{what}: no air passes in clear air");
    assert!(groups.len() >= 6, "{what}: light groups {}", groups.len());
    let mut lit = 0;
    let mut worst = 0.0f32;
    for i in 0..film.rgba.len() {
        let beauty = Vec3::from_slice(&film.rgba[i][..3]);
        lit += (beauty.max_element() > 0.0) as usize;
        for (family, passes) in [("light paths", &paths), ("light groups", &groups)] {
            let values: Vec<Vec3> = passes.iter().map(|p| Vec3::from(p.data[i])).collect();
            assert!(values.iter().all(|v| v.min_element() >= 0.0), "{what}: pixel {i}: negative light");
            let sum: Vec3 = values.iter().copied().sum();
            let tol = (sum + beauty) * (roundings * 2f32.powi(-11) + 2f32.powi(-18)) + Vec3::splat(roundings * 1e-6);
            let off = (sum - beauty).abs();
            worst = worst.max((off / tol).max_element());
            assert!(
                (off - tol).max_element() <= 0.0,
                "{what}: pixel {i}: {family} sum to {sum}, beauty {beauty} (tolerance {tol}: {roundings} half roundings)"
            );
        }
    }
    assert!(lit >= 20, "{what}: only {lit} lit pixels");
    eprintln!("{what}: worst |sum - beauty| is {worst:.2} of {roundings} half roundings' tolerance");
}

fn read(path: &Path) -> Film {
    exr::read_layer(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).0
}

#[test]
fn every_layer_and_the_comp_add_up_to_their_beauty_through_motion_blur() {
    let dir = tempdir().unwrap();
    let d = dir.path();
    let shot = common::demo_shot();
    let shot = shot.to_str().unwrap();
    let manifest = d.join("demo.layers.json");
    let m = manifest.to_str().unwrap();
    let out = d.join("r");
    let (code, _, err) = run(&["layers", shot, "--out", m]);
    assert_eq!(code, 0, "{err}");
    let frames = FRAME.to_string();
    let (code, json, err) = run(&[
        "render",
        shot,
        "--manifest",
        m,
        "--layer",
        "all",
        "--frames",
        &frames,
        "--spp",
        "2",
        "--resolution",
        "64x36",
        "--shutter",
        "-0.25,0.25",
        "--passes",
        "all",
        "--progress",
        "off",
        "--json",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let summary: serde_json::Value = serde_json::from_str(&json).unwrap();
    let layer_frames = summary["layer_frames"].as_array().unwrap();
    assert_eq!(layer_frames.len(), 4, "set and three crowd layers");
    let manifest_value = throng::layers::read_manifest(&manifest).unwrap();
    let mut films = Vec::new();
    for lf in layer_frames {
        let layer = lf["layer"].as_str().unwrap();
        let path = throng::output::layer_path(&out, "demo", layer, FRAME);
        let film = read(&path);
        assert!(!film.motion.is_empty(), "{layer}: rendered with a shutter");
        assert_adds_up(&film, layer, 1.0);
        // render --json: each pass with its channels' bytes before compression.
        let passes = lf["passes"].as_array().unwrap();
        let names: Vec<&str> = passes.iter().map(|p| p["name"].as_str().unwrap()).collect();
        let want: Vec<&str> = film.passes.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, want, "{layer}");
        for p in passes {
            let each = if p["name"] == "P" { 4 } else { 2 };
            assert_eq!(p["bytes"].as_u64(), Some(64 * 36 * 3 * each), "{layer}: {p}");
        }
        assert_eq!(lf["file_bytes"].as_u64(), Some(std::fs::metadata(&path).unwrap().len()));
        films.push((layer.to_string(), film));
    }
    // The demo's groups: the dome, each lamp, each emissive material, the sun.
    let groups: Vec<&str> = light_groups(&films[0].1).iter().map(|p| p.name.as_str()).collect();
    for g in ["lg_dome", "lg_lamp_1", "lg_lamp_4"] {
        assert!(groups.contains(&g), "{g} in {groups:?}");
    }
    // The set layer's crowd shadows: light taken from set surfaces only.
    let set = &films.iter().find(|(l, _)| *l == manifest_value.set.name).unwrap().1;
    let shadow = &set.passes.iter().find(|p| p.name == "shadow").unwrap().data;
    assert!(shadow.iter().any(|v| v[0] > 0.0), "the crowd shadows the set");
    for (layer, film) in films.iter().filter(|(l, _)| *l != manifest_value.set.name) {
        let s = &film.passes.iter().find(|p| p.name == "shadow").unwrap().data;
        assert!(s.iter().all(|v| *v == [0.0; 3]), "{layer}: a crowd layer shades no set surface");
    }

    // throng comp stacks every pass: still adds up, P from the front.
    let comp_path = d.join("comp.exr");
    let (code, _, err) = run(&[
        "comp",
        out.to_str().unwrap(),
        "--frame",
        &frames,
        "--manifest",
        m,
        "--out",
        comp_path.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains("warning"), "{err}");
    let comped = throng::comp::comp_frame(&out, FRAME, Some(&manifest_value)).unwrap();
    assert!(comped.warnings.is_empty(), "{:?}", comped.warnings);
    let want: Vec<&str> = films[0].1.passes.iter().map(|p| p.name.as_str()).collect();
    let got: Vec<&str> = comped.film.passes.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(got, want);
    assert_adds_up(&comped.film, "comp (stacked in memory)", 1.0);
    // The file rounds the comp's values to half once more: two roundings'
    // bound, on every pixel of the file.
    let file = read(&comp_path);
    assert_eq!(file.passes.len(), comped.film.passes.len());
    assert_adds_up(&file, "comp (the file)", 2.0);
    let p_of = |f: &Film| f.passes.iter().find(|p| p.name == "P").unwrap().data.clone();
    let comp_p = p_of(&comped.film);
    assert_eq!(p_of(&file), comp_p, "P is float in the file");
    let layer_p: Vec<_> = films.iter().map(|(_, f)| p_of(f)).collect();
    for (i, (&z, p)) in comped.film.z.iter().zip(&comp_p).enumerate() {
        let from = films.iter().rposition(|(_, f)| f.z[i].is_finite() && f.z[i] == z);
        let want = from.map_or([0.0; 3], |k| layer_p[k][i]);
        assert_eq!(*p, want, "pixel {i}: P from the layer whose Z won");
    }

    // botinfo by pixel on a crowd layer full of passes.
    let crowd0 = films.iter().find(|(l, _)| l == "crowd0").unwrap();
    let i = crowd0.1.agent_id.iter().position(|&id| id > 0).expect("an agent in crowd0");
    let pixel = format!("{},{}", i % 64, i / 64);
    let exr_path = throng::output::layer_path(&out, "demo", "crowd0", FRAME);
    let (code, info, err) = run(&["botinfo", shot, "--exr", exr_path.to_str().unwrap(), "--pixel", &pixel, "--json"]);
    assert_eq!(code, 0, "{err}");
    let id = crowd0.1.agent_id[i] - 1;
    assert!(info.contains(&format!("\"id\": {id}")), "agent {id} at {pixel}: {info}");
}

/// Renders an edited copy of the demo shot written beside it (so its
/// relative paths hold), removed afterwards: (exit code, stderr).
fn render_edited(text: &str, tag: &str, out: &Path) -> (i32, String) {
    let path = common::demo_shot().with_file_name(format!(".passes_{tag}_{}.toml", std::process::id()));
    std::fs::write(&path, text).unwrap();
    let (code, _, err) = run(&["render", path.to_str().unwrap(), "--layer", "full", "--out", out.to_str().unwrap()]);
    let _ = std::fs::remove_file(&path);
    (code, err)
}

#[test]
fn bad_pass_names_are_refused_naming_what_is_known() {
    let dir = tempdir().unwrap();
    let shot = common::demo_shot();
    let out = dir.path().join("r");
    let (code, _, err) = run(&[
        "render",
        shot.to_str().unwrap(),
        "--layer",
        "full",
        "--frames",
        "1024",
        "--passes",
        "diffuse_direct,glossy",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--passes") && err.contains("unknown pass `glossy`"), "{err}");
    for known in ["diffuse_direct", "specular_indirect", "environment", "light_groups", "shadow", "P", "all"] {
        assert!(err.contains(known), "{known} not listed: {err}");
    }
    assert!(!out.exists(), "nothing written");

    // In the shot: the key and the known names.
    let text = std::fs::read_to_string(&shot).unwrap().replace("[render]\n", "[render]\npasses = [\"beauty\"]\n");
    let (code, err) = render_edited(&text, "passes", &out);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("render.passes") && err.contains("unknown pass `beauty`"), "{err}");

    // A light group that cannot name EXR channels: the light is named.
    let text = std::fs::read_to_string(&shot).unwrap().replacen(
        "name = \"lamp_4\"\n",
        "name = \"lamp_4\"\nlight_group = \"street lamps\"\n",
        1,
    );
    let (code, err) = render_edited(&text, "group", &out);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("light_group") && err.contains("`street lamps`") && err.contains("lights.sphere"), "{err}");
}
