"""Time per light-mixer change (docs/benchmarks.md, "Light mixer").

Against a running `throng review SHOT --renders DIR` whose frame 1024 has a
`full` layer rendered with light-group passes: 30 changes, each a mix the
server has not seen (no cache hit), their wall times, and the server's CPU
time per change read from /proc/PID/stat.

    python3 examples/mixer_timing.py http://127.0.0.1:PORT PID
"""
import json
import os
import random
import statistics
import sys
import time
import urllib.request

base, pid = sys.argv[1], sys.argv[2]
salt = random.random()  # a new mix each run, so no change hits the cache


def cpu():
    f = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")


layers = json.load(urllib.request.urlopen(base + "/api/layers?frame=1024"))
groups = [v[3:] for v in layers["layers"][0]["views"] if v.startswith("lg_")]
urllib.request.urlopen(base + "/api/mix.png?frame=1024&layer=full&mix=").read()  # decode once
c0 = cpu()
ts = []
for i in range(30):
    g = groups[i % len(groups)]
    mix = f"{g}:{1 + salt + 0.01 * (i + 1)}:1:1:1"
    t = time.perf_counter()
    body = urllib.request.urlopen(base + f"/api/mix.png?frame=1024&layer=full&mix={mix}").read()
    ts.append((time.perf_counter() - t) * 1000)
cpu_ms = (cpu() - c0) * 1000 / len(ts)
print(f"server CPU per change {cpu_ms:.1f} ms; {len(groups)} groups; per change ms: median {statistics.median(ts):.1f} min {min(ts):.1f} max {max(ts):.1f}; png {len(body)} bytes")
