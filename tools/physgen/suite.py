#!/usr/bin/env python3
"""Build the physgen benchmark suite.

    python3 tools/physgen/suite.py --out DIR [--small] [--jobs 2] [--tiles tests/data/als]

Every world is one call of physgen.py (a separate process, run under `nice`).  DIR/suite.json lists
the worlds: name, folder, effects, params, seed, and the control world of the same seed (same scene,
tracks, pulses and noise draws) for paired comparisons.  Existing complete worlds (truth.json present
and the same command) are reused.
"""
import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

HERE = os.path.dirname(os.path.abspath(__file__))
SEEDS = [11, 14]  # 11 -> lidarforfuel_1_42 (leaf-on), 14 -> lidarforfuel_2_bas_lig (leaf-off)
EXTRA_CONTROL_SEEDS = [12, 15]  # null worlds, one per tile


def variants():
    """(name, effect, params) for single effects; signed effects in both directions."""
    v = []
    for dz in (0.6, -0.6, 1.2, -1.2):
        v.append(("datum_%+.1f" % dz, "datum", {"dz_m": dz}))
    for r in (0.6, 1.7):
        v.append(("weighting_%.1f" % r, "weighting", {"rho_ground_over_veg": r}))
    for s in (0.7, 1.4):
        v.append(("pulse_%.1f" % s, "pulse", {"pulse_sigma_m": s}))
    for f in (4.0, 8.0):
        v.append(("footprint_%.0f" % f, "footprint", {"fsigma_m": f}))
    for n in (0.6, 2.0):
        v.append(("noise_%.1f" % n, "noise", {"noise_sigma_factor": n}))
    v.append(("canopy_change_loss0.3_h10", "canopy_change", {"height_m": 10.0, "fraction": 0.3}))
    v.append(("canopy_change_gain0.3_h10", "canopy_change", {"height_m": 10.0, "fraction": -0.3}))
    v.append(("canopy_change_loss0.6_h5", "canopy_change", {"height_m": 5.0, "fraction": 0.6}))
    for g in (-0.5, 0.5):
        v.append(("occlusion_%+.1f_h10" % g, "occlusion", {"height_m": 10.0, "gain": g}))
    for o in (0.7, -0.7):
        v.append(("ground_detection_a1_%+.1f" % o, "ground_detection", {"algorithm": "1", "offset_m": o}))
    for o in (0.5, -0.5):
        v.append(("ground_detection_all_%+.1f" % o, "ground_detection", {"algorithm": "all", "offset_m": o}))
    v.append(("geolocation_shot_3", "geolocation", {"level": "shot", "shot_sigma_m": 3.0}))
    v.append(("geolocation_beam_3", "geolocation", {"level": "beam", "shot_sigma_m": 3.0}))
    return v


def pairs():
    return [
        ("datum+weighting", {"datum.dz_m": 0.6, "weighting.rho_ground_over_veg": 1.7}),
        ("pulse+footprint", {"pulse.pulse_sigma_m": 1.4, "footprint.fsigma_m": 8.0}),
        ("canopy_change+noise", {"canopy_change.height_m": 10.0, "canopy_change.fraction": 0.3,
                                 "noise.noise_sigma_factor": 2.0}),
        ("ground_detection+geolocation", {"ground_detection.algorithm": "all", "ground_detection.offset_m": -0.5,
                                          "geolocation.level": "shot", "geolocation.shot_sigma_m": 3.0}),
    ]


def plan(small):
    worlds = []
    if small:
        worlds.append(dict(name="control_s11", effect="none", params={}, seed=11))
        worlds.append(dict(name="datum_+0.6_s11", effect="datum", params={"dz_m": 0.6}, seed=11))
        worlds.append(dict(name="weighting_0.6_s11", effect="weighting", params={"rho_ground_over_veg": 0.6}, seed=11))
    else:
        for s in SEEDS + EXTRA_CONTROL_SEEDS:
            worlds.append(dict(name="control_s%d" % s, effect="none", params={}, seed=s))
        for s in SEEDS:
            for name, eff, p in variants():
                worlds.append(dict(name="%s_s%d" % (name, s), effect=eff, params=p, seed=s))
            for eff, p in pairs():
                worlds.append(dict(name="%s_s%d" % (eff.replace("+", "__"), s), effect=eff, params=p, seed=s))
    for w in worlds:
        w["control"] = "control_s%d" % w["seed"]
    return worlds


def cmd_for(w, tiles, out, passes):
    c = ["nice", "-n", "10", sys.executable, os.path.join(HERE, "physgen.py"), "--effect", w["effect"],
         "--seed", str(w["seed"]), "--tiles", tiles, "--out", os.path.join(out, w["name"]), "--passes", str(passes)]
    for k, v in w["params"].items():
        c += ["--param", "%s=%s" % (k, v)]
    return c


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--small", action="store_true")
    ap.add_argument("--tiles", default=os.path.join(HERE, "..", "..", "tests", "data", "als"))
    ap.add_argument("--passes", type=int, default=4)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    tiles = os.path.abspath(a.tiles)
    os.makedirs(a.out, exist_ok=True)
    worlds = plan(a.small)
    t_all = time.time()

    def run(w):
        d = os.path.join(a.out, w["name"])
        c = cmd_for(w, tiles, a.out, a.passes)
        stamp = os.path.join(d, ".physgen-cmd")
        if os.path.exists(os.path.join(d, "truth.json")) and os.path.exists(stamp) and \
                open(stamp).read() == json.dumps(c[3:]):
            w["seconds"] = 0.0
            w["reused"] = True
            return w
        t = time.time()
        r = subprocess.run(c, capture_output=True, text=True)
        if r.returncode != 0:
            raise SystemExit("world %s failed:\n%s" % (w["name"], r.stderr[-3000:]))
        with open(stamp, "w") as f:
            f.write(json.dumps(c[3:]))
        w["seconds"] = round(time.time() - t, 2)
        print("%-45s %6.1f s" % (w["name"], w["seconds"]), flush=True)
        return w

    with ThreadPoolExecutor(max_workers=max(1, a.jobs)) as ex:
        done = list(ex.map(run, worlds))
    suite = {"generator": "physgen suite", "small": a.small, "passes": a.passes, "tiles": tiles,
             "worlds": [{"name": w["name"], "dir": w["name"], "effect": w["effect"],
                         "effects": [] if w["effect"] == "none" else w["effect"].split("+"),
                         "params": w["params"], "seed": w["seed"], "control": w["control"],
                         "seconds": w.get("seconds")} for w in done],
             "wall_seconds": round(time.time() - t_all, 1)}
    fn = os.path.join(a.out, "suite.json")
    with open(fn + ".tmp", "w") as f:
        json.dump(suite, f, indent=1)
    os.replace(fn + ".tmp", fn)
    print("wrote %s (%d worlds, %.0f s)" % (fn, len(done), suite["wall_seconds"]))


if __name__ == "__main__":
    main()
