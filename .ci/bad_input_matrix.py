#!/usr/bin/env python3
"""Issue 15's closing bad-input matrix: every input kind (shot TOML, cache
CSV and .crowd, wardrobe TOML, manifest JSON, EXR, flags) given bad values.
Each case must exit 2 naming the file or flag, or exit 0 with a warning for
a documented rule; never panic (101), abort (134) or grow past the memory
limit. Usage: .ci/bad_input_matrix.py target/debug/throng"""
import json, os, resource, shutil, subprocess, sys, tempfile

BIN = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else "target/debug/throng")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMO = os.path.join(ROOT, "demo")
T = tempfile.mkdtemp()

def rows(frames=(1, 2, 3), extra=()):
    out = ["frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags"]
    for f in frames:
        out += [f"{f},1,-0.8,0,1.0,0,bipedThinA,IdleA,3,", f"{f},2,0.9,0,-1.0,0,bipedThinA,IdleA,3,"]
        out += [r for (ff, r) in extra if ff == f]
    return "\n".join(out) + "\n"

BASE = f'''version = 1
name = "bad"
seed = 5
wardrobes = ["{ROOT}/wardrobes/robots.toml"]
[frames]
start = 1001
end = 1003
fps = 24.0
[cache]
path = "c.csv"
frame_offset = -1000
[rigs.bipedThinA]
file = "{DEMO}/rigs/bipedThinA.glb"
schemes = {{ HighEnd = 1.0 }}
[set]
file = "{DEMO}/set/set.glb"
[camera]
[[camera.keys]]
frame = 1001
position = [0.0, 1.6, 9.0]
aim = [0.0, 0.9, 0.0]
focal_length = 35.0
[layers]
count = 2
[render]
resolution = [48, 27]
spp = 1
'''

WARD = f'''version = 1
name = "w"
[materials.red]
base_color = [0.6, 0.05, 0.04]
[schemes.Only]
[[schemes.Only.parts]]
file = "{DEMO}/parts/heads.glb"
mesh = "head_sphere"
slot = "head"
materials = ["red"]
'''

def case_dir(name, shot=BASE, csv=None, ward=None):
    d = os.path.join(T, name)
    os.makedirs(d)
    if ward is not None:
        open(os.path.join(d, "w.toml"), "w").write(ward)
        shot = shot.replace(f"{ROOT}/wardrobes/robots.toml", os.path.join(d, "w.toml")).replace("HighEnd = 1.0", "Only = 1.0")
    open(os.path.join(d, "shot.toml"), "w").write(shot)
    open(os.path.join(d, "c.csv"), "w").write(rows() if csv is None else csv)
    return d

def limit():
    resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))

CASES = []
def case(kind, name, args, shot=BASE, csv=None, ward=None, setup=None, expect="error"):
    CASES.append((kind, name, args, shot, csv, ward, setup, expect))

