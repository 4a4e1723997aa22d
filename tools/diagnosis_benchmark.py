#!/usr/bin/env python3
"""Score `gedisim diagnose` on worlds from either generator (`gedisim scenario`, tools/worldgen).

Each world folder holds `truth.json` (both generators write `effects: [{name, params}]`,
`datum_dz_m` and per-shot true/reported positions) and `als/` + `gedi/`. For each world the
diagnosis is run with the whole chain into `<world>/diag` (`--diag NAME`: another folder) unless its `diagnosis.json` exists.
It is then scored against the truth:
- the simulator configuration chosen (weighting + pulse), which is never an effect;
- which effect comes first (or `unexplained`), and whether the diagnosis calls it ambiguous;
- whether per-shot geolocation was named anywhere on the ladder (spurious where none was planted),
  and its ground test (β and interval);
- the held-out shrink of the true effect (its own trial);
- the error of its main parameter;
- the collocation: for every segment, dz − datum_dz (vertical) and the distance between (dx, dy)
  and the mean true − reported offset of its shots (horizontal); summarised over all segments and
  over those of ≥ 20 shots.

Usage:
    python3 tools/diagnosis_benchmark.py --gedisim target/debug/gedisim [--twins N] [--diag NAME] WORLD... [--json out.json]
Prints one line per world, then the summary per generator. Asserts nothing.
"""

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq

# The parameter of each effect that the benchmark scores, and its "no effect" value.
MAIN = {
    "datum": ("dz_m", 0.0),
    "ground_detection": ("offset_m", 0.0),
    "canopy_change": ("fraction", 0.0),
    "occlusion": ("gain", 0.0),
    "weighting": ("rho_ground_over_veg", 1.0),
    "pulse": ("pulse_sigma_m", 0.0),
    "footprint": ("fsigma_m", 5.5),
    "noise": ("noise_sigma_factor", 1.0),
    "geolocation": ("shot_sigma_m", 0.0),
}


def generator(truth):
    g = str(truth.get("generator", truth.get("format", "")))
    for name in ("worldgen", "physgen"):
        if g.startswith(name):
            return name
    return "gedisim"


def true_offsets(truth):
    """shot number -> (dx, dy) = true - reported (m)."""
    out = {}
    for s in truth["shots"]:
        sn = int(s["shot_number"])
        if "x_true" in s:
            out[sn] = (s["x_true"] - s["x_reported"], s["y_true"] - s["y_reported"])
        else:
            out[sn] = (s["dx"], s["dy"])
    return out


def collocation_errors(world, truth, diag_name):
    path = world / diag_name / "dataset" / "offsets" / "offsets.parquet"
    if not path.exists():
        return []
    t = pq.read_table(path).to_pylist()
    offs = true_offsets(truth)
    datum = float(truth.get("datum_dz_m", 0.0) or 0.0)
    rows = []
    for r in t:
        shots = [s for s in (r["shot_numbers"] or []) if s in offs]
        if not shots or r["dz"] is None:
            continue
        tx = sum(offs[s][0] for s in shots) / len(shots)
        ty = sum(offs[s][1] for s in shots) / len(shots)
        rows.append((r["dz"] - datum, math.hypot(r["dx"] - tx, r["dy"] - ty), len(shots)))
    return rows


def is_configuration(e):
    """A weighting planted as another method at ρ 1 (every return weighing 1: `count`) is a simulator
    configuration, which the diagnosis chooses first and never reports as an effect."""
    p = e.get("params", {})
    return e["name"] == "weighting" and p.get("method", "ratio") != "ratio" and p.get("rho_ground_over_veg", 1.0) == 1.0


def score(world, truth, d, diag_name):
    planted = [e["name"] for e in truth["effects"] if e["name"] != "none" and not is_configuration(e)]
    effects = d["effects"]
    first = None if d["unexplained"] else effects[0]["name"]
    named = [t["name"] for t in d["ladder"]] or ([first] if first else [])
    row = {
        "world": world.name,
        "generator": generator(truth),
        "truth": "+".join(planted) or "none",
        "world_configuration": next((e["params"]["method"] for e in truth["effects"] if is_configuration(e)), None),
        "first": first or "unexplained",
        "ambiguous_with": d.get("ambiguous_with", []),
        "right_first": (first in planted) if planted else (first is None),
        "pair_both": all(p in named for p in planted) if len(planted) == 2 else None,
        "configuration": (d.get("configuration") or {}).get("chosen"),
        "geolocation_named": "geolocation" in named,
        "geolocation_planted": "geolocation" in planted,
        # The ranking's first effect by its intervals, before the self-test decided the verdict.
        "ranking_first": (d.get("verdict") or {}).get("ranking_names"),
        "verdict": (d.get("verdict") or {}).get("kind"),
    }
    st = d.get("self_test")
    if st and st.get("named"):
        n = st["named"]
        row["self_test"] = (n["effect"], n["recovered"], n["named_without"], n["twins"])
    geo = next((t for t in effects if t["name"] == "geolocation"), None)
    if geo and geo.get("ground_test"):
        g = geo["ground_test"]
        row["ground_test"] = (g.get("beta"), g.get("ci95"), g.get("rms_predicted_m"))
    if len(planted) == 1:
        name = planted[0]
        trial = next((t for t in effects if t["name"] == name), None)
        if trial:
            row["shrink"] = trial["held_out"]["shrink"]
            key, nominal = MAIN[name]
            want = next(e for e in truth["effects"] if e["name"] == name and not is_configuration(e))["params"].get(key)
            got = trial["params"].get(key)
            if name == "weighting" and isinstance(got, (int, float)):
                # The effect's ratio is relative to the chosen configuration's reflectances.
                got *= (d.get("configuration") or {}).get("rho_ground_over_veg", 1.0)
            if isinstance(want, (int, float)) and isinstance(got, (int, float)) and want != nominal:
                row["param_rel_err"] = abs(got - want) / abs(want - nominal)
                row["param"] = (got, want)
    row["collocation"] = collocation_errors(world, truth, diag_name)
    return row


