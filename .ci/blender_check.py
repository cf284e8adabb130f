#!/usr/bin/env python3
"""Imports a `throng export --format usd` stage into Blender (PyPI bpy 5.x,
CPython 3.13) with scene instancing and checks the meshes are shared, not
copied: one mesh datablock per prototype, every agent part a collection
instance of one of them.

usage: blender_check.py STAGE.usda
"""
import sys

import bpy


def main(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.wm.usd_import(filepath=path, support_scene_instancing=True) == {"FINISHED"}
    objs = bpy.data.objects
    inst = [o for o in objs if o.instance_type == "COLLECTION" and o.instance_collection]
    shared = {o.instance_collection.name for o in inst}
    meshes = len(bpy.data.meshes)
    cam = bpy.data.cameras[0]
    print(f"blender: {len(objs)} objects, {meshes} mesh datablocks, {len(inst)} collection instances "
          f"of {len(shared)} collections; camera lens/sensor {cam.lens / cam.sensor_width:.4f}")
    ok = meshes > 0 and len(inst) > meshes and len(shared) <= meshes
    ok = ok and bpy.data.objects.get("agent_1") is not None
    if not ok:
        print("FAIL: Blender copied the meshes or lost the agents")
        return 1
    print("blender: meshes shared, not copied")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[-1]))
