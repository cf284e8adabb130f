#!/usr/bin/env python3
"""usd-core's UsdSkel evaluation of the crowds it writes today against the
committed tests/fixtures/usd/skel_expected.json that tests/usdskel.rs checks
throng's joints with: a newer usd-core that evaluated them otherwise would
make that test compare against a stale answer. Exit 1 naming the first
joint further apart than 1e-6 m.

usage: usdskel_check.py FRESH.json COMMITTED.json
"""
import json
import sys


def main(fresh, committed):
    a, b = (json.load(open(p)) for p in (fresh, committed))
    if sorted(a) != sorted(b):
        print(f"FAIL: files {sorted(a)} vs {sorted(b)}")
        return 1
    for file, agents in a.items():
        if sorted(agents) != sorted(b[file]):
            print(f"FAIL: {file}: agents {sorted(agents)} vs {sorted(b[file])}")
            return 1
        for prim, data in agents.items():
            for frame, joints in data["frames"].items():
                for j, (p, q) in enumerate(zip(joints, b[file][prim]["frames"][frame])):
                    if max(abs(x - y) for x, y in zip(p, q)) > 1e-6:
                        print(f"FAIL: {file} {prim} frame {frame} joint {j}: usd-core now {p}, committed {q}")
                        return 1
    print("usdskel: usd-core's joint world positions match skel_expected.json")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
