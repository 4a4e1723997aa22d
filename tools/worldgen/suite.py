#!/usr/bin/env python3
"""Build a benchmark suite of worldgen worlds into a folder.

Full suite: every effect x 2 variants (both directions / two magnitudes) x 2 seeds, 4 pairs x 2 seeds
and 4 controls.  --small: 3 worlds (one control, one weighting world, one pulse world) for CI.

    python3 tools/worldgen/suite.py --out /tmp/suite [--small] [--tiles DIR] [--jobs 1]

Each world goes to <out>/<effect>-<dir>-s<seed>/ and <out>/suite.json lists them all.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import worldgen  # noqa: E402

SEEDS = (1, 2)

# (effect, direction label, params) -- two variants per effect, both directions where the effect
# has a sign, two magnitudes otherwise.
VARIANTS = [
    ("geolocation", "shot", {"level": "shot", "shot_sigma_m": 3.0}),
    ("geolocation", "beam", {"level": "beam", "shot_sigma_m": 3.0}),
    ("datum", "up", {"dz_m": 0.5}),
    ("datum", "down", {"dz_m": -0.5}),
    ("weighting", "low", {"rho_ground_over_veg": 0.6}),
    ("weighting", "high", {"rho_ground_over_veg": 1.6}),
    ("pulse", "small", {"pulse_sigma_m": 0.6}),
    ("pulse", "large", {"pulse_sigma_m": 1.2}),
    ("footprint", "narrow", {"fsigma_m": 4.0}),
    ("footprint", "wide", {"fsigma_m": 7.5}),
    ("noise", "low", {"noise_sigma_factor": 0.6}),
    ("noise", "high", {"noise_sigma_factor": 2.0}),
    ("canopy_change", "loss", {"height_m": 10.0, "fraction": 0.3}),
    ("canopy_change", "gain", {"height_m": 10.0, "fraction": -0.3}),
    ("occlusion", "more", {"height_m": 5.0, "gain": 0.5}),
    ("occlusion", "less", {"height_m": 5.0, "gain": -0.4}),
    ("ground_detection", "up", {"algorithm": "all", "offset_m": 0.5}),
    ("ground_detection", "down", {"algorithm": "1", "offset_m": -0.4}),
]

PAIRS = [
    ("datum+pulse", "up-large", {"datum.dz_m": 0.5, "pulse.pulse_sigma_m": 1.2}),
    ("canopy_change+noise", "loss-high", {"canopy_change.height_m": 10.0, "canopy_change.fraction": 0.3,
                                          "noise.noise_sigma_factor": 2.0}),
    ("weighting+footprint", "high-wide", {"weighting.rho_ground_over_veg": 1.6, "footprint.fsigma_m": 7.5}),
    ("geolocation+ground_detection", "beam-down", {"geolocation.level": "beam",
                                                   "geolocation.shot_sigma_m": 3.0,
                                                   "ground_detection.algorithm": "all",
                                                   "ground_detection.offset_m": -0.4}),
]

CONTROL_SEEDS = (1, 2, 3, 4)


def plan(small):
    worlds = []
    if small:
        return [("none", "ctl", {}, 1), ("weighting", "high", {"rho_ground_over_veg": 1.6}, 1),
                ("pulse", "large", {"pulse_sigma_m": 1.2}, 1)]
    for s in CONTROL_SEEDS:
        worlds.append(("none", "ctl", {}, s))
    for s in SEEDS:
        for eff, lab, par in VARIANTS:
            worlds.append((eff, lab, par, s))
        for eff, lab, par in PAIRS:
            worlds.append((eff, lab, par, s))
    return worlds


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--small", action="store_true", help="3 worlds only (CI)")
    ap.add_argument("--tiles", nargs="+", default=[os.path.join(HERE, "..", "..", "tests", "data", "als")])
    ap.add_argument("--pulse-reference", choices=["centroid", "peak", "gaussian-fit"], default="gaussian-fit")
    ap.add_argument("--passes", type=int, default=None, help="passes per world (default 6; 3 with --small)")
    ap.add_argument("--only", default=None, help="build only worlds whose name contains this text")
    ap.add_argument("--seeds", default=None, help="comma list: build only worlds of these seeds (controls included)")
    a = ap.parse_args(argv)
    seeds = {int(x) for x in a.seeds.split(",")} if a.seeds else None
    passes = a.passes or (3 if a.small else 6)
    os.makedirs(a.out, exist_ok=True)
    index = {"generator": worldgen.GENERATOR, "pulse_reference": a.pulse_reference, "worlds": []}
    t_all = time.time()
    for eff, lab, par, seed in plan(a.small):
        name = f"{eff}-{lab}-s{seed}"
        if (a.only and a.only not in name) or (seeds and seed not in seeds):
            continue
        params = [f"{k}={v}" for k, v in par.items()]
        argv_w = ["--effect", eff, "--seed", str(seed), "--out", os.path.join(a.out, name),
                  "--pulse-reference", a.pulse_reference, "--passes", str(passes), "--quiet", "--tiles", *a.tiles]
        for p in params:
            argv_w += ["--param", p]
        t0 = time.time()
        truth = worldgen.generate_world(worldgen.build_parser().parse_args(argv_w))
        dt = time.time() - t0
        print(f"{name:45s} {len(truth['tracks']):3d} tracks {len(truth['shots']):4d} shots  {dt:5.1f} s", flush=True)
        index["worlds"].append({"name": name, "effect": eff, "direction": lab, "seed": seed,
                                "effects": truth["effects"], "tracks": len(truth["tracks"]),
                                "shots": len(truth["shots"]), "seconds": round(dt, 1),
                                "source_tiles": [s["file"] for s in truth["scene"]["sources"]]})
    tmp = os.path.join(a.out, "suite.json.tmp")
    with open(tmp, "w") as fh:
        json.dump(index, fh, indent=1)
    os.replace(tmp, os.path.join(a.out, "suite.json"))
    print(f"{len(index['worlds'])} worlds in {time.time() - t_all:.0f} s -> {a.out}")


if __name__ == "__main__":
    main()
