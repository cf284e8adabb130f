#!/usr/bin/env bash
# Seeds fuzz/corpus/<target>/ from the repository's own files and the shared
# test assets (docs/fuzzing.md). The corpora are not committed: run this once
# before fuzzing. Needs python3 and a built throng binary (`cargo build`;
# THRONG=path overrides where it is looked for). ASSETS defaults to
# ../shared/assets beside the repository, as the tests find it; missing
# assets are skipped with a note.
set -euo pipefail
cd "$(dirname "$0")/.."
THRONG=${THRONG:-${CARGO_TARGET_DIR:-target}/debug/throng}
ASSETS=${ASSETS:-../shared/assets}
if [ ! -x "$THRONG" ]; then
    echo "seed.sh: no throng binary at $THRONG (run cargo build, or set THRONG)" >&2
    exit 1
fi
[ -d "$ASSETS" ] || echo "seed.sh: no shared assets at $ASSETS; seeding from the repository only" >&2
C=fuzz/corpus
S=$(mktemp -d)
trap 'rm -rf "$S"' EXIT
for t in cache_reader csv_import shot_toml wardrobe_toml gltf_load layer_manifest exr_reader \
    usd_crowd jupedsim_sqlite sim_scene farm_plan rig_skin; do
    mkdir -p "$C/$t"
done
asset() { # copy an asset if present: asset SRC DEST
    if [ -f "$1" ]; then cp "$1" "$2"; else echo "seed.sh: skipped missing $1" >&2; fi
}
q() { "$THRONG" "$@" >/dev/null; }

# cache_reader: small .crowd files converted from the fixtures (the demo's
# cache is 465 KB, far past the fuzzer's input length).
printf 'frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n' >"$S/empty.csv"
printf 'frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n5,,,,,,,,,\n6,3,1.5,0,-2,0.25,r,c,1.5,seated|hidden\n' >"$S/gap.csv"
q cache convert tests/fixtures/stack_shot/stack.csv "$C/cache_reader/stack.crowd"
q cache convert "$S/empty.csv" "$C/cache_reader/empty.crowd"
q cache convert "$S/gap.csv" "$C/cache_reader/gap.crowd"
q cache convert tests/fixtures/tabular/eth_obsmat.txt "$C/cache_reader/eth.crowd" --preset eth
q cache convert tests/fixtures/jupedsim_small.sqlite "$S/jupedsim_small.crowd"
# The JuPedSim fixture as a .crowd, when it fits the fuzzer's 64 KiB inputs.
python3 - "$S/jupedsim_small.crowd" "$C/cache_reader/jupedsim_small.crowd" <<'EOF'
import sys
data = open(sys.argv[1], "rb").read()
if len(data) <= 65536:
    open(sys.argv[2], "wb").write(data)
EOF

# csv_import: throng CSV and the foreign tables.
cp tests/fixtures/stack_shot/stack.csv "$S/gap.csv" "$C/csv_import/"
cp tests/fixtures/tabular/eth_obsmat.txt tests/fixtures/tabular/petrack_cm.txt \
    tests/fixtures/tabular/foreign.csv tests/fixtures/tabular/foreign.csv.gz "$C/csv_import/"
q cache convert "$C/cache_reader/eth.crowd" "$C/csv_import/eth_as_throng.csv"

# shot_toml: the real shots, and every inline shot in the tests.
cp demo/shot.toml "$C/shot_toml/demo.toml"
cp tests/fixtures/stack_shot/shot.toml "$C/shot_toml/stack.toml"
python3 - "$C/shot_toml" tests/shot.rs tests/layers.rs tests/tabular.rs <<'EOF'
import re, sys, hashlib
out = sys.argv[1]
for src in sys.argv[2:]:
    try:
        text = open(src).read()
    except OSError:
        continue
    for body in re.findall(r'r#"(.*?)"#', text, re.S):
        if "version = 1" in body and "[frames]" in body:
            name = hashlib.sha1(body.encode()).hexdigest()[:12]
            open(f"{out}/inline-{name}.toml", "w").write(body)
EOF

