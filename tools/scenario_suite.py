#!/usr/bin/env python3
"""Build the worlds of the independent generator's suite plan (tools/worldgen/suite.py: every
effect in two variants, both directions where it has a sign, × seeds, the pairs and the controls)
with `gedisim scenario`, so that the two generators are benchmarked on the same design.

Usage:
    python3 tools/scenario_suite.py --gedisim target/debug/gedisim --out DIR [--seeds 1,2] [--only TEXT]
Then: python3 tools/diagnosis_benchmark.py --gedisim ... DIR/*/
"""

import argparse
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "worldgen"))
import suite  # noqa: E402  (the plan only; worldgen itself is not called)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gedisim", default="gedisim")
    ap.add_argument("--out", required=True)
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--only", default=None)
    a = ap.parse_args()
    seeds = {int(x) for x in a.seeds.split(",")}
    os.makedirs(a.out, exist_ok=True)
    t_all, n = time.time(), 0
    for eff, lab, par, seed in suite.plan(False):
        name = f"{eff}-{lab}-s{seed}"
        if seed not in seeds or (a.only and a.only not in name):
            continue
        cmd = [a.gedisim, "scenario", "--effect", eff, "--seed", str(seed), "--out", os.path.join(a.out, name),
               "--force"]
        for k, v in par.items():
            cmd += ["--param", f"{k}={v}"]
        t0 = time.time()
        r = subprocess.run(cmd, capture_output=True, text=True)
        status = "ok" if r.returncode == 0 else "FAILED: " + (r.stderr.strip().splitlines() or [""])[-1]
        print(f"{name:45s} {time.time() - t0:5.1f} s {status}", flush=True)
        n += r.returncode == 0
    print(f"{n} worlds in {time.time() - t_all:.0f} s -> {a.out}")


if __name__ == "__main__":
    main()
