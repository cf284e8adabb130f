#!/usr/bin/env python3
"""Writes tests/fixtures/usd/pointinstancer_crowd.usda with Pixar's USD
(usd-core): what a crowd department hands throng. A PointInstancer of six
agents walking over frames 1-5 (ids, positions, orientations, protoIndices
time-sampled; per-instance primvars throng:rig and throng:cycle; a constant
throng:cycleFrame is left out so throng counts frames), plus one prototype.

usage: make_usd_crowd.py OUT.usda
"""
import math
import sys

from pxr import Gf, Sdf, Usd, UsdGeom, Vt


def main(out):
    stage = Usd.Stage.CreateNew(out)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(5)
    stage.SetTimeCodesPerSecond(24)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    pi = UsdGeom.PointInstancer.Define(stage, "/World/crowd")
    proto = UsdGeom.Cube.Define(stage, "/World/crowd/Prototypes/body")
    proto.CreateSizeAttr(0.5)
    pi.CreatePrototypesRel().SetTargets([proto.GetPath()])
    ids = [7, 11, 12, 40, 41, 99]
    rigs = ["bipedThinA", "bipedTallB", "bipedThinA", "bipedTallB", "bipedThinA", "bipedThinA"]
    cycles = ["WalkA", "WalkB", "WalkA", "IdleA", "WalkB", "WalkA"]
    for f in range(1, 6):
        pos, ori = [], []
        for i, _ in enumerate(ids):
            heading = 0.3 * i - 0.8
            step = 0.05 * (f - 1)
            pos.append(Gf.Vec3f(-3.0 + 1.2 * i + step * math.sin(heading), 0.0, -2.0 - 0.5 * i + step * math.cos(heading)))
            q = Gf.Rotation(Gf.Vec3d(0, 1, 0), math.degrees(heading)).GetQuat()
            ori.append(Gf.Quath(q.GetReal(), *q.GetImaginary()))
        pi.GetIdsAttr().Set(Vt.Int64Array(ids), f)
        pi.GetPositionsAttr().Set(Vt.Vec3fArray(pos), f)
        pi.GetOrientationsAttr().Set(Vt.QuathArray(ori), f)
        pi.GetProtoIndicesAttr().Set(Vt.IntArray([0] * len(ids)), f)
    pv = UsdGeom.PrimvarsAPI(pi)
    pv.CreatePrimvar("throng:rig", Sdf.ValueTypeNames.StringArray, UsdGeom.Tokens.vertex).Set(rigs)
    pv.CreatePrimvar("throng:cycle", Sdf.ValueTypeNames.StringArray, UsdGeom.Tokens.vertex).Set(cycles)
    stage.GetRootLayer().Save()


if __name__ == "__main__":
    main(sys.argv[1])