R = lambda a, b: BASE.replace(a, b)
# ---- shot TOML
case("shot", "version 2", ["cast", "{d}/shot.toml"], R("version = 1", "version = 2"))
case("shot", "no version", ["cast", "{d}/shot.toml"], R("version = 1\n", ""))
case("shot", "end before start", ["cast", "{d}/shot.toml"], R("end = 1003", "end = 900"))
case("shot", "fps 0", ["cast", "{d}/shot.toml"], R("fps = 24.0", "fps = 0.0"))
case("shot", "fps nan", ["cast", "{d}/shot.toml"], R("fps = 24.0", "fps = nan"))
case("shot", "resolution 100000x100000", ["render", "{d}/shot.toml", "--layer", "full", "--out", "{d}/o"], R("[48, 27]", "[100000, 100000]"))
case("shot", "resolution 0", ["cast", "{d}/shot.toml"], R("[48, 27]", "[0, 27]"))
case("shot", "resolution 16384x16384 (too many pixels)", ["cast", "{d}/shot.toml"], R("[48, 27]", "[16384, 16384]"))
case("shot", "spp 0", ["cast", "{d}/shot.toml"], R("spp = 1", "spp = 0"))
case("shot", "spp 10^7", ["cast", "{d}/shot.toml"], R("spp = 1", "spp = 10000000"))
case("shot", "4 billion frames", ["cast", "{d}/shot.toml"], R("start = 1001", "start = -2147483648").replace("end = 1003", "end = 2147483647"))
case("shot", "frame + frame_offset overflow", ["cast", "{d}/shot.toml"], R("frame_offset = -1000", "frame_offset = 2147483000"))
case("shot", "unknown key", ["cast", "{d}/shot.toml"], R("seed = 5", "seed = 5\nsede = 6"))
case("shot", "missing cache file", ["cast", "{d}/shot.toml"], R('path = "c.csv"', 'path = "nope.csv"'))
case("shot", "camera without keys", ["cast", "{d}/shot.toml"], BASE.split("[camera]")[0] + "[camera]\n[layers]\ncount = 2\n")
case("shot", "focal length 0", ["cast", "{d}/shot.toml"], R("focal_length = 35.0", "focal_length = 0.0"))
case("shot", "sensor width 0", ["cast", "{d}/shot.toml"], R("[camera]\n", "[camera]\nsensor_width = 0.0\n"))
case("shot", "zero sun direction", ["cast", "{d}/shot.toml"], BASE + "[lights.sun]\ndirection = [0.0, 0.0, 0.0]\n")
case("shot", "layer count 0", ["layers", "{d}/shot.toml", "--out", "{d}/m.json"], R("count = 2", "count = 0"))
case("shot", "decreasing cut-offs", ["cast", "{d}/shot.toml"], R("count = 2", 'split = "cutoffs"\ncutoffs = [9.0, 3.0]'))
case("shot", "budget in parsecs", ["cast", "{d}/shot.toml"], R("count = 2", 'split = "budget"\nbudget = "3 parsecs"'))
case("shot", "pin to layer 7 of 2", ["layers", "{d}/shot.toml", "--out", "{d}/m.json"], R("count = 2", "count = 2\npins = [{ agent = 1, layer = 7 }]"))
case("shot", "pin of an unknown agent", ["layers", "{d}/shot.toml", "--out", "{d}/m.json"], R("count = 2", "count = 2\npins = [{ agent = 99, layer = 0 }]"))
case("shot", "height_jitter 1.5", ["cast", "{d}/shot.toml"], R("schemes = { HighEnd = 1.0 }", "schemes = { HighEnd = 1.0 }\nheight_jitter = 1.5"))
case("shot", "negative scheme weight", ["cast", "{d}/shot.toml"], R("HighEnd = 1.0", "HighEnd = -1.0"))
case("shot", "outside_cache bogus", ["cast", "{d}/shot.toml"], R("fps = 24.0", 'fps = 24.0\noutside_cache = "maybe"'))
case("shot", "frames past the cache", ["cast", "{d}/shot.toml"], R("end = 1003", "end = 1006"))
case("shot", "frames past the cache, outside_cache = empty (rule)", ["cast", "{d}/shot.toml"], R("end = 1003", "end = 1006").replace("fps = 24.0", 'fps = 24.0\noutside_cache = "empty"'), expect="warning")
case("shot", "ref_frame outside the shot", ["layers", "{d}/shot.toml", "--out", "{d}/m.json"], R("count = 2", "count = 2\nref_frame = 5000"))
# ---- cache CSV / binary
case("cache", "agent id 4294967295", ["cast", "{d}/shot.toml"], csv=rows(extra=[(1, "1,4294967295,0,0,0,0,bipedThinA,IdleA,3,")]))
case("cache", "gap at frame 2", ["cast", "{d}/shot.toml"], csv=rows((1, 3)))
case("cache", "x is not a number", ["cast", "{d}/shot.toml"], csv=rows() + "3,9,abc,0,0,0,bipedThinA,IdleA,3,\n")
case("cache", "frames out of order", ["cast", "{d}/shot.toml"], csv=rows() + "1,9,0,0,0,0,bipedThinA,IdleA,3,\n")
case("cache", "rig the shot lacks", ["cast", "{d}/shot.toml"], csv=rows(extra=[(1, "1,9,0,0,0,0,ghost,IdleA,3,")]))
case("cache", "cycle the rig lacks", ["cast", "{d}/shot.toml"], csv=rows(extra=[(1, "1,9,0,0,0,0,bipedThinA,Moonwalk,3,")]))
case("cache", "empty CSV", ["cast", "{d}/shot.toml"], csv="")
case("cache", "NaN position", ["cast", "{d}/shot.toml"], csv=rows(extra=[(1, "1,9,nan,0,0,0,bipedThinA,IdleA,3,")]))
case("cache", "duplicate agent in a frame", ["cast", "{d}/shot.toml"], csv=rows(extra=[(1, "1,1,0,0,0,0,bipedThinA,IdleA,3,")]))
case("cache", "garbage .crowd", ["cache", "info", "{d}/g.crowd"], setup=lambda d: open(os.path.join(d, "g.crowd"), "wb").write(b"THRONG\0\0" + os.urandom(200)))
# ---- wardrobe TOML
case("wardrobe", "all-zero material weights", ["cast", "{d}/shot.toml"], ward=WARD.replace('materials = ["red"]', 'materials = ["red"]\nmaterial_weights = [0.0]'))
case("wardrobe", "part for a slot the rig lacks", ["cast", "{d}/shot.toml"], ward=WARD.replace('slot = "head"', 'slot = "tail"'))
case("wardrobe", "unknown material", ["cast", "{d}/shot.toml"], ward=WARD.replace('materials = ["red"]', 'materials = ["blue"]'))
case("wardrobe", "version 9", ["cast", "{d}/shot.toml"], ward=WARD.replace("version = 1", "version = 9"))
case("wardrobe", "missing part file", ["cast", "{d}/shot.toml"], ward=WARD.replace("heads.glb", "nope.glb"))
case("wardrobe", "negative part weight", ["cast", "{d}/shot.toml"], ward=WARD.replace('slot = "head"', 'slot = "head"\nweight = -2.0'))
# ---- flags
case("flags", "--spp 0", ["render", "{d}/shot.toml", "--layer", "full", "--spp", "0", "--out", "{d}/o"])
case("flags", "--threads 0", ["render", "{d}/shot.toml", "--layer", "full", "--threads", "0", "--out", "{d}/o"])
case("flags", "--resolution 0x5", ["render", "{d}/shot.toml", "--layer", "full", "--resolution", "0x5", "--out", "{d}/o"])
case("flags", "--resolution 20000x10", ["render", "{d}/shot.toml", "--layer", "full", "--resolution", "20000x10", "--out", "{d}/o"])
case("flags", "--frames 4 billion", ["render", "{d}/shot.toml", "--layer", "full", "--frames=-2147483648-2147483647", "--out", "{d}/o"])
case("flags", "--frames 10-5", ["render", "{d}/shot.toml", "--layer", "full", "--frames", "10-5", "--out", "{d}/o"])
case("flags", "--frames outside the shot", ["render", "{d}/shot.toml", "--layer", "full", "--frames", "5000", "--out", "{d}/o"])
case("flags", "--layer bogus", ["render", "{d}/shot.toml", "--layer", "bogus", "--out", "{d}/o"], setup=lambda d: run([BIN, "layers", f"{d}/shot.toml"]))
case("flags", "export into a missing folder", ["export", "{d}/shot.toml", "--frame", "1001", "--out", "{d}/no/x.glb"])
case("flags", "farm plan --cores 0", ["farm", "plan", "{d}/shot.toml", "--cores", "0", "--out", "{d}/farm"])
case("flags", "completions tcsh", ["completions", "tcsh"])
# ---- manifest JSON
def stale(d):
    run([BIN, "layers", f"{d}/shot.toml"])
    open(os.path.join(d, "c.csv"), "w").write(rows().replace("-0.8", "-0.5"))