# wardrobe_toml: the shipped wardrobes.
cp wardrobes/*.toml "$C/wardrobe_toml/"

# gltf_load: binary files as they are; JSON files minified, and those with
# an external buffer packed into a .glb (the fuzzer writes one file only).
cp tests/fixtures/KenneyAlien/alien.glb demo/set/set.glb demo/parts/torsos.glb \
    demo/parts/heads.glb demo/rigs/bipedThinA.glb "$C/gltf_load/"
python3 - "$C/gltf_load" tests/fixtures/rig_small.gltf tests/fixtures/set_small.gltf \
    tests/fixtures/InterpolationTest/InterpolationTest.gltf \
    "$ASSETS/gltf/SimpleSkin/SimpleSkin.gltf" "$ASSETS/gltf/SimpleSkin/SimpleSkin-multi-joint-set.gltf" \
    "$ASSETS/gltf/RiggedFigure/RiggedFigure.gltf" <<'EOF'
import json, os, struct, sys
out = sys.argv[1]
for src in sys.argv[2:]:
    if not os.path.exists(src):
        print(f"seed.sh: skipped missing {src}", file=sys.stderr)
        continue
    doc = json.load(open(src))
    name = os.path.splitext(os.path.basename(src))[0]
    bufs = doc.get("buffers", [])
    external = [b for b in bufs if "uri" in b and not b["uri"].startswith("data:")]
    if not external:
        open(f"{out}/{name}.gltf", "w").write(json.dumps(doc, separators=(",", ":")))
        continue
    if len(bufs) != 1:
        continue
    blob = open(os.path.join(os.path.dirname(src), bufs[0].pop("uri")), "rb").read()
    blob += b"\0" * (-len(blob) % 4)
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    glb = struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(js) + 8 + len(blob))
    glb += struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(blob), b"BIN\0") + blob
    open(f"{out}/{name}.glb", "wb").write(glb)
EOF

# layer_manifest and exr_reader: the stack shot (5 agents) laid out and
# rendered at 16x9, one sample, in each compression; the small goldens and
# the Cryptomatte fixtures.
q layers tests/fixtures/stack_shot/shot.toml --out "$S/stack.layers.json"
cp "$S/stack.layers.json" "$C/layer_manifest/stack.layers.json"
q layers tests/fixtures/stack_shot/shot.toml --per-frame --lod-per-frame --out "$C/layer_manifest/stack_per_frame.layers.json"
q layers tests/fixtures/stack_shot/shot.toml --count 2 --out "$C/layer_manifest/stack_count.layers.json"
q layers tests/fixtures/stack_shot/shot.toml --budget 40MB --out "$C/layer_manifest/stack_budget.layers.json"
for comp in zip none piz b44 zips; do
    q render tests/fixtures/stack_shot/shot.toml --manifest "$S/stack.layers.json" --layer all --frames 1001 \
        --resolution 16x9 --spp 1 --threads 1 --progress off --compression "$comp" --out "$S/render-$comp"
    for f in "$S/render-$comp"/*/*.exr; do
        cp "$f" "$C/exr_reader/$comp-$(basename "$f")"
    done
