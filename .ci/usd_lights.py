#!/usr/bin/env python3
"""The lights and the lens of a `throng export --format usd` stage, read with
Pixar's USD (usd-core) and interpreted by the UsdLux and UsdGeomCamera specs
(docs/usd.md, "Lights"), compared with what the shot file says in throng's
render units (docs/lights.md):

- DistantLight (the sun, a glTF directional light): the irradiance at normal
  incidence the spec implies. Luminance L = intensity x 2^exposure x color,
  divided by sizeFactor = pi sin^2(theta_max) when normalize is on (theta_max
  half the angle; 1 at angle 0); a disc of radiance L and half angle
  theta_max gives L pi sin^2(theta_max) at normal incidence.
- SphereLight with treatAsPoint (point, spot): the radiant intensity, L /
  sizeFactor x pi r^2 with sizeFactor = 4 pi r^2 (normalize on), so L / 4,
  in the limit r -> 0; a spot's ShapingAPI cone angle and softness.
- RectLight, DiskLight, SphereLight: the radiance L / sizeFactor (1 with
  normalize off); width, height, radius.
- DomeLight: the radiance scale L, the texture and its orientation (the
  OpenEXR lat-long convention the DomeLight docs quote) against throng's
  lat-long formula at the shot's `rotate`.
- every light's world transform: position, and its -Z the way it faces.
- the camera's fStop (f-number) and focusDistance (metres) at its keys.

check_lights(stage, shot, shot_dir, check) and check_lens(stage, shot, check)
call check(ok, what) for each property and return a line saying what matched.
"""
import math
import os

from pxr import Ar, Gf, Usd, UsdGeom, UsdLux

KINDS = ["point", "spot", "rect", "disk", "sphere"]


def close(a, b, tol=1e-4):
    a, b = list(a), list(b)
    return len(a) == len(b) and all(abs(x - y) <= tol * max(1.0, abs(y)) for x, y in zip(a, b))


def scale3(v, s):
    return [x * s for x in v]


def luminance(prim):
    """UsdLux's L: intensity x 2^exposure x color (colour temperature off)."""
    api = UsdLux.LightAPI(prim)
    assert not api.GetEnableColorTemperatureAttr().Get(), f"{prim.GetPath()}: colour temperature is on"
    s = api.GetIntensityAttr().Get() * 2.0 ** api.GetExposureAttr().Get()
    return scale3(api.GetColorAttr().Get(), s)


def normalize(prim):
    return bool(UsdLux.LightAPI(prim).GetNormalizeAttr().Get())


def distant_irradiance(prim):
    """The irradiance at normal incidence of a DistantLight, by the spec."""
    angle = UsdLux.DistantLight(prim).GetAngleAttr().Get()
    theta = min(max(math.radians(angle) / 2.0, 0.0), math.pi)
    assert theta <= math.pi / 2, "a distant light wider than a hemisphere"
    disc = math.pi * math.sin(theta) ** 2 if theta > 0 else 1.0
    size = disc if normalize(prim) else 1.0
    return scale3(luminance(prim), disc / size)


def point_intensity(prim):
    """Radiant intensity of a treatAsPoint SphereLight: L / sizeFactor x pi r^2
    as r -> 0 (normalize on: L / 4; off: nothing)."""
    return scale3(luminance(prim), 0.25 if normalize(prim) else 0.0)


def area_radiance(prim, kind):
    """The radiance of a rect, disk or sphere light: L / sizeFactor, the
    world-space surface area when normalize is on."""
    if not normalize(prim):
        return luminance(prim)
    m = world(prim)
    sx, sy, sz = (m.TransformDir(Gf.Vec3d(*a)).GetLength() for a in [(1, 0, 0), (0, 1, 0), (0, 0, 1)])
    if kind == "rect":
        r = UsdLux.RectLight(prim)
        area = r.GetWidthAttr().Get() * r.GetHeightAttr().Get() * sx * sy
    elif kind == "disk":
        area = math.pi * UsdLux.DiskLight(prim).GetRadiusAttr().Get() ** 2 * sx * sy
    else:
        area = 4 * math.pi * UsdLux.SphereLight(prim).GetRadiusAttr().Get() ** 2 * sx * sy
    return scale3(luminance(prim), 1.0 / area)


def world(prim, frame=Usd.TimeCode.Default()):
    return UsdGeom.XformCache(frame).GetLocalToWorldTransform(prim)


def facing(m):
    return m.TransformDir(Gf.Vec3d(0, 0, -1)).GetNormalized()


def unit(v):
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def shot_locals(shot):
    """(kind, index, entry, name, emission) for every [[lights.<kind>]]."""
    lights = shot.get("lights", {})
    out = []
    for kind in KINDS:
        for i, e in enumerate(lights.get(kind, [])):
            gain = e["intensity"] * 2.0 ** e.get("exposure", 0.0)
            out.append((kind, i, e, e.get("name", f"lights.{kind}[{i}]"), scale3(e.get("color", [1, 1, 1]), gain)))
    return out


