#!/usr/bin/env python3
"""Cycles reference for throng's atmosphere (docs/render.md, "Atmosphere").

Runs the peer harness's render_cycles.py (read from ../shared/peers, never
changed) with one addition made just before it renders: a box of homogeneous
haze whose top is at glTF height HEIGHT, 2 km wide and 200 m deep, with
Volume Scatter (colour ALBEDO, density DENSITY, anisotropy G) plus Volume
Absorption (colour ALBEDO, density DENSITY): scattering DENSITY x ALBEDO,
absorption DENSITY x (1 - ALBEDO), as throng's `[atmosphere]` (whose air
reaches down forever; 200 m of it below the ground is never seen). Volume
bounces = the render's bounces.

  /work/venv/peers/bin/python examples/cycles_haze.py --density 0.05 --albedo 0.9 \\
      --anisotropy 0.3 --height 6 -- SCENE.glb [render_cycles.py options]

throng's side: `cargo run --release --example peer_bench -- SCENE.glb
--atmosphere 0.05 0.9 0.3 6 ...`; compare with peers/compare_images.py.
"""
import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
PEERS = os.environ.get("PEERS", os.path.join(HERE, "..", "..", "shared", "peers"))
# Where render_cycles.py has set its bounce limits: the haze goes in after them.
MARKER = "    c.volume_bounces = 0\n"


def add_haze(bpy, scene, air):
    """The haze box (Blender is Z up: glTF height is Blender Z)."""
    half, depth = 1000.0, 200.0
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, air.height - 0.5 * depth))
    box = bpy.context.active_object
    box.name = "throng_haze"
    box.scale = (2.0 * half, 2.0 * half, depth)
    mat = bpy.data.materials.new("throng_haze")
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    scatter = nt.nodes.new("ShaderNodeVolumeScatter")
    scatter.inputs["Color"].default_value = (air.albedo, air.albedo, air.albedo, 1.0)
    scatter.inputs["Density"].default_value = air.density
    scatter.inputs["Anisotropy"].default_value = air.anisotropy
    absorb = nt.nodes.new("ShaderNodeVolumeAbsorption")
    absorb.inputs["Color"].default_value = (air.albedo, air.albedo, air.albedo, 1.0)
    absorb.inputs["Density"].default_value = air.density
    add = nt.nodes.new("ShaderNodeAddShader")
    nt.links.new(scatter.outputs[0], add.inputs[0])
    nt.links.new(absorb.outputs[0], add.inputs[1])
    nt.links.new(add.outputs[0], out.inputs["Volume"])
    try:
        mat.cycles.homogeneous_volume = True
    except AttributeError:
        pass  # newer Blender detects a constant density itself
    box.data.materials.append(mat)
    scene.cycles.volume_bounces = scene.cycles.max_bounces


def main():
    argv = sys.argv[1:]
    if "--" not in argv:
        raise SystemExit(__doc__)
    split = argv.index("--")
    ap = argparse.ArgumentParser()
    ap.add_argument("--density", type=float, required=True)
    ap.add_argument("--albedo", type=float, default=1.0)
    ap.add_argument("--anisotropy", type=float, default=0.0)
    ap.add_argument("--height", type=float, required=True)
    air = ap.parse_args(argv[:split])
    source = open(os.path.join(PEERS, "render_cycles.py")).read()
    if source.count(MARKER) != 1:
        raise SystemExit("render_cycles.py changed: no single line %r to add the haze after" % MARKER.strip())
    source = source.replace(MARKER, MARKER + "    _add_haze(bpy, scene)\n")
    module = {"__name__": "render_cycles", "__file__": os.path.join(PEERS, "render_cycles.py")}
    exec(compile(source, module["__file__"], "exec"), module)
    module["_add_haze"] = lambda bpy, scene: add_haze(bpy, scene, air)
    module["main"](argv[split + 1:])


if __name__ == "__main__":
    main()