case("manifest", "stale manifest (cache changed)", ["render", "{d}/shot.toml", "--frames", "1001", "--out", "{d}/o"], setup=stale)
case("manifest", "garbage JSON", ["render", "{d}/shot.toml", "--frames", "1001", "--out", "{d}/o"], setup=lambda d: open(os.path.join(d, "bad.layers.json"), "w").write("{nope"))
case("manifest", "version 9", ["render", "{d}/shot.toml", "--frames", "1001", "--out", "{d}/o"], setup=lambda d: open(os.path.join(d, "bad.layers.json"), "w").write('{"version": 9}'))
case("manifest", "no manifest for --layer all", ["render", "{d}/shot.toml", "--out", "{d}/o"])
# ---- EXR
case("exr", "botinfo on garbage EXR", ["botinfo", "{d}/shot.toml", "--exr", "{d}/g.exr", "--pixel", "1,1"], setup=lambda d: open(os.path.join(d, "g.exr"), "wb").write(b"\x76\x2f\x31\x01" + os.urandom(300)))
def truncated(d):
    run([BIN, "render", f"{d}/shot.toml", "--layer", "full", "--frames", "1001", "--progress", "off", "--out", f"{d}/o"])
    p = f"{d}/o/full/bad.full.1001.exr"
    b = open(p, "rb").read()
    open(p, "wb").write(b[: len(b) // 2])
case("exr", "botinfo on a truncated EXR", ["botinfo", "{d}/shot.toml", "--exr", "{d}/o/full/bad.full.1001.exr", "--pixel", "1,1"], setup=truncated)
case("exr", "comp of an empty folder", ["comp", "{d}", "--frame", "1001", "--out", "{d}/c.exr"])

def run(args):
    return subprocess.run(args, capture_output=True, text=True, timeout=120, preexec_fn=limit)

counts = {}
bad = 0
for kind, name, args, shot, csv, ward, setup, expect in CASES:
    d = case_dir(f"c{len(counts) + sum(counts.values())}_{kind}", shot, csv, ward)
    if setup:
        setup(d)
    p = run([BIN] + [a.replace("{d}", d) for a in args])
    err = p.stderr.strip().splitlines()
    if "panicked" in p.stderr or p.returncode not in (0, 2):
        outcome = f"FAIL (status {p.returncode})"
    elif p.returncode == 2:
        outcome = "error" if expect == "error" else "FAIL (error, expected a warning)"
    elif "warning" in p.stderr:
        outcome = "warning" if expect == "warning" else "FAIL (accepted with a warning)"
    else:
        outcome = "FAIL (silently accepted)"
    bad += outcome.startswith("FAIL")
    counts[outcome] = counts.get(outcome, 0) + 1
    print(f"{kind:9} {name:50} {outcome:10} {err[-1][:150] if err else ''}")
# closed stdout
p = subprocess.Popen([BIN, "botinfo", f"{DEMO}/shot.toml"] + [str(i % 12 + 1) for i in range(360)] + ["--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
p.stdout.close()
rc = p.wait()
e = p.stderr.read().decode()
ok = rc == 0 and "panicked" not in e
print(f"{'cli':9} {'botinfo --json | (closed)':50} {'exit 0' if ok else 'FAIL'}")
bad += not ok
print(f"\n{len(CASES) + 1} cases: {counts}, closed stdout {'ok' if ok else 'FAIL'}")
shutil.rmtree(T)
sys.exit(1 if bad else 0)
