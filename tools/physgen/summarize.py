#!/usr/bin/env python3
"""Paired effect responses of a physgen suite (median over shots of effect world - its control).

    python3 tools/physgen/summarize.py /tmp/physgen-suite
"""
import glob
import json
import os
import sys

import h5py
import numpy as np


def load(d):
    out = {}
    for fn in sorted(glob.glob(os.path.join(d, "gedi", "GEDI02_A_*.h5"))):
        l1 = fn.replace("GEDI02_A_", "GEDI01_B_").replace("_003_02_V002", "_005_02_V002")
        with h5py.File(fn, "r") as f, h5py.File(l1, "r") as g:
            for b in (k for k in f if k.startswith("BEAM")):
                B, L = f[b], g[b]
                v = dict(z=B["elev_lowestmode"][:], z1=B["geolocation/elev_lowestmode_a1"][:],
                         rh98=B["rh"][:, 98], rh50=B["rh"][:, 50], b0=L["geolocation/elevation_bin0"][:],
                         lat=B["lat_lowestmode"][:], ns=L["noise_stddev_corrected"][:], en=L["rx_energy"][:],
                         eg=B["geolocation/energy_lowestmode_a1"][:], q=B["quality_flag"][:], sens=B["sensitivity"][:])
                for i, sn in enumerate(B["shot_number"][:]):
                    out[int(sn)] = {k: float(a[i]) for k, a in v.items()}
    return out


def main():
    root = sys.argv[1]
    suite = json.load(open(os.path.join(root, "suite.json")))
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = load(os.path.join(root, name))
        return cache[name]

    print("| world | n | Δ elev_lowestmode | Δ elev a1 | Δ rh98 | Δ rh50 | Δ bin0 | σ ratio | rx_energy ratio | "
          "ground-mode energy ratio | |Δ lat_lowestmode| (m) | quality |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for w in suite["worlds"]:
        if w["effect"] == "none":
            c = get(w["name"])
            print("| %s (control) | %d | | | | | | | | | | %.2f |" % (w["name"], len(c), np.mean([v["q"] for v in c.values()])))
            continue
        c = get(w["control"])
        e = get(w["name"])
        k = [s for s in c if s in e]

        def d(key):
            return np.median([e[s][key] - c[s][key] for s in k])

        def r(key):
            return np.median([e[s][key] / c[s][key] for s in k if c[s][key] != 0])
        dlat = np.median([abs(e[s]["lat"] - c[s]["lat"]) * 111320 for s in k])
        print("| %s | %d | %+.3f | %+.3f | %+.2f | %+.2f | %+.3f | %.2f | %.2f | %.2f | %.2f | %.2f |" % (
            w["name"], len(k), d("z"), d("z1"), d("rh98"), d("rh50"), d("b0"), r("ns"), r("en"), r("eg"), dlat,
            np.mean([e[s]["q"] for s in k])))


if __name__ == "__main__":
    main()