def placement(e):
    """(position, facing) the shot gives a light."""
    if "transform" in e:
        m = e["transform"]  # column by column
        return m[12:15], unit([-m[8], -m[9], -m[10]])
    p = e["position"]
    if "aim" in e:
        return p, unit([a - b for a, b in zip(e["aim"], p)])
    return p, unit(e.get("direction", [0.0, -1.0, 0.0]))


def throng_uv(d, rotate_deg):
    """throng's lat-long coordinates of a world direction (docs/lights.md)."""
    r = -math.radians(rotate_deg)
    x, y, z = d
    x, z = x * math.cos(r) + z * math.sin(r), -x * math.sin(r) + z * math.cos(r)
    u = (math.pi - math.atan2(-z, x)) / (2 * math.pi)
    return u % 1.0, math.acos(max(-1.0, min(1.0, y))) / math.pi


def usd_uv(prim, d):
    """The DomeLight's lat-long coordinates of a world direction, by the
    OpenEXR convention its docs quote: longitude 0 is +Z, pi/2 is +X;
    pixel x runs from longitude +pi to -pi, y from latitude +pi/2 down."""
    local = world(prim).GetInverse().TransformDir(Gf.Vec3d(*d)).GetNormalized()
    lon = math.atan2(local[0], local[2])
    lat = math.asin(max(-1.0, min(1.0, local[1])))
    return ((math.pi - lon) / (2 * math.pi)) % 1.0, (math.pi / 2 - lat) / math.pi


def asset_bytes(resolved):
    asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
    return bytes(asset.GetBuffer()) if asset else None


