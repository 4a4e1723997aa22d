"""Write a LAS/LAZ tile as COPC with copclib (copc-lib), another tool than gedisim, so that gedisim's
COPC reader is tested against files it did not write.

The octree is made as COPC writers make it: a cube centred on the header bounds, half its side the
largest half-extent; each level keeps at most one point per cell of a `--grid`³ grid of its node (the
first in a seeded random order), the rest go one level down, and the deepest level keeps every
point left (`--cube corner` puts the cube's corner at the bounds' minimum instead). Nodes of level ≥ `--page-level` are listed in hierarchy pages of their own (one per
node of that level), as deep real tiles are. `--no-info-cube` writes zeros for the cube in the COPC
info VLR, as some writers do.

    python3 tools/copc/write_copc.py IN.laz OUT.copc.laz [--depth 6] [--grid 32] [--page-level 2]

Needs numpy, laspy with lazrs, and copclib (pip install copclib).
"""
import argparse

import copclib as copc
import laspy
import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("src")
    ap.add_argument("dest")
    ap.add_argument("--depth", type=int, default=6, help="deepest octree level")
    ap.add_argument("--grid", type=int, default=32, help="cells per node side kept at each level")
    ap.add_argument("--page-level", type=int, default=2, help="level whose nodes start hierarchy pages")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-info-cube", action="store_true", help="write zeros for the cube in the info VLR")
    ap.add_argument("--cube", choices=["centred", "corner"], default="centred",
                    help="octree cube centred on the bounds (COPC writers), or with its corner at their minimum")
    a = ap.parse_args()

    las = laspy.read(a.src)
    h = las.header
    if h.point_format.id != 6:
        raise SystemExit(f"{a.src}: point format {h.point_format.id}; this writer handles format 6")
    n = len(las.points)
    raw = np.frombuffer(las.points.array.tobytes(), dtype=np.uint8).reshape(n, -1)[:, :30]
    xyz = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    lo, hi = np.asarray(h.mins, float), np.asarray(h.maxs, float)
    half = float(np.max(hi - lo) / 2)
    centre = (lo + hi) / 2 if a.cube == "centred" else lo + half
    origin = centre - half

    order = np.random.default_rng(a.seed).permutation(n)
    level = np.full(n, a.depth, dtype=np.int64)
    left = order
    for lv in range(a.depth):
        side = 2 * half / (1 << lv)
        cell = np.floor((xyz[left] - origin) / side * a.grid).astype(np.int64)
        cell = np.clip(cell, 0, (1 << lv) * a.grid - 1)
        key = (cell[:, 0] * (1 << 21) + cell[:, 1]) * (1 << 21) + cell[:, 2]
        _, first = np.unique(key, return_index=True)
        keep = np.zeros(len(left), bool)
        keep[first] = True
        level[left[keep]] = lv
        left = left[~keep]

    wkt = ""
    for v in list(h.vlrs) + list(getattr(las, "evlrs", []) or []):
        if getattr(v, "record_id", None) == 2112:
            wkt = v.string if hasattr(v, "string") else bytes(v.record_data).decode().rstrip("\0")
    cfg = copc.CopcConfigWriter(
        6,
        copc.Vector3(*[float(s) for s in h.scales]),
        copc.Vector3(*[float(o) for o in h.offsets]),
        wkt,
    )
    if not a.no_info_cube:
        cfg.copc_info.center_x, cfg.copc_info.center_y, cfg.copc_info.center_z = map(float, centre)
        cfg.copc_info.halfsize = half
        cfg.copc_info.spacing = 2 * half / a.grid
    hd = cfg.las_header
    hd.min = copc.Vector3(*map(float, lo))
    hd.max = copc.Vector3(*map(float, hi))
    w = copc.FileWriter(a.dest, cfg)

    nodes = {}
    for lv in range(a.depth + 1):
        idx = np.nonzero(level == lv)[0]
        side = 2 * half / (1 << lv)
        k = np.clip(np.floor((xyz[idx] - origin) / side).astype(np.int64), 0, (1 << lv) - 1)
        for key, members in zip(*_groups(k, idx)):
            nodes[(lv, *key)] = members
    for (lv, x, y, z), members in sorted(nodes.items()):
        if lv >= a.page_level:
            s = lv - a.page_level
            page = copc.VoxelKey(a.page_level, x >> s, y >> s, z >> s)
        else:
            page = copc.VoxelKey(0, 0, 0, 0)
        data = raw[np.sort(members)].tobytes()
        w.AddNode(copc.VoxelKey(lv, x, y, z), copc.VectorChar(np.frombuffer(data, dtype=np.int8)), page)
    w.Close()
    print(f"{a.dest}: {n} points, {len(nodes)} nodes, depth {a.depth}")


def _groups(keys, idx):
    """Rows of `idx` grouped by their (x, y, z) key."""
    uniq, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.ravel()
    sorter = np.argsort(inv, kind="stable")
    bounds = np.searchsorted(inv[sorter], np.arange(len(uniq) + 1))
    return [tuple(map(int, u)) for u in uniq], [idx[sorter[bounds[i]:bounds[i + 1]]] for i in range(len(uniq))]


if __name__ == "__main__":
    main()