def self_test_text(row):
    if "self_test" not in row:
        return ""
    effect, recovered, without, twins = row["self_test"]
    return f" self-test {effect} {recovered}/{twins} planted, {without}/{twins} none"


def median(v):
    v = sorted(v)
    return v[len(v) // 2] if v else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gedisim", default="gedisim")
    ap.add_argument("--json")
    ap.add_argument("--twins", help="twin sets per planted hypothesis of the self-test (default: gedisim's)")
    ap.add_argument("--diag", default="diag", help="folder of each world's diagnosis (default diag)")
    ap.add_argument("worlds", nargs="+", type=Path)
    a = ap.parse_args()
    rows = []
    for w in a.worlds:
        truth = json.loads((w / "truth.json").read_text())
        out = w / a.diag
        diag = out / "diagnosis.json"
        if not diag.exists():
            t0 = time.time()
            cmd = [a.gedisim, "diagnose", "--als", str(w / "als"), "--l1b", str(w / "gedi"), "--l2a", str(w / "gedi"),
                   "--out", str(out)] + (["--twins", a.twins] if a.twins else [])
            r = subprocess.run(cmd, capture_output=True, text=True)
            if r.returncode != 0:
                print(f"{w.name}: diagnose failed: {r.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
                continue
            (out / "summary.txt").write_text(r.stdout)  # the summary as a scientist reads it
            (out / "seconds.txt").write_text(f"{time.time() - t0:.1f}\n")
            print(f"{w.name}: diagnosed in {time.time() - t0:.0f} s", file=sys.stderr)
        row = score(w, truth, json.loads(diag.read_text()), a.diag)
        seconds = out / "seconds.txt"
        row["seconds"] = float(seconds.read_text()) if seconds.exists() else None
        rows.append(row)
        col = row["collocation"]
        print(f"{row['world']:<28} {row['generator']:<8} truth {row['truth']:<26} first {row['first']:<18}"
              f"{' ambiguous ' + ','.join(row['ambiguous_with']) if row['ambiguous_with'] else ''}"
              f" shrink {row.get('shrink', float('nan')):.2f} param_err {row.get('param_rel_err', float('nan')):.2f}"
              f" config {row['configuration']}"
              f" ranking {row['ranking_first'] or '–'}"
              f"{self_test_text(row)}"
              f"{' GEOLOCATION named' if row['geolocation_named'] else ''}"
              f" segments {len(col)} median dz err {median([c[0] for c in col]):+.3f} m")
    for g in sorted({r["generator"] for r in rows}):
        rs = [r for r in rows if r["generator"] == g]
        eff = [r for r in rs if r["truth"] != "none" and "+" not in r["truth"]]
        ctl = [r for r in rs if r["truth"] == "none"]
        pairs = [r for r in rs if "+" in r["truth"]]
        col = [c for r in rs for c in r["collocation"]]
        print(f"\n{g}: {len(rs)} worlds")
        if eff:
            print(f"  right effect first {sum(r['right_first'] for r in eff)}/{len(eff)}; "
                  f"held-out shrink of the true effect median {median([r.get('shrink', 0.0) for r in eff]):.2f}, "
                  f"mean {sum(r.get('shrink', 0.0) for r in eff) / len(eff):.2f}; "
                  f"parameter within 20 % {sum(r.get('param_rel_err', 9) <= 0.2 for r in eff)}/{len(eff)}")
            for name in sorted({r["truth"] for r in eff}):
                er = [r for r in eff if r["truth"] == name]
                shrinks = ", ".join(f"{r.get('shrink', float('nan')):.2f}" for r in er)
                errs = ", ".join(f"{100 * r['param_rel_err']:.0f} %" if "param_rel_err" in r else "–" for r in er)
                print(f"    {name:<17} first {sum(r['right_first'] for r in er)}/{len(er)} "
                      f"(ambiguous {sum(bool(r['ambiguous_with']) for r in er)}); shrink {shrinks}; "
                      f"parameter error {errs}")
        if ctl:
            print(f"  controls unexplained {sum(r['right_first'] for r in ctl)}/{len(ctl)}")
        nogeo = [r for r in rs if not r["geolocation_planted"]]
        if nogeo:
            print(f"  per-shot geolocation named in {sum(r['geolocation_named'] for r in nogeo)}/{len(nogeo)} "
                  f"worlds without it")
        configs = {}
        for r in rs:
            configs[r["configuration"]] = configs.get(r["configuration"], 0) + 1
        print(f"  configurations chosen: {configs}")
        if pairs:
            print(f"  pairs both named {sum(bool(r['pair_both']) for r in pairs)}/{len(pairs)}")
        for label, sel in [("all segments", col), ("segments of ≥ 20 shots", [c for c in col if c[2] >= 20])]:
            if sel:
                dz = [c[0] for c in sel]
                print(f"  collocation, {label} ({len(sel)}): dz − truth median {median(dz):+.3f} m, "
                      f"max |.| {max(abs(x) for x in dz):.3f} m; horizontal within 1 m "
                      f"{sum(c[1] <= 1.0 for c in sel)}/{len(sel)}")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