def check_lights(stage, shot, shot_dir, check):
    lights = shot.get("lights", {})
    prims = [p for p in stage.Traverse() if p.HasAPI(UsdLux.LightAPI)]
    by_name = {}
    for p in prims:
        name = p.GetAttribute("throng:name").Get() if p.HasAttribute("throng:name") else None
        if name is not None:
            by_name.setdefault(name, []).append(p)
    seen = 0

    sun = lights.get("sun")
    prim = stage.GetPrimAtPath("/World/Lights/sun")
    check(bool(prim) == (sun is not None), "a DistantLight /World/Lights/sun exactly when the shot has a sun")
    if sun and prim:
        seen += 1
        want = scale3(sun.get("color", [1, 1, 1]), sun.get("intensity", 1.0))
        got = distant_irradiance(prim)
        check(prim.IsA(UsdLux.DistantLight), "the sun is a DistantLight")
        check(close(got, want), f"sun: UsdLux implies irradiance {got}, the shot says {want} W/m^2")
        check(abs(UsdLux.DistantLight(prim).GetAngleAttr().Get() - sun.get("angular_diameter", 0.53)) < 1e-4,
              "sun angle is its angular diameter in degrees")
        check(close(facing(world(prim)), scale3(unit(sun["direction"]), -1.0)), "the sun shines from its direction")

    dome = lights.get("dome")
    if dome:
        prim = stage.GetPrimAtPath("/World/Lights/dome")
        check(bool(prim) and prim.IsA(UsdLux.DomeLight), "a DomeLight /World/Lights/dome")
        check(not stage.GetPrimAtPath("/World/Lights/sky"), "the dome replaces the uniform sky")
        if prim:
            seen += 1
            d = UsdLux.DomeLight(prim)
            want = scale3(dome.get("color", [1, 1, 1]), dome.get("intensity", 1.0) * 2.0 ** dome.get("exposure", 0.0))
            check(close(luminance(prim), want), f"dome radiance scale {luminance(prim)} == {want}")
            check(d.GetTextureFormatAttr().Get() == "latlong", "dome texture:format is latlong")
            f = d.GetTextureFileAttr().Get()
            check(f is not None and f.resolvedPath != "", f"dome texture {f} resolves from the stage")
            if f is not None and f.resolvedPath:
                data = asset_bytes(f.resolvedPath)
                source = open(os.path.join(shot_dir, dome["file"]), "rb").read()
                if data == source:
                    how = "the shot's map, byte for byte"
                else:
                    how = "an OpenEXR of it"
                    check(data is not None and data[:4] == b"\x76\x2f\x31\x01", f"dome map {f.resolvedPath} is the "
                          "shot's file or an OpenEXR")
            worst = 0.0
            for d3 in [(1, 0, 0), (0, 0, -1), (0, 0, 1), (-1, 0.3, 0.2), (0.3, 0.8, -0.5), (0.6, -0.4, 0.7)]:
                d3 = unit(d3)
                (a, b), (c, e) = throng_uv(d3, dome.get("rotate", 0.0)), usd_uv(prim, d3)
                worst = max(worst, min(abs(a - c), 1 - abs(a - c)), abs(b - e))
            check(worst < 1e-5, f"the DomeLight's lat-long (OpenEXR convention) is throng's at rotate "
                  f"{dome.get('rotate', 0.0)} (worst texel coordinate error {worst:.1e})")
            print(f"dome: radiance scale {luminance(prim)}, map {how}, orientation matches (error {worst:.1e})")
    else:
        prim = stage.GetPrimAtPath("/World/Lights/sky")
        check(bool(prim) and prim.IsA(UsdLux.DomeLight), "a DomeLight /World/Lights/sky")
        if prim:
            seen += 1
            sky = lights.get("sky", {})
            want = scale3(sky.get("color", [0.3, 0.38, 0.5]), sky.get("intensity", 1.0))
            check(close(luminance(prim), want), f"sky radiance {luminance(prim)} == {want}")

    for kind, i, e, name, emission in shot_locals(shot):
        found = by_name.get(name, [])
        twins = 2 if kind in ("rect", "disk") and e.get("two_sided", False) else 1
        check(len(found) == twins, f"lights.{kind}[{i}] ({name}): {twins} light prim(s), found {len(found)}")
        if not found:
            continue
        seen += len(found)
        position, towards = placement(e)
        faces = []
        for prim in found:
            m = world(prim)
            faces.append(facing(m))
            check(close(m.ExtractTranslation(), position), f"{name}: at {tuple(m.ExtractTranslation())}, not {position}")
            if kind in ("point", "spot"):
                s = UsdLux.SphereLight(prim)
                check(prim.IsA(UsdLux.SphereLight) and s.GetTreatAsPointAttr().Get() and s.GetRadiusAttr().Get() == 0,
                      f"{name}: a zero-radius SphereLight treated as a point")
                got = point_intensity(prim)
                check(close(got, emission), f"{name}: UsdLux implies radiant intensity {got}, the shot says {emission} W/sr")
                if kind == "spot":
                    sh = UsdLux.ShapingAPI(prim)
                    outer, inner = e["outer_angle"], e.get("inner_angle", 0.0)
                    check(prim.HasAPI(UsdLux.ShapingAPI), f"{name}: ShapingAPI applied")
                    check(abs(sh.GetShapingConeAngleAttr().Get() - outer) < 1e-4, f"{name}: cone angle {outer}")
                    check(abs(sh.GetShapingConeSoftnessAttr().Get() - (1 - inner / outer)) < 1e-5,
                          f"{name}: cone softness 1 - inner / outer")
            else:
                schema = {"rect": UsdLux.RectLight, "disk": UsdLux.DiskLight, "sphere": UsdLux.SphereLight}[kind]
                check(prim.IsA(schema), f"{name}: a {schema.__name__}")
                got = area_radiance(prim, kind)
                check(close(got, emission), f"{name}: UsdLux radiance {got}, the shot says {emission} W/(m^2 sr)")
                if kind == "rect":
                    r = UsdLux.RectLight(prim)
                    check(close([r.GetWidthAttr().Get(), r.GetHeightAttr().Get()], e["size"]), f"{name}: size")
                else:
                    check(abs(schema(prim).GetRadiusAttr().Get() - e["radius"]) < 1e-5, f"{name}: radius")
        if kind != "point" and kind != "sphere":
            check(close(faces[0], towards), f"{name}: faces {tuple(faces[0])}, not {towards}")
        if twins == 2:
            check(close(faces[1], scale3(towards, -1.0)), f"{name}: its back twin faces the other way")
    others = len(prims) - seen
    print(f"lights: {seen} light prims match the shot's sun, environment and {len(shot_locals(shot))} local "
          f"lights in UsdLux's units; {others} more (the set's glTF lights)")
    return seen


def check_lens(stage, shot, check):
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/shotcam"))
    keys = [k for k in shot["camera"].get("keys", [])
            if stage.GetStartTimeCode() <= k["frame"] <= stage.GetEndTimeCode()]
    lens = [k for k in keys if "f_stop" in k]
    if not lens:
        check(not cam.GetFStopAttr().HasAuthoredValue(), "no fStop without depth of field")
        return "camera: a pinhole (no fStop)"
    for k in lens:
        t = k["frame"]
        gf = cam.GetCamera(t)
        check(abs(cam.GetFStopAttr().Get(t) - k["f_stop"]) < 1e-5, f"fStop at key frame {t}")
        check(abs(gf.fStop - k["f_stop"]) < 1e-5, f"GfCamera f-stop at key frame {t}")
        # Scene units: metres on this stage.
        check(abs(cam.GetFocusDistanceAttr().Get(t) - k["focus_distance"]) < 1e-5, f"focusDistance at key frame {t}")
        check(abs(gf.focusDistance - k["focus_distance"]) < 1e-5, f"GfCamera focus distance at key frame {t}")
    return f"camera: fStop and focusDistance match {len(lens)} keys"