done
cp golden/figure.crowd0.1024.exr golden/figure.full.1024.exr "$C/exr_reader/"
cp tests/fixtures/cryptomatte/*.exr "$C/exr_reader/"

# usd_crowd: the USD fixtures (an exported shot is far past 64 KiB).
cp tests/fixtures/usd/*.usda "$C/usd_crowd/"

# jupedsim_sqlite: the small JuPedSim fixture (45 KB), and the same file
# vacuumed after dropping all but its first frames.
cp tests/fixtures/jupedsim_small.sqlite "$C/jupedsim_sqlite/"
python3 - tests/fixtures/jupedsim_small.sqlite "$C/jupedsim_sqlite/first_frames.sqlite" <<'EOF2'
import shutil, sqlite3, sys
shutil.copy(sys.argv[1], sys.argv[2])
db = sqlite3.connect(sys.argv[2])
try:
    db.execute("DELETE FROM trajectory_data WHERE frame > (SELECT MIN(frame) + 3 FROM trajectory_data)")
    db.commit()
    db.execute("VACUUM")
except sqlite3.Error as e:
    print(f"seed.sh: first_frames.sqlite left whole ({e})", file=sys.stderr)
db.close()
EOF2

# sim_scene: the demo scene, whole and cut to 4 frames without warmup (so
# the target steps it), and small scenes as tests/sim.rs builds them (its
# header and cycles above one body each: obstacles still and moving, walls,
# goals, weights, chase, spawn, cycle changes, seated agents, rig files).
cp demo/sim/demo.toml "$C/sim_scene/demo.toml"
python3 - "$C/sim_scene" demo/sim/demo.toml <<'EOF2'
import re, sys
out = sys.argv[1]
demo = open(sys.argv[2]).read()
demo = re.sub(r"(?m)^end = \d+", "end = 4", re.sub(r"(?m)^warmup = \d+", "warmup = 0", demo))
open(f"{out}/demo_short.toml", "w").write(demo)
cycles = """[cycles.WalkA]
length = 32
stride = 1.5
[cycles.WalkB]
length = 28
stride = 1.2
[cycles.IdleA]
length = 48
stride = 0
[cycles.SitA]
length = 48
stride = 0
"""
def walker(i, x, z, h=0.0, extra=""):
    return (f'[[agents]]\nid = {i}\nposition = [{x}, {z}]\nheading_deg = {h}\nrig = "bipedThinA"\n'
            f'cycle = "WalkA"\ncycle_frame = 0.0\n{extra}\n')
bodies = {
    "obstacle": '[[targets]]\nname = "t"\nposition = [0.0, 6.0]\nradius = 0.5\n' + walker(1, 0.0, 0.0)
        + "[[obstacles]]\ncenter = [-0.3, 2.5]\nradius = 0.5\n",
    "moving_obstacle": '[[targets]]\nname = "n"\nposition = [0.0, 8.0]\nradius = 0.5\n' + walker(1, 0.0, 0.0)
        + "[[obstacles]]\nradius = 0.6\npath = [{ frame = 1, center = [3.0, 3.0] }, { frame = 121, center = [-3.0, 3.0] }]\n",
    "head_on": '[[targets]]\nname = "n"\nposition = [0.0, 9.0]\nradius = 0.5\n[[targets]]\nname = "s"\nposition = [0.0, -3.0]\nradius = 0.5\n'
        + walker(1, 0.0, 0.0, 0.0, 'targets = ["n"]') + walker(2, 0.0, 6.0, 180.0, 'targets = ["s"]'),
    "chase": '[model]\nchase = true\n[[targets]]\nname = "far"\nposition = [0.0, 200.0]\n'
        + "".join(walker(k + 1, 0.01 if k % 2 == 0 else -0.01, k * 0.7) for k in range(6)),
    "walls": walker(1, 0.1, 0.0, 0.0, "weights = { walls = 0.0 }") + walker(2, 50.1, 0.0)
        + '[[walls]]\nfrom = [-2.0, 3.0]\nto = [2.0, 3.0]\n[[walls]]\nname = "w"\nfrom = [48.0, 3.0]\nto = [52.0, 3.0]\nradius = 0.25\n'
        + '[[walls]]\npoint = [0.0, -5.0]\nnormal = [0.0, 1.0]\n',
    "spawn_weights": '[[targets]]\nname = "a"\nposition = [0.0, 20.0]\n[[targets]]\nname = "b"\nposition = [0.0, -20.0]\n'
        + "[[obstacles]]\ncenter = [0.0, 0.0]\nradius = 1.0\n"
        + "[[spawn]]\ncount = 20\nfirst_id = 10\nmin = [-8.0, -8.0]\nmax = [8.0, 8.0]\nheading_jitter_deg = 180\n"
        + "rigs = { bipedThinA = 1 }\ncycles = { WalkA = 1 }\n"
        + '[[agents]]\nid = 1\nposition = [0.3, -1.6]\nrig = "bipedThinA"\ncycle = "WalkA"\n'
        + "weights = { targets = 4.0, obstacles = 0.0, walls = 0.0, agents = 0.0 }\n",
    "seated_next": walker(1, 0.0, 0.0) + '[[agents]]\nid = 2\nposition = [2.0, 0.0]\nrig = "bipedThinA"\ncycle = "SitA"\nseated = true\n',
}
head = "version = 1\nseed = 7\n[frames]\nstart = 1\nend = 24\n"
for name, body in bodies.items():
    c = cycles
    if name == "seated_next":
        c = c.replace("stride = 1.5\n", "stride = 1.5\nnext = { WalkA = 2, WalkB = 1, IdleA = 1 }\n", 1)
    open(f"{out}/{name}.toml", "w").write(head + c + body)
open(f"{out}/rigs.toml", "w").write(head + '[rigs]\nbipedThinA = "../rigs/bipedThinA.glb"\nbipedTallB = "../rigs/bipedTallB.glb"\n'
    + "[cycles.WalkA]\n[cycles.WalkB]\n"
    + "".join(f'[[agents]]\nid = {k + 1}\nposition = [{4.0 * k}, 0.0]\nrig = "{r}"\ncycle = "{c}"\ncycle_frame = 0.0\n'
              f"[[obstacles]]\ncenter = [{4.0 * k + 0.3}, 3.0]\nradius = 0.4\n"
              for k, (r, c) in enumerate([("bipedThinA", "WalkA"), ("bipedTallB", "WalkA"), ("bipedThinA", "WalkB"), ("bipedTallB", "WalkB")])))
EOF2

# farm_plan: plans of the stack shot (every layer, the set layer alone); their
# fingerprints name the repository's files, so they open.
q farm plan tests/fixtures/stack_shot/shot.toml --out "$S/farm-all"
cp "$S/farm-all/plan.json" "$C/farm_plan/stack.plan.json"
q farm plan tests/fixtures/stack_shot/shot.toml --layers set --out "$S/farm-set"
cp "$S/farm-set/plan.json" "$C/farm_plan/stack_set.plan.json"

# rig_skin: the slot rigs, and the skinned and rigged glTFs packed above.
cp demo/rigs/bipedThinA.glb demo/rigs/bipedTallB.glb "$C/rig_skin/"
for f in rig_small.gltf rig_small.glb SimpleSkin.gltf SimpleSkin-multi-joint-set.gltf RiggedFigure.glb \
    InterpolationTest.glb alien.glb; do
    [ -f "$C/gltf_load/$f" ] && cp "$C/gltf_load/$f" "$C/rig_skin/"
done

for t in "$C"/*/; do
    echo "$(basename "$t"): $(find "$t" -type f | wc -l) seeds, $(du -sk "$t" | cut -f1) KiB"
done
