#!/usr/bin/env python3
"""Imports a `throng export --format usd` stage into Blender (PyPI bpy 5.x,
CPython 3.13) with scene instancing and checks: the meshes are shared, not
copied (every agent part a collection instance of one of few collections);
the materials come through (the binding sits inside each prototype, where
Blender reads it), textured ones with their image; the camera shows the
shot's millimetres (USD camera lengths are tenths of a scene unit, which
Blender converts with metersPerUnit).

usage: blender_check.py STAGE.usda [FOCAL_MM SENSOR_MM]
"""
import sys

import bpy


def main(path, focal_mm=35.0, sensor_mm=36.0):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.wm.usd_import(filepath=path, support_scene_instancing=True) == {"FINISHED"}
    objs = bpy.data.objects
    inst = [o for o in objs if o.instance_type == "COLLECTION" and o.instance_collection]
    shared = {o.instance_collection.name for o in inst}
    meshes = len(bpy.data.meshes)
    cam = bpy.data.cameras[0]
    mats = [m for m in bpy.data.materials if m.users > 0]
    with_mat = [me for me in bpy.data.meshes if any(m is not None for m in me.materials)]
    images = [im for im in bpy.data.images if im.has_data or im.filepath]
    textured = [m for m in mats if m.node_tree and any(n.type == "TEX_IMAGE" and n.image for n in m.node_tree.nodes)]
    print(f"blender: {len(objs)} objects, {meshes} mesh datablocks ({len(with_mat)} with a material), "
          f"{len(inst)} collection instances of {len(shared)} collections; {len(mats)} materials "
          f"({len(textured)} textured, {len(images)} images); camera lens {cam.lens:.3f} mm, sensor {cam.sensor_width:.3f} mm")
    status = 0
    if not (meshes > 0 and len(inst) > meshes and len(shared) <= meshes and objs.get("agent_1") is not None):
        print("FAIL: Blender copied the meshes or lost the agents")
        status = 1
    if not mats or len(with_mat) < len(shared):
        print("FAIL: Blender sees no materials on the instanced meshes")
        status = 1
    if not textured:
        print("FAIL: no material imported with its base colour texture")
        status = 1
    if abs(cam.lens - focal_mm) > 1e-2 or abs(cam.sensor_width - sensor_mm) > 1e-2:
        print(f"FAIL: camera lens/sensor {cam.lens}/{cam.sensor_width} mm, not {focal_mm}/{sensor_mm}")
        status = 1
    if status == 0:
        print("blender: meshes shared, materials and textures bound, camera in millimetres")
    return status


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    sys.exit(main(args[0], *map(float, args[1:3])))
