#!/usr/bin/env python3
"""Reads a `throng export --format usd` stage with Pixar's USD (usd-core) and
compares it with throng itself: agent ids and transforms at several frames
against `throng botinfo --json`, the camera against the shot file, the stage
metadata, instancing (prototypes shared, not copied), material bindings
inside the prototypes (where Blender reads them), and base-colour textures
that resolve from the stage with st on their meshes.

Camera lengths are tenths of a scene unit (the UsdGeomCamera spec): at
metersPerUnit = 1, focalLength x 100 is millimetres (docs/usd.md).

Every light and the lens (fStop, focusDistance) are read by the UsdLux and
UsdGeomCamera specs and compared with the shot's values (.ci/usd_lights.py).

Every emissive material's UsdPreviewSurface emissiveColor (the radiance the
renderer emits: glTF emissiveFactor x emissive strength, a wardrobe's
emission) is compared with throng's own materials, read from a glTF
`throng export` of the first frame (emissiveFactor x
KHR_materials_emissive_strength).

usage: usd_check.py THRONG SHOT STAGE FRAME...
"""
import json
import math
import os
import re
import struct
import subprocess
import sys
import tempfile
import tomllib

from pxr import Gf, Usd, UsdGeom, UsdShade

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from usd_lights import check_lens, check_lights  # noqa: E402

failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAIL:", what)


def close(a, b, tol=1e-4):
    return all(abs(x - y) <= tol * max(1.0, abs(y)) for x, y in zip(a, b))


def usd_material_name(name):
    """The USD prim name throng gives a library material (docs/usd.md,
    "The stage"): `<file>#<name>` as `<file stem>_<name>`, made a USD identifier."""
    if "#" in name:
        file, mat = name.rsplit("#", 1)
        name = os.path.splitext(os.path.basename(file))[0] + "_" + mat
    name = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return "_" + name if not name or name[0].isdigit() else name


def glb_emission(throng, shot_path, frame):
    """Material name -> emitted radiance, from a glTF export of `frame`."""
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "frame.glb")
        subprocess.run([throng, "export", shot_path, "--frame", str(frame), "--out", out],
                       check=True, capture_output=True)
        data = open(out, "rb").read()
    (length,) = struct.unpack("<I", data[12:16])
    doc = json.loads(data[20:20 + length])
    found = {}
    for m in doc.get("materials", []):
        strength = m.get("extensions", {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
        found[m["name"]] = [c * strength for c in m.get("emissiveFactor", [0.0, 0.0, 0.0])]
    return found


def emissive_color(stage, material):
    """A Looks material's emitted radiance: UsdPreviewSurface emissiveColor,
    or the scale of the texture connected to it."""
    shader = UsdShade.Shader(stage.GetPrimAtPath(f"{material}/PreviewSurface"))
    if not shader:
        return None
    inp = shader.GetInput("emissiveColor")
    if not inp:
        return [0.0, 0.0, 0.0]
    if inp.HasConnectedSource():
        source = inp.GetConnectedSources()[0][0].source
        scale = UsdShade.Shader(source.GetPrim()).GetInput("scale").Get()
        return list(scale)[:3]
    return list(inp.Get())


def check_emission(throng, shot_path, stage, frame):
    want = glb_emission(throng, shot_path, frame)
    emissive = 0
    for name, radiance in sorted(want.items()):
        path = f"/World/Looks/{usd_material_name(name)}"
        got = emissive_color(stage, path)
        check(got is not None, f"material {name}: {path} exists")
        if got is None:
            continue
        check(close(got, radiance, 1e-5), f"{path}: emissiveColor {got}, throng emits {radiance} (material {name})")
        emissive += max(radiance) > 0
    return f"{len(want)} materials of frame {frame}, {emissive} emissive, emit in USD what throng renders"


def main(throng, shot_path, stage_path, frames):
    stage = Usd.Stage.Open(stage_path)
    check(UsdGeom.GetStageUpAxis(stage) == "Y", "upAxis is Y")
    check(UsdGeom.GetStageMetersPerUnit(stage) == 1.0, "metersPerUnit is 1")
    shot = tomllib.load(open(shot_path, "rb"))
    fps = shot["frames"]["fps"]
    check(stage.GetTimeCodesPerSecond() == fps, f"timeCodesPerSecond {stage.GetTimeCodesPerSecond()} == {fps}")

    crowd = stage.GetPrimAtPath("/World/Crowd")
    agents = [p for p in crowd.GetChildren() if p.GetName().startswith("agent_")]
    check(len(agents) > 0, "the stage holds agents")
    # Instancing: every part an instance of a shared prototype.
    instances = [p for p in Usd.PrimRange(crowd) if p.IsInstance()]
    protos = {p.GetPrototype().GetPath() for p in instances}
    print(f"{len(agents)} agents, {len(instances)} instanceable parts sharing {len(protos)} prototypes")
    check(len(instances) > len(protos) > 0, "parts share prototypes")
    # Materials: bound on the Mesh inside every prototype (an importer that
    # reads bindings only inside prototypes, as Blender does, sees them).
    textured = 0
    for proto in stage.GetPrototypes():
        meshes = [p for p in Usd.PrimRange(proto) if p.IsA(UsdGeom.Mesh)]
        check(len(meshes) > 0, f"prototype {proto.GetPath()} holds a mesh")
        for m in meshes:
            mat, _ = UsdShade.MaterialBindingAPI(m).ComputeBoundMaterial()
            check(bool(mat), f"{m.GetPath()} (prototype of {proto.GetInstances()[0].GetPath()}): material bound inside the prototype")
            if not mat:
                continue
            for sh in Usd.PrimRange(mat.GetPrim()):
                shader = UsdShade.Shader(sh)
                if not shader or shader.GetIdAttr().Get() != "UsdUVTexture":
                    continue
                textured += 1
                f = shader.GetInput("file").Get()
                check(f is not None and f.resolvedPath != "", f"{sh.GetPath()}: texture {f} resolves from the stage")
                st = UsdGeom.PrimvarsAPI(m).GetPrimvar("st")
                check(st and st.HasValue(), f"{m.GetPath()}: textured mesh has primvars:st")
    print(f"{len(stage.GetPrototypes())} prototypes, every mesh in them bound; {textured} textured prototype meshes")
    for p in agents:
        pv = UsdGeom.PrimvarsAPI(p)
        aid = pv.GetPrimvar("throng:agentId").Get()
        check(p.GetName() == f"agent_{aid}", f"{p.GetPath()}: primvar throng:agentId {aid} matches the prim name")
        check(pv.GetPrimvar("throng:name").Get() == p.GetName(), f"{p.GetPath()}: throng:name is the Cryptomatte name")
        for part in p.GetChildren():
            name = UsdGeom.PrimvarsAPI(part).GetPrimvar("throng:name").Get()
            check(name is not None and name.startswith(p.GetName() + "/"), f"{part.GetPath()}: part Cryptomatte name {name}")

    cache = UsdGeom.XformCache()
    for frame in frames:
        cache.SetTime(frame)
        shown = [p for p in agents if UsdGeom.Imageable(p).ComputeVisibility(frame) != "invisible"]
        ids = [UsdGeom.PrimvarsAPI(p).GetPrimvar("throng:agentId").Get() for p in shown]
        out = subprocess.run([throng, "botinfo", shot_path, *map(str, ids), "--frame", str(frame), "--json"],
                             check=True, capture_output=True, text=True).stdout
        infos = {b["id"]: b for b in json.loads(out)}
        check(set(infos) == set(ids), f"frame {frame}: botinfo knows the same {len(ids)} agents")
        worst = 0.0
        for p, aid in zip(shown, ids):
            b = infos[aid]
            m = cache.GetLocalToWorldTransform(p)
            t = m.ExtractTranslation()
            h = math.radians(b["heading_deg"])
            s = b["height_scale"]
            # Agent +Z (heading 0) turned by heading about +Y, scaled by the height scale.
            z = m.TransformDir(Gf.Vec3d(0, 0, 1))
            want_z = (s * math.sin(h), 0.0, s * math.cos(h))
            err = max(max(abs(a - b) for a, b in zip(t, b["position"])), max(abs(a - b) for a, b in zip(z, want_z)))
            worst = max(worst, err)
            check(err < 1e-3, f"frame {frame}: agent {aid} transform {tuple(t)} vs botinfo {b['position']} (err {err:.2e})")
            rig = UsdGeom.PrimvarsAPI(p).GetPrimvar("throng:rig").Get()
            cyc = UsdGeom.PrimvarsAPI(p).GetPrimvar("throng:cycle").Get(frame)
            check(rig == b["rig"] and cyc == b["cycle"], f"frame {frame}: agent {aid} rig/cycle {rig}/{cyc} vs {b['rig']}/{b['cycle']}")
        print(f"frame {frame}: {len(ids)} agents match botinfo (worst transform error {worst:.1e})")

    # The camera, as the shot defines it.
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/shotcam"))
    res = shot.get("render", {}).get("resolution", [1920, 1080])
    width = shot["camera"]["sensor_width"]
    # Tenths of a scene unit: at metersPerUnit 1, x 100 gives millimetres.
    mm = 0.1 / UsdGeom.GetStageMetersPerUnit(stage) * 1000.0
    check(abs(cam.GetHorizontalApertureAttr().Get() * mm - width) < 1e-3, "horizontal aperture is the sensor width")
    check(abs(cam.GetVerticalApertureAttr().Get() * mm - width * res[1] / res[0]) < 1e-3, "vertical aperture from the aspect")
    near, far = cam.GetClippingRangeAttr().Get()
    check(0 < near < far, f"clipping range {near}-{far}")
    keys = shot["camera"].get("keys", [])
    for k in keys:
        f = k["frame"]
        if not (stage.GetStartTimeCode() <= f <= stage.GetEndTimeCode()):
            continue
        cache.SetTime(f)
        m = cache.GetLocalToWorldTransform(cam.GetPrim())
        check(close(m.ExtractTranslation(), k["position"]), f"camera position at key frame {f}")
        fwd = m.TransformDir(Gf.Vec3d(0, 0, -1)).GetNormalized()
        aim = Gf.Vec3d(*k["aim"]) - Gf.Vec3d(*k["position"])
        check(close(fwd, aim.GetNormalized()), f"camera looks at the aim at key frame {f}")
        check(abs(cam.GetFocalLengthAttr().Get(f) * mm - k["focal_length"]) < 1e-3, f"focal length at key frame {f}")
    # GfCamera (usd-core's own reading) gives the same field of view as the shot.
    gf = cam.GetCamera(stage.GetStartTimeCode())
    fov = gf.GetFieldOfView(Gf.Camera.FOVHorizontal)
    want = math.degrees(2 * math.atan(width / (2 * cam.GetFocalLengthAttr().Get(stage.GetStartTimeCode()) * mm)))
    check(abs(fov - want) < 1e-3, f"GfCamera horizontal field of view {fov} == {want}")
    print(f"camera: aperture {cam.GetHorizontalApertureAttr().Get() * mm:.3f} x "
          f"{cam.GetVerticalApertureAttr().Get() * mm:.3f} mm, "
          f"focal {cam.GetFocalLengthAttr().Get(stage.GetStartTimeCode()) * mm:.3f} mm "
          f"(tenths of a metre: {cam.GetFocalLengthAttr().Get(stage.GetStartTimeCode())}), "
          f"field of view {fov:.3f} deg, clipping {near}-{far}")
    print(check_emission(throng, shot_path, stage, frames[0]))
    check_lights(stage, shot, os.path.dirname(os.path.abspath(shot_path)), check)
    print(check_lens(stage, shot, check))
    if failures:
        print(f"{len(failures)} failures")
        return 1
    print("usd-core reads back the same agents, transforms, camera and lights as throng")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2], sys.argv[3], [int(f) for f in sys.argv[4:]]))
