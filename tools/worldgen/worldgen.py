#!/usr/bin/env python3
"""worldgen -- an independent generator of GEDI test "worlds" from real ALS tiles.

A world = a mosaic of real ALS tiles (LAZ, EPSG:2154) + pseudo-real GEDI L1B/L2A granules
(HDF5, V2 layout) simulated from the ALS points with our own physics + truth.json.

Written from physics and public facts only (see README.md); it is a test input, not a reference.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import glob
import hashlib
import json
import math
import os
import sys
import time
import uuid

import numpy as np

VERSION = "1.0.0"
GENERATOR = f"worldgen {VERSION}"

# --------------------------------------------------------------------------------------------
# Physical constants and measured instrument constants (provenance: README.md "Constants")
# --------------------------------------------------------------------------------------------
C_LIGHT = 299_792_458.0
BIN_M = C_LIGHT * 1e-9 / 2.0          # range of one 1 ns sample, 0.149896 m
GEDI_EPOCH = _dt.datetime(2018, 1, 1, tzinfo=_dt.timezone.utc)
GPS_EPOCH = _dt.datetime(1980, 1, 6, tzinfo=_dt.timezone.utc)
MASTER_TIME_EPOCH = 1198800018.0      # GPS seconds of 2018-01-01 (measured in the V1 L1B)
TX_SAMPLES = 128                      # samples per txwaveform record (measured, V1 and V2 L1B)

# Per beam: (beam number, channel, type, laser group, noise mean DN, noise_stddev_corrected DN).
# Noise mean/stddev: per-beam medians measured on the real V1 L1B (BEAM0000 is absent from the
# subset: it takes BEAM0001's values and channel 0, an assumption).
BEAMS = {
    "BEAM0000": (0, 0, "coverage", "cov", 245.6, 2.97),
    "BEAM0001": (1, 0, "coverage", "cov", 245.6, 2.97),
    "BEAM0010": (2, 1, "coverage", "cov", 241.0, 2.48),
    "BEAM0011": (3, 1, "coverage", "cov", 241.0, 2.51),
    "BEAM0101": (5, 2, "full", "fpA", 204.8, 3.26),
    "BEAM0110": (6, 3, "full", "fpA", 228.0, 3.51),
    "BEAM1000": (8, 4, "full", "fpB", 254.5, 3.09),
    "BEAM1011": (11, 5, "full", "fpB", 222.6, 2.96),
}
# cross-track order of the beams in our compressed fan (assumption, see README)
BEAM_ORDER = ["BEAM0000", "BEAM0101", "BEAM0001", "BEAM0110",
              "BEAM0010", "BEAM1000", "BEAM0011", "BEAM1011"]

E_MEDIAN = {"full": 16268.0, "coverage": 6896.0}   # rx_energy medians (counts*samples), measured
E_LOGSD = 0.12                                      # log-sd of rx_energy within a beam type, measured
NOISE_SD_RATIO = 1.74        # noise_stddev_corrected / std of the stored pre-signal samples, measured
NOISE_CORR_SIGMA = 1.75      # Gaussian low-pass (samples) reproducing the measured noise autocorrelation
SHOT_NOISE_KAPPA = 0.01      # signal shot-noise variance per count of signal (assumption)
TX_NOISE_SD = 1.4            # in-record std of txwaveform baseline (DN), measured 1.26-1.58
ADC_MAX = 4095.0             # 12-bit digitiser saturation (assumption)
SHOT_DT = 0.00826            # s between consecutive shots of one beam, measured
SHOT_SPACING_M = 60.0        # along-track spacing (brief; measured 57.15 m in the V1 granule)
ISS_ALT = 413_340.0          # m, altitude_instrument, measured
TOP_MARGIN_M = (42.0, 47.0)  # record start above highest return (measured toploc ~288-298 samples)
BOT_MARGIN_M = (58.0, 64.0)  # record end below lowest ground (measured n - botloc ~396-436 samples)
FSIGMA_NOMINAL = 5.5         # m, footprint Gaussian sigma (brief)
FOOTPRINT_MARGIN_SIGMA = 7.5 # shots kept if footprint (2*max(sigma, this)+1 m) inside the mosaic
GEOID_RANGE = (44.0, 55.0)   # m, world-constant geoid undulation (brief; France)
GROUND_CLASSES = (2, 9)      # ASPRS ground, water -> ground reflectance
EXCLUDED_CLASSES = (7, 18)   # noise; classes >= 19 (e.g. IGN 65) are excluded too

# Our own L2A-like algorithm settings (sigmas in samples, thresholds in noise_stddev_corrected)
ALGS = {
    1: dict(sig_locs=5.0, sig_modes=5.0, k_front=4.0, k_back=4.0),
    2: dict(sig_locs=5.0, sig_modes=4.0, k_front=3.0, k_back=2.5),
    3: dict(sig_locs=8.0, sig_modes=8.0, k_front=4.0, k_back=4.0),
    4: dict(sig_locs=5.0, sig_modes=5.0, k_front=6.0, k_back=6.0),
    5: dict(sig_locs=5.0, sig_modes=3.0, k_front=3.0, k_back=2.0),
    6: dict(sig_locs=8.0, sig_modes=6.0, k_front=3.0, k_back=3.0),
}
K_PROMINENCE = 1.0           # a mode must stand 1 noise sd above its neighbouring valleys
NOMINAL_PULSE_SIGMA = 7.0    # samples; Gaussian-fit sigma of the real pulses is 5.7-7.6
GUARD = 10                   # samples ignored at both ends of a record by our L2A
FILL = -9999.0

# --------------------------------------------------------------------------------------------
# Effects (names and parameter names are a contract)
# --------------------------------------------------------------------------------------------
EFFECTS = {
    "none": {},
    "geolocation": {"level": "shot", "shot_sigma_m": 3.0},
    "datum": {"dz_m": 0.5},
    "weighting": {"rho_ground_over_veg": 1.6},
    "pulse": {"pulse_sigma_m": 1.2},
    "footprint": {"fsigma_m": 7.5},
    "noise": {"noise_sigma_factor": 2.0},
    "canopy_change": {"height_m": 10.0, "fraction": 0.3},
    "occlusion": {"height_m": 5.0, "gain": 0.5},
    "ground_detection": {"algorithm": "all", "offset_m": 0.5},
}
PRIMARY = {"geolocation": "shot_sigma_m", "datum": "dz_m", "weighting": "rho_ground_over_veg",
           "pulse": "pulse_sigma_m", "footprint": "fsigma_m", "noise": "noise_sigma_factor",
           "canopy_change": "fraction", "occlusion": "gain", "ground_detection": "offset_m"}


def _coerce(key, val):
    if key in ("level",):
        if val not in ("shot", "beam"):
            raise SystemExit(f"geolocation level must be 'shot' or 'beam', got {val!r}")
        return val
    if key == "algorithm":
        if str(val) == "all":
            return "all"
        v = int(val)
        if v not in range(1, 7):
            raise SystemExit("ground_detection algorithm must be 'all' or 1..6")
        return v
    return float(val)


def parse_effects(effect: str, params: list[str], magnitude):
    names = [e.strip() for e in effect.split("+") if e.strip()]
    if not names:
        raise SystemExit("empty --effect")
    for n in names:
        if n not in EFFECTS:
            raise SystemExit(f"unknown effect {n!r}; known: {', '.join(EFFECTS)}")
    if "none" in names and len(names) > 1:
        raise SystemExit("'none' cannot be combined")
    out = [{"name": n, "params": dict(EFFECTS[n])} for n in names]
    if magnitude is not None:
        if len(names) != 1 or names[0] == "none":
            raise SystemExit("--magnitude needs exactly one effect (use --param name.key=value for pairs)")
        out[0]["params"][PRIMARY[names[0]]] = float(magnitude)
    for p in params or []:
        if "=" not in p:
            raise SystemExit(f"--param expects key=value, got {p!r}")
        key, val = p.split("=", 1)
        key = key.strip()
        target = None
        if "." in key:
            target, key = key.split(".", 1)
            if target not in names:
                raise SystemExit(f"--param {p!r}: effect {target!r} not in {names}")
        hit = False
        for e in out:
            if (target is None or e["name"] == target) and key in e["params"]:
                e["params"][key] = _coerce(key, val.strip())
                hit = True
        if not hit:
            raise SystemExit(f"--param {p!r} matches no parameter of {names}")
    if names == ["none"]:
        return [{"name": "none", "params": {}}]
    return out


class Physics:
    """Resolved nominal + effect parameters of one world."""

    def __init__(self, effects):
        self.fsigma = FSIGMA_NOMINAL
        self.rho_g = 1.0
        self.rho_v = 1.0
        self.pulse_sigma_m = 0.0
        self.noise_factor = 1.0
        self.datum_dz = 0.0
        self.geo_level = None
        self.geo_sigma = 0.0
        self.canopy_change = None     # (height, fraction)
        self.occlusion = None         # (height, gain)
        self.ground_detection = None  # (algorithm, offset)
        for e in effects:
            p = e["params"]
            n = e["name"]
            if n == "footprint":
                self.fsigma = float(p["fsigma_m"])
            elif n == "weighting":
                self.rho_g = float(p["rho_ground_over_veg"])
            elif n == "pulse":
                self.pulse_sigma_m = float(p["pulse_sigma_m"])
            elif n == "noise":
                self.noise_factor = float(p["noise_sigma_factor"])
            elif n == "datum":
                self.datum_dz = float(p["dz_m"])
            elif n == "geolocation":
                self.geo_level = p["level"]
                self.geo_sigma = float(p["shot_sigma_m"])
            elif n == "canopy_change":
                self.canopy_change = (float(p["height_m"]), float(p["fraction"]))
            elif n == "occlusion":
                self.occlusion = (float(p["height_m"]), float(p["gain"]))
            elif n == "ground_detection":
                self.ground_detection = (p["algorithm"], float(p["offset_m"]))
        if self.fsigma <= 0 or self.noise_factor < 0 or self.pulse_sigma_m < 0:
            raise SystemExit("invalid effect parameter (fsigma_m > 0, noise_sigma_factor >= 0, pulse_sigma_m >= 0)")


# --------------------------------------------------------------------------------------------
# Random streams: one independent generator per purpose, so that an effect never shifts the
# random draws of anything else (same seed => same scene, tracks, pulses and noise).
# --------------------------------------------------------------------------------------------
def rng_for(seed, *keys):
    words = [int(seed) & 0xFFFFFFFF]
    for k in keys:
        if isinstance(k, str):
            words.append(int.from_bytes(hashlib.sha256(k.encode()).digest()[:4], "little"))
        else:
            words.append(int(k) & 0xFFFFFFFF)
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(words)))


# --------------------------------------------------------------------------------------------
# Small numerical helpers
# --------------------------------------------------------------------------------------------
def gauss_kernel(sigma, trunc=4.0):
    if sigma <= 0:
        return np.array([1.0])
    half = max(1, int(math.ceil(trunc * sigma)))
    x = np.arange(-half, half + 1, dtype=float)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


def smooth(w, sigma):
    k = gauss_kernel(sigma)
    h = len(k) // 2
    return np.convolve(np.pad(w, h, mode="edge"), k, mode="valid")


def gfit(y, x=None, iters=60):
    """Least-squares fit of b + A exp(-(x-mu)^2 / (2 s^2)) (Levenberg-Marquardt).
    Returns (A, mu, s, b, errors(4))."""
    y = np.asarray(y, float)
    if x is None:
        x = np.arange(len(y), dtype=float)
    b = float(np.median(np.concatenate([y[:8], y[-8:]])))
    i = int(np.argmax(y))
    A = float(y[i] - b)
    above = np.where(y - b > A / 2)[0]
    s = max(1.0, (above[-1] - above[0] + 1) / 2.355) if len(above) else 3.0
    p = np.array([A, float(x[i]), s, b])
    lam = 1e-3

    def model(p):
        g = np.exp(-(x - p[1]) ** 2 / (2 * p[2] ** 2))
        return p[3] + p[0] * g, g

    m, g = model(p)
    r = y - m
    cost = float(r @ r)
    J = None
    for _ in range(iters):
        J = np.stack([g, p[0] * g * (x - p[1]) / p[2] ** 2,
                      p[0] * g * (x - p[1]) ** 2 / p[2] ** 3, np.ones_like(x)], 1)
        H = J.T @ J
        dp = np.linalg.solve(H + lam * np.diag(np.diag(H)) + 1e-12 * np.eye(4), J.T @ r)
        pn = p + dp
        if pn[2] <= 0.3:
            lam *= 10
            continue
        mn, gn = model(pn)
        rn = y - mn
        cn = float(rn @ rn)
        if cn < cost:
            p, m, g, r, cost = pn, mn, gn, rn, cn
            lam *= 0.3
            if abs(dp[1]) < 1e-7:
                break
        else:
            lam *= 10
    try:
        with np.errstate(all="ignore"):
            J = np.stack([g, p[0] * g * (x - p[1]) / p[2] ** 2,
                          p[0] * g * (x - p[1]) ** 2 / p[2] ** 3, np.ones_like(x)], 1)
            cov = np.linalg.inv(J.T @ J) * cost / max(1, len(y) - 4)
            err = np.sqrt(np.abs(np.diag(cov)))
        err = np.where(np.isfinite(err), err, 0.0)
    except np.linalg.LinAlgError:
        err = np.zeros(4)
    return p[0], p[1], p[2], p[3], err


def pulse_reference_points(samples):
    """Peak (parabolic vertex), centroid and Gaussian-fit mean of a baseline-free pulse record,
    all in 0-based sample units."""
    s = np.asarray(samples, float)
    j = int(np.argmax(s))
    if 0 < j < len(s) - 1:
        den = s[j - 1] - 2 * s[j] + s[j + 1]
        peak = j + (0.5 * (s[j - 1] - s[j + 1]) / den if den != 0 else 0.0)
    else:
        peak = float(j)
    pos = np.clip(s, 0, None)
    centroid = float((np.arange(len(s)) * pos).sum() / pos.sum())
    gf = gfit(s)[1]
    return float(peak), centroid, float(gf)


def sha256_of(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def gps_to_datetime(gps_adjusted):
    # LAS adjusted standard GPS time: GPS seconds - 1e9; UTC = GPS - 18 s (since 2017)
    return GPS_EPOCH + _dt.timedelta(seconds=float(gps_adjusted) + 1e9 - 18.0)


# --------------------------------------------------------------------------------------------
# Transmit pulse library (real GEDI txwaveform shapes)
# --------------------------------------------------------------------------------------------
def default_tx_sources():
    here = os.path.dirname(os.path.abspath(__file__))
    cands = sorted(glob.glob(os.path.join(here, "..", "..", "tests", "data", "gedi", "GEDI01_B_*.h5")))
    if not cands:
        cands = sorted(glob.glob("/work/shared/data/gedi/rgedi_v001/GEDI01_B_*.h5"))
    return [os.path.abspath(c) for c in cands]


_PULSE_CACHE = {}


def load_pulse_library(paths):
    key = tuple(paths)
    if key in _PULSE_CACHE:
        return _PULSE_CACHE[key]
    import h5py
    lib = {"cov": [], "fpA": [], "fpB": []}
    for p in paths:
        with h5py.File(p, "r") as f:
            for b in sorted(k for k in f.keys() if k.startswith("BEAM")):
                if b not in BEAMS:
                    continue
                grp = BEAMS[b][3]
                B = f[b]
                tx = B["txwaveform"][:].astype(float)
                st = B["tx_sample_start_index"][:].astype(np.int64) - 1
                cnt = B["tx_sample_count"][:].astype(np.int64)
                for s0, c in zip(st, cnt):
                    rec = tx[s0:s0 + c]
                    if len(rec) != TX_SAMPLES:
                        continue
                    base = float(np.median(rec[:20]))
                    s = rec - base
                    amp = float(s.max())
                    ipk = int(np.argmax(s))
                    above = np.where(s[:ipk] < 0.01 * amp)[0]
                    onset = int(above[-1]) if len(above) else 0
                    s[:max(0, onset - 3)] = 0.0
                    # tail: below 2 % of the peak, replace by a 7-sample running mean (denoise)
                    ma = np.convolve(np.pad(s, 3, mode="edge"), np.ones(7) / 7, mode="valid")
                    tail = (np.arange(TX_SAMPLES) > ipk) & (ma < 0.02 * amp)
                    s[tail] = ma[tail]
                    s = np.clip(s, 0, None) / amp
                    mu = gfit(s)[1]
                    lib[grp].append({"shape": s, "mu": float(mu), "amp": amp,
                                     "src": f"{os.path.basename(p)}:{b}"})
    for g in lib:
        if not lib[g]:
            # fall back to any other group's pulses
            lib[g] = [q for gg in lib for q in lib[gg]]
    if not any(lib.values()):
        raise SystemExit("no usable txwaveform in " + ", ".join(paths))
    _PULSE_CACHE[key] = lib
    return lib


# --------------------------------------------------------------------------------------------
# ALS tiles
# --------------------------------------------------------------------------------------------
class Tile:
    pass


_TILE_CACHE = {}


def load_tile(path):
    path = os.path.abspath(path)
    if path in _TILE_CACHE:
        return _TILE_CACHE[path]
    import laspy
    las = laspy.read(path)
    t = Tile()
    t.path = path
    t.name = os.path.basename(path)
    t.sha256 = sha256_of(path)
    t.header = las.header
    crs_vlrs = [v for v in las.header.vlrs if v.user_id == "LASF_Projection" and v.record_id == 2112]
    if not crs_vlrs:
        raise SystemExit(f"{path}: no WKT CRS VLR (LASF_Projection/2112)")
    t.crs_vlr = crs_vlrs[0]
    crs = las.header.parse_crs()
    if crs is None or crs.to_epsg() != 2154:
        raise SystemExit(f"{path}: CRS is not EPSG:2154")
    x = np.asarray(las.x, float)
    y = np.asarray(las.y, float)
    z = np.asarray(las.z, float)
    t.fields = {
        "intensity": np.asarray(las.intensity),
        "return_number": np.asarray(las.return_number),
        "number_of_returns": np.asarray(las.number_of_returns),
        "classification": np.asarray(las.classification),
        "scan_angle": np.asarray(las.scan_angle),
        "user_data": np.asarray(las.user_data),
        "point_source_id": np.asarray(las.point_source_id),
        "gps_time": np.asarray(las.gps_time),
        "scanner_channel": np.asarray(las.scanner_channel),
        "scan_direction_flag": np.asarray(las.scan_direction_flag),
        "edge_of_flight_line": np.asarray(las.edge_of_flight_line),
        "synthetic": np.asarray(las.synthetic),
        "key_point": np.asarray(las.key_point),
        "withheld": np.asarray(las.withheld),
        "overlap": np.asarray(las.overlap),
    }
    t.xmin, t.xmax, t.ymin, t.ymax = x.min(), x.max(), y.min(), y.max()
    t.cx, t.cy = (t.xmin + t.xmax) / 2, (t.ymin + t.ymax) / 2
    # copies are laid out on a grid of this pitch: the tile extent plus one 1 cm LAS step
    t.size = math.ceil(round(max(t.xmax - t.xmin, t.ymax - t.ymin) * 100, 3)) / 100.0 + 0.01
    u, v = x - t.cx, y - t.cy
    cls = t.fields["classification"].astype(int)
    t.cls = cls
    t.ground = np.isin(cls, GROUND_CLASSES)
    t.phys = ~(np.isin(cls, EXCLUDED_CLASSES) | (cls >= 19))
    g = t.ground & t.phys
    if g.sum() < 50:
        raise SystemExit(f"{path}: too few ground points")
    A = np.c_[np.ones(g.sum()), u[g], v[g]]
    t.plane = np.linalg.lstsq(A, z[g], rcond=None)[0]       # p0, pu, pv
    zd = z - (t.plane[0] + t.plane[1] * u + t.plane[2] * v)  # detrended heights
    t.u, t.v, t.zd = u, v, zd
    # residual DTM (1 m grid) from ground points, holes filled by neighbour means
    res = 1.0
    half = t.size / 2
    nx = int(math.ceil(t.size / res)) + 1
    t.dtm_res, t.dtm_x0, t.dtm_n = res, -half, nx
    ix = np.clip(((u[g] + half) / res).astype(int), 0, nx - 1)
    iy = np.clip(((v[g] + half) / res).astype(int), 0, nx - 1)
    s = np.zeros((nx, nx))
    n = np.zeros((nx, nx))
    np.add.at(s, (ix, iy), zd[g])
    np.add.at(n, (ix, iy), 1)
    dtm = np.where(n > 0, s / np.maximum(n, 1), np.nan)
    for _ in range(500):
        m = np.isnan(dtm)
        if not m.any():
            break
        p = np.pad(dtm, 1, constant_values=np.nan)
        stack = np.stack([p[1 + a:1 + a + nx, 1 + b:1 + b + nx]
                          for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)])
        cnt = np.sum(~np.isnan(stack), 0)
        mean = np.nansum(stack, 0) / np.maximum(cnt, 1)
        fill = m & (cnt > 0)
        dtm[fill] = mean[fill]
    t.dtm = np.nan_to_num(dtm, nan=0.0)       # cell centres at -half + (i+0.5)*res
    t.h = zd - _dtm_interp(t, u, v)
    # density weights: each pulse carries 1/number_of_returns of its energy; each 2 m cell gets
    # the same total weight whatever its pulse density. A pulse is counted once, in the cell of its
    # first return, and all its returns share that cell's count: a pulse's returns lie metres apart
    # on a slanted ALS ray, and dividing each return by the count of its own cell (our first
    # choice) weighed ground returns up by 4-8 % in the ground/canopy odds (see README, "Density").
    dres = 2.0
    nd = int(math.ceil(t.size / dres)) + 1
    dx_ = np.clip(((u + half) / dres).astype(int), 0, nd - 1)
    dy_ = np.clip(((v + half) / dres).astype(int), 0, nd - 1)
    first = t.fields["return_number"] == 1
    pulse_key = np.rec.fromarrays([t.fields["gps_time"], t.fields["point_source_id"],
                                   t.fields["scanner_channel"]])
    _, pid = np.unique(pulse_key, return_inverse=True)
    pid = pid.ravel()
    # the pulse's cell: its first return's, or (first return missing) its earliest return's
    order = np.lexsort((t.fields["return_number"], pid))
    lead = order[np.r_[0, np.flatnonzero(np.diff(pid[order])) + 1]]   # one per pulse, by pulse id
    pcell = dx_[lead] * nd + dy_[lead]
    cnt = np.bincount(pcell, minlength=nd * nd)
    ncell = cnt[pcell][pid]
    nret = np.maximum(t.fields["number_of_returns"].astype(float), 1.0)
    t.bw = (1.0 / nret) / np.maximum(ncell, 1.0)
    t.first = first
    gps = t.fields["gps_time"]
    t.date = gps_to_datetime(np.median(gps))
    t.npoints = len(x)
    _TILE_CACHE[path] = t
    return t


def _dtm_interp(t, u, v):
    """Bilinear interpolation of the tile's residual DTM at local coordinates (u, v)."""
    fx = (np.asarray(u) - t.dtm_x0) / t.dtm_res - 0.5
    fy = (np.asarray(v) - t.dtm_x0) / t.dtm_res - 0.5
    n = t.dtm_n
    fx = np.clip(fx, 0, n - 1.000001)
    fy = np.clip(fy, 0, n - 1.000001)
    i0 = np.floor(fx).astype(int)
    j0 = np.floor(fy).astype(int)
    ax = fx - i0
    ay = fy - j0
    i1 = np.minimum(i0 + 1, n - 1)
    j1 = np.minimum(j0 + 1, n - 1)
    d = t.dtm
    return ((1 - ax) * (1 - ay) * d[i0, j0] + ax * (1 - ay) * d[i1, j0]
            + (1 - ax) * ay * d[i0, j1] + ax * ay * d[i1, j1])


def collect_tile_paths(spec):
    out = []
    for s in spec:
        if os.path.isdir(s):
            out += sorted(glob.glob(os.path.join(s, "*.laz")) + glob.glob(os.path.join(s, "*.las")))
        else:
            out.append(s)
    out = sorted(set(os.path.abspath(p) for p in out))
    if not out:
        raise SystemExit("no ALS tiles found in --tiles")
    return out


# --------------------------------------------------------------------------------------------
# Scene (mosaic)
# --------------------------------------------------------------------------------------------
def _rot(u, v, k):
    k %= 4
    if k == 0:
        return u, v
    if k == 1:
        return -v, u
    if k == 2:
        return -u, -v
    return v, -u


class Scene:
    pass


def build_scene(tiles, seed, grid, tile_mode, slope_deg):
    rng = rng_for(seed, "scene")
    # round-robin over the sorted tiles, so consecutive seeds use different tiles
    primary = sorted(tiles, key=lambda t: t.name)[(seed - 1) % len(tiles)]
    if tile_mode == "mix":
        pool = [t for t in tiles if abs(t.size - primary.size) < 1.0]
    else:
        pool = [primary]
    cell = primary.size
    N = grid if grid else int(math.ceil(450.0 / cell))
    if N * cell < 300:
        print(f"warning: mosaic only {N * cell:.0f} m across", file=sys.stderr)
    sc = Scene()
    sc.cell, sc.N, sc.primary = cell, N, primary
    sc.X0 = math.floor(primary.xmin)
    sc.Y0 = math.floor(primary.ymin)
    sc.size = N * cell
    sc.Xm, sc.Ym = sc.X0 + sc.size / 2, sc.Y0 + sc.size / 2
    if slope_deg is None:
        slope_deg = float(rng.uniform(1.0, 4.0))
        slope_az = float(rng.uniform(0, 360))
    else:
        rng.uniform(1.0, 4.0)
        slope_az = float(rng.uniform(0, 360))
    sc.slope_deg, sc.slope_az = slope_deg, slope_az
    g = math.tan(math.radians(slope_deg))
    sc.sx = g * math.sin(math.radians(slope_az))   # dz/dX (uphill azimuth from north)
    sc.sy = g * math.cos(math.radians(slope_az))
    sc.zbase = float(primary.plane[0])
    sc.copies = []
    for i in range(N):
        for j in range(N):
            src = pool[int(rng.integers(len(pool)))]
            k = int(rng.integers(4))
            mirror = bool(rng.integers(2))
            sc.copies.append({"i": i, "j": j, "tile": src, "rot": k, "mirror": mirror,
                              "cx": sc.X0 + (i + 0.5) * cell, "cy": sc.Y0 + (j + 0.5) * cell})
    # physics arrays in mosaic-local coordinates (x - X0, y - Y0), quantised to the LAS 0.01 m grid
    xs, ys, zs, bws, gs, hs, fs = [], [], [], [], [], [], []
    for c in sc.copies:
        t = c["tile"]
        X, Y, Z = copy_coords(sc, c, np.arange(t.npoints))
        m = t.phys
        xs.append((X[m] - sc.X0).astype(np.float32))
        ys.append((Y[m] - sc.Y0).astype(np.float32))
        zs.append(Z[m].astype(np.float32))
        bws.append(t.bw[m].astype(np.float32))
        gs.append(t.ground[m])
        hs.append(t.h[m].astype(np.float32))
        fs.append(t.first[m])
    x = np.concatenate(xs)
    y = np.concatenate(ys)
    gcell = 10.0
    ng = int(math.ceil(sc.size / gcell)) + 1
    ci = np.clip((x / gcell).astype(int), 0, ng - 1) * ng + np.clip((y / gcell).astype(int), 0, ng - 1)
    order = np.argsort(ci, kind="stable")
    sc.px = x[order]
    sc.py = y[order]
    sc.pz = np.concatenate(zs)[order]
    sc.pbw = np.concatenate(bws)[order]
    sc.pg = np.concatenate(gs)[order]
    sc.ph = np.concatenate(hs)[order]
    sc.pfirst = np.concatenate(fs)[order]
    ci = ci[order]
    sc.gcell, sc.ng = gcell, ng
    sc.cstart = np.searchsorted(ci, np.arange(ng * ng), side="left")
    sc.cend = np.searchsorted(ci, np.arange(ng * ng), side="right")
    return sc


def copy_coords(sc, c, idx):
    """World coordinates (EPSG:2154, quantised to 0.01 m) of points idx of copy c."""
    t = c["tile"]
    u, v = t.u[idx], t.v[idx]
    if c["mirror"]:
        u = -u
    u2, v2 = _rot(u, v, c["rot"])
    X = np.round((c["cx"] + u2) * 100) / 100
    Y = np.round((c["cy"] + v2) * 100) / 100
    Z = t.zd[idx] + sc.zbase + sc.sx * (X - sc.Xm) + sc.sy * (Y - sc.Ym)
    Z = np.round(Z * 100) / 100
    return X, Y, Z


def ground_at(sc, X, Y):
    """ALS ground (orthometric, m) of the mosaic at world coordinates X, Y."""
    X = np.atleast_1d(np.asarray(X, float))
    Y = np.atleast_1d(np.asarray(Y, float))
    i = np.clip(((X - sc.X0) / sc.cell).astype(int), 0, sc.N - 1)
    j = np.clip(((Y - sc.Y0) / sc.cell).astype(int), 0, sc.N - 1)
    ci = i * sc.N + j
    out = np.empty_like(X)
    for cidx in np.unique(ci):
        m = ci == cidx
        c = sc.copies[int(cidx)]
        u, v = _rot(X[m] - c["cx"], Y[m] - c["cy"], -c["rot"])
        if c["mirror"]:
            u = -u
        out[m] = _dtm_interp(c["tile"], u, v)
    return out + sc.zbase + sc.sx * (X - sc.Xm) + sc.sy * (Y - sc.Ym)


def footprint_ground(sc, x, y, fsigma):
    """Gaussian-footprint-weighted mean ALS ground around (x, y)."""
    o = np.linspace(-2.5, 2.5, 11) * fsigma
    gx, gy = np.meshgrid(o, o)
    w = np.exp(-(gx ** 2 + gy ** 2) / (2 * fsigma ** 2)).ravel()
    z = ground_at(sc, x + gx.ravel(), y + gy.ravel())
    return float((w * z).sum() / w.sum())


def points_near(sc, x, y, r):
    """Indices of physics points within the 10 m cells overlapping a disc (local coords)."""
    i0 = max(0, int((x - r) / sc.gcell))
    i1 = min(sc.ng - 1, int((x + r) / sc.gcell))
    j0 = max(0, int((y - r) / sc.gcell))
    j1 = min(sc.ng - 1, int((y + r) / sc.gcell))
    parts = []
    for i in range(i0, i1 + 1):
        a = sc.cstart[i * sc.ng + j0]
        b = sc.cend[i * sc.ng + j1]
        if b > a:
            parts.append(np.arange(a, b))
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def write_als(sc, outdir, date):
    import laspy
    os.makedirs(outdir, exist_ok=True)
    B = max(1, int(round(200.0 / sc.cell)))
    files = []
    for bi in range(0, sc.N, B):
        for bj in range(0, sc.N, B):
            members = [c for c in sc.copies if bi <= c["i"] < bi + B and bj <= c["j"] < bj + B]
            if not members:
                continue
            Xs, Ys, Zs, F = [], [], [], {k: [] for k in members[0]["tile"].fields}
            for c in members:
                t = c["tile"]
                X, Y, Z = copy_coords(sc, c, np.arange(t.npoints))
                Xs.append(X)
                Ys.append(Y)
                Zs.append(Z)
                for k in F:
                    F[k].append(t.fields[k])
            X = np.concatenate(Xs)
            Y = np.concatenate(Ys)
            Z = np.concatenate(Zs)
            hdr = laspy.LasHeader(point_format=6, version="1.4")
            hdr.scales = np.array([0.01, 0.01, 0.01])
            xmin = sc.X0 + bi * sc.cell
            ymin = sc.Y0 + bj * sc.cell
            hdr.offsets = np.array([math.floor(xmin / 1000) * 1000.0, math.floor(ymin / 1000) * 1000.0, 0.0])
            hdr.vlrs.append(sc.primary.crs_vlr)
            hdr.global_encoding.wkt = True
            # the source GPS times exceed one week: they are adjusted standard GPS time
            hdr.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
            hdr.system_identifier = "worldgen"
            hdr.generating_software = GENERATOR
            hdr.creation_date = date.date()
            las = laspy.LasData(hdr)
            las.x = X
            las.y = Y
            las.z = Z
            for k, arrs in F.items():
                setattr(las, k, np.concatenate(arrs))
            name = f"als_{int(round(xmin)):07d}_{int(round(ymin)):07d}.laz"
            final = os.path.join(outdir, name)
            tmp = final + ".tmp"
            las.write(tmp, do_compress=True)
            os.replace(tmp, final)
            files.append(name)
    return files


# --------------------------------------------------------------------------------------------
# Tracks
# --------------------------------------------------------------------------------------------
HIBERNATION = (_dt.datetime(2023, 3, 17, tzinfo=_dt.timezone.utc),
               _dt.datetime(2024, 4, 26, tzinfo=_dt.timezone.utc))
GEDI_START = _dt.datetime(2019, 4, 1, tzinfo=_dt.timezone.utc)
ORBIT_REF = (_dt.datetime(2019, 4, 18, 8, 3, 38, tzinfo=_dt.timezone.utc), 1964)
ORBIT_PERIOD_S = 92.68 * 60


def draw_pass_date(rng, als_date):
    """A GEDI acquisition date within a year of the ALS date, outside GEDI's storage period.
    3 passes in 4 fall in the ALS's own leaf season (leaf_off rule), the others in the other."""
    als_off = leaf_off(als_date.timetuple().tm_yday)
    want_same = rng.uniform() < 0.75
    for _ in range(5000):
        d = als_date + _dt.timedelta(days=float(rng.uniform(-365, 365)))
        d = d.replace(hour=0, minute=0, second=0, microsecond=0) + _dt.timedelta(seconds=float(rng.uniform(0, 86400)))
        if d < GEDI_START or HIBERNATION[0] <= d < HIBERNATION[1]:
            continue
        if d > _dt.datetime(2026, 1, 1, tzinfo=_dt.timezone.utc):
            continue
        if (leaf_off(d.timetuple().tm_yday) == als_off) != want_same:
            continue
        return d
    raise SystemExit("could not draw a GEDI date near the ALS date")


def plan_passes(sc, seed, npass, phys):
    rng = rng_for(seed, "tracks")
    heads = [61.0, 119.0, 241.0, 299.0]
    hord = [heads[int(i)] for i in rng.permutation(4)]
    passes = []
    margin = 2 * max(FOOTPRINT_MARGIN_SIGMA, phys.fsigma) + 1.0
    used_orbits = set()
    for p in range(npass):
        heading = hord[p % 4] + float(rng.uniform(-4, 4))
        date = draw_pass_date(rng, sc.als_date)
        orbit = ORBIT_REF[1] + int((date - ORBIT_REF[0]).total_seconds() // ORBIT_PERIOD_S)
        while orbit in used_orbits:
            orbit += 1
        used_orbits.add(orbit)
        spacing = float(rng.uniform(40, 55))
        shift = float(rng.uniform(-25, 25))
        theta0 = float(rng.uniform(0.3, 1.4))         # off-nadir angle (deg)
        side = 1.0 if rng.uniform() < 0.5 else -1.0   # instrument left/right of the track
        az_jit = float(rng.normal(0, 10))
        s_phase = float(rng.uniform(0, SHOT_SPACING_M))
        sub = int(rng.integers(1, 5))
        track_no = int(rng.integers(1000, 9999))
        gstart = date - _dt.timedelta(seconds=float(rng.uniform(180, 1200)))
        h = math.radians(heading)
        a = np.array([math.sin(h), math.cos(h)])      # along-track (E, N)
        cr = np.array([math.cos(h), -math.sin(h)])    # cross-track, to the right
        inst_az = (heading + 90.0 * side + az_jit) % 360.0
        beams = []
        for k, beam in enumerate(BEAM_ORDER):
            brng = rng_for(seed, "track", p, k)
            dx, dy = np.clip(brng.normal(0, 3.0, 2), -7.5, 7.5)
            theta = max(0.05, theta0 + side * (k - 3.5) * 0.08 + float(brng.normal(0, 0.03)))
            along_off = float(brng.uniform(-5, 5))
            off = (k - 3.5) * spacing + shift
            beams.append({"beam": beam, "k": k, "off": off, "dx": float(dx), "dy": float(dy),
                          "theta": theta, "along_off": along_off})
        passes.append({"p": p, "heading": heading, "date": date, "orbit": orbit, "sub": sub,
                       "track_no": track_no, "gstart": gstart, "a": a, "cr": cr,
                       "inst_az": inst_az, "s_phase": s_phase, "beams": beams})
    # extra geolocation offsets of the geolocation effect (own stream)
    for ps in passes:
        for b in ps["beams"]:
            erng = rng_for(seed, "effect-geolocation", ps["p"], b["k"])
            b["extra_beam"] = erng.normal(0, 1.0, 2) * (phys.geo_sigma if phys.geo_level == "beam" else 0.0)
            b["erng"] = erng
    # shots
    half_diag = sc.size * 0.75
    ctr = np.array([sc.size / 2, sc.size / 2])
    v_ground = SHOT_SPACING_M / SHOT_DT
    for ps in passes:
        for b in ps["beams"]:
            shots = []
            base = ctr + b["off"] * ps["cr"]
            kmin = int(math.floor((-half_diag - ps["s_phase"]) / SHOT_SPACING_M))
            kmax = int(math.ceil((half_diag - ps["s_phase"]) / SHOT_SPACING_M))
            for ks in range(kmin, kmax + 1):
                s = ps["s_phase"] + b["along_off"] + ks * SHOT_SPACING_M
                xr, yr = base + s * ps["a"]
                ex = np.zeros(2)
                if phys.geo_level == "shot":
                    ex = b["erng"].normal(0, phys.geo_sigma, 2)
                elif phys.geo_level == "beam":
                    ex = b["extra_beam"]
                xt = xr + b["dx"] + ex[0]
                yt = yr + b["dy"] + ex[1]
                # keep the shot if the footprint is inside the mosaic at the reported and at the
                # base true position with the effect-independent margin (same shot set for every
                # effect of a seed), and at the final true position with 2*sigma_f + 1 m
                xb, yb = xr + b["dx"], yr + b["dy"]
                ok = all(margin <= q <= sc.size - margin for q in (xr, yr, xb, yb))
                m2 = 2 * phys.fsigma + 1.0
                ok = ok and all(m2 <= q <= sc.size - m2 for q in (xt, yt))
                if not ok:
                    continue
                shots.append({"ks": ks, "s": s, "xr": xr, "yr": yr, "xt": xt, "yt": yt,
                              "ex": ex, "t_rel": s / v_ground})
            b["shots"] = shots
    return passes


# --------------------------------------------------------------------------------------------
# Waveform simulation
# --------------------------------------------------------------------------------------------
def make_shot_pulse(rng, lib_group):
    """Per-shot transmit pulse: a real shape with a time-scale jitter, as a continuous function of
    the sample coordinate of the 128-sample tx record (linear interpolation of the real shape)."""
    L = lib_group[int(rng.integers(len(lib_group)))]
    eps = float(np.clip(rng.normal(0, 0.03), -0.08, 0.08))
    c0 = float(rng.uniform(54.5, 60.5))
    amp = L["amp"] * float(1 + np.clip(rng.normal(0, 0.03), -0.1, 0.1))
    grid = np.arange(TX_SAMPLES, dtype=float)

    def P(tau):
        src = (np.asarray(tau, float) - c0) / (1 + eps) + L["mu"]
        return np.interp(src, grid, L["shape"], left=0.0, right=0.0)

    return P, eps, c0, amp, L["src"]


def colored_noise(rng, n, sigma_k=NOISE_CORR_SIGMA):
    k = gauss_kernel(sigma_k)
    k = k / math.sqrt((k ** 2).sum())      # unit output variance
    h = len(k) // 2
    w = rng.standard_normal(n + 2 * h)
    return np.convolve(w, k, mode="valid")


def simulate_shot(sc, phys, pref, shot, beam, ps, geoid, lib, seed):
    """Form the received waveform of one shot and its L1B record."""
    bnum, chan, btype, lgroup, mu_beam, sdc_beam = BEAMS[beam["beam"]]
    rng = rng_for(seed, "shot", ps["p"], beam["k"], shot["ks"])
    # --- pulse
    P, eps, c0, tx_amp, tx_src = make_shot_pulse(rng, lib[lgroup])
    tx_clean = P(np.arange(TX_SAMPLES, dtype=float))
    peak_s, cen_s, gf_s = pulse_reference_points(tx_clean)
    mu_tx = mu_beam + float(rng.normal(0, 0.4))
    txrec = mu_tx + tx_amp * tx_clean + TX_NOISE_SD * colored_noise(rng, TX_SAMPLES)
    txrec = np.clip(txrec, 0, ADC_MAX).astype(np.float32)
    txfit = gfit(txrec.astype(float))
    if pref == "peak":
        tau_ref = peak_s
    elif pref == "centroid":
        tau_ref = cen_s
    else:
        tau_ref = float(np.float32(txfit[1]))   # exactly the stored tx_gloc
    # --- geometry: ray direction (unit, pointing down), instrument azimuth seen from the ground
    th = math.radians(beam["theta"])
    az = math.radians(ps["inst_az"])
    e_az = np.array([math.sin(az), math.cos(az)])
    d = np.array([-math.sin(th) * e_az[0], -math.sin(th) * e_az[1], -math.cos(th)])
    zg_rep = float(ground_at(sc, sc.X0 + shot["xr"], sc.Y0 + shot["yr"])[0])
    Gt = np.array([shot["xt"], shot["yt"], zg_rep])
    # --- ALS points around the true ray
    fs = phys.fsigma
    R = 3.5 * fs + 2.0
    idx = points_near(sc, shot["xt"], shot["yt"], R)
    qx = sc.px[idx].astype(float) - Gt[0]
    qy = sc.py[idx].astype(float) - Gt[1]
    qz = sc.pz[idx].astype(float) - Gt[2]
    r = qx * d[0] + qy * d[1] + qz * d[2]                    # range beyond Gt along the ray
    perp2 = np.maximum(qx * qx + qy * qy + qz * qz - r * r, 0.0)
    sel = perp2 < R * R
    idx, r, perp2 = idx[sel], r[sel], perp2[sel]
    gfoot = np.exp(-perp2 / (2 * fs * fs))
    isg = sc.pg[idx]
    hgt = sc.ph[idx].astype(float)
    base_w = sc.pbw[idx].astype(float) * gfoot
    mult = np.ones_like(base_w)
    if phys.canopy_change is not None:
        hc, frac = phys.canopy_change
        mult[(~isg) & (hgt > hc)] *= (1.0 - frac)
    if phys.occlusion is not None:
        ho, gain = phys.occlusion
        mult[(~isg) & (hgt > 0.5) & (hgt <= ho)] *= (1.0 + gain)
    rho = np.where(isg, phys.rho_g, phys.rho_v)
    W = base_w * rho * mult
    Wref = base_w.sum()
    if W.sum() <= 0 or Wref <= 0:
        return None
    # canopy cover seen by the footprint (first returns > 5 m)
    fr = sc.pfirst[idx]
    cover = float((base_w[fr] * (hgt[fr] > 5.0)).sum() / max(base_w[fr].sum(), 1e-12))
    # --- record window, from the true surface inside 2 sigma
    core = perp2 < (2 * fs) ** 2
    r_top = float(r[core].min()) if core.any() else float(r.min())
    gcore = core & isg
    r_bot = float(r[gcore].max()) if gcore.any() else float(r[core].max() if core.any() else r.max())
    m_top = float(rng.uniform(*TOP_MARGIN_M))
    m_bot = float(rng.uniform(*BOT_MARGIN_M))
    r_bin0 = r_top - m_top
    n = int(round((r_bot + m_bot - r_bin0) / BIN_M)) + 1
    n = int(np.clip(n, 600, 2400))
    # --- surface response on a 1/8-sample grid, convolved with the shot's own pulse
    OV = 8
    K = P(np.arange(TX_SAMPLES * OV) / OV)
    Rf = tau_ref * OV
    if phys.pulse_sigma_m > 0:
        gk = gauss_kernel(phys.pulse_sigma_m / BIN_M * OV)
        K = np.convolve(K, gk)
        Rf += len(gk) // 2
    Ri = int(math.floor(Rf))
    Rfrac = Rf - Ri
    f = (r - r_bin0) / BIN_M * OV - Rfrac
    keep = (f >= 0) & (f < n * OV - 1)
    f, Wk = f[keep], W[keep]
    i0 = np.floor(f).astype(np.int64)
    a = f - i0
    L = n * OV + 2
    H = np.bincount(i0, weights=Wk * (1 - a), minlength=L)[:L] + \
        np.bincount(i0 + 1, weights=Wk * a, minlength=L)[:L]
    nfft = 1 << int(math.ceil(math.log2(L + len(K))))
    Cv = np.fft.irfft(np.fft.rfft(H, nfft) * np.fft.rfft(K, nfft), nfft)
    tidx = np.arange(n) * OV + Ri
    S = np.where(tidx < len(Cv), Cv[np.minimum(tidx, len(Cv) - 1)], 0.0)
    S = np.clip(S, 0, None)
    E_sig = E_MEDIAN[btype] * math.exp(float(rng.normal(0, E_LOGSD))) * (W.sum() / Wref)
    if S.sum() <= 0:
        return None
    S *= E_sig / S.sum()
    # --- noise and digitiser
    mu = mu_beam + float(rng.normal(0, 0.3))
    sdc = sdc_beam * (1 + float(np.clip(rng.normal(0, 0.04), -0.12, 0.12)))
    sdc_used = sdc * phys.noise_factor
    sd_rec = sdc_used / NOISE_SD_RATIO
    cn = colored_noise(rng, n)
    kappa = SHOT_NOISE_KAPPA * phys.noise_factor ** 2
    w = mu + S + np.sqrt(sd_rec ** 2 + kappa * S) * cn
    clipped = int((w >= ADC_MAX).sum())
    w = np.clip(w, 0, ADC_MAX).astype(np.float32)
    eo = float(rng.normal(0, 0.8))
    # --- geolocation of the record (reported ray)
    Gr = np.array([shot["xr"], shot["yr"], zg_rep])
    P0 = Gr + r_bin0 * d
    PN = Gr + (r_bin0 + (n - 1) * BIN_M) * d
    rng_inst = (ISS_ALT - P0[2]) / math.cos(th)
    inst = P0 - rng_inst * d
    rec = {
        "n": n, "rx": w, "tx": txrec, "noise_mean": mu, "noise_sd": sdc_used,
        "nse_even": round((mu + eo / 2) * 16) / 16, "nse_odd": round((mu - eo / 2) * 16) / 16,
        "rx_energy": float((w.astype(float) - mu).sum()), "clipped": clipped,
        "P0": P0, "PN": PN, "inst": inst, "d": d, "theta": th, "az": az,
        "r_bin0": r_bin0, "zg_rep": zg_rep, "txfit": txfit, "cover": cover,
        "pulse": {"src": tx_src, "time_scale": 1 + eps, "center_sample": c0, "amp_dn": tx_amp,
                  "peak_sample": peak_s, "centroid_sample": cen_s, "gfit_sample": gf_s,
                  "tx_gloc": float(np.float32(txfit[1])), "reference_sample": tau_ref},
        "E_sig": E_sig, "ground_frac": float(W[isg].sum() / W.sum()),
        # elevation (ALS frame) on the ray at the W-weighted mean range of all returns
        "return_centroid_elev": zg_rep - float((W * r).sum() / W.sum()) * math.cos(th),
        "dem_err": float(rng.normal(0, 2.0)), "dem_srtm_err": float(rng.normal(0, 3.0)),
    }
    return rec


# --------------------------------------------------------------------------------------------
# Our own L2A-like processing
# --------------------------------------------------------------------------------------------
def _q(x):
    return round(x * 4) / 4.0


def _runs(mask):
    """(start, end) inclusive index pairs of True runs."""
    if not mask.any():
        return []
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    st = np.where(d == 1)[0]
    en = np.where(d == -1)[0] - 1
    return list(zip(st, en))


def l2a_process(w, mu, sdc, alg):
    """Returns positions (0-based fractional samples) and metrics of one algorithm."""
    p = ALGS[alg]
    n = len(w)
    w = w.astype(float)
    ws = smooth(w, p["sig_locs"])
    wz = smooth(w, p["sig_modes"])
    thr_f = mu + p["k_front"] * sdc
    thr_b = mu + p["k_back"] * sdc
    out = {"ok": False, "thr_f": thr_f, "thr_b": thr_b, "ws": ws, "wz": wz,
           "search_start": GUARD, "search_end": n - 1 - GUARD}
    lo, hi = GUARD, n - 1 - GUARD
    rf = [(a, b) for a, b in _runs(ws[lo:hi + 1] > thr_f) if b - a >= 2]
    rb = [(a, b) for a, b in _runs(ws[lo:hi + 1] > thr_b) if b - a >= 2]
    if not rf or not rb:
        return out
    i = rf[0][0] + lo
    top = i - 1 + (thr_f - ws[i - 1]) / (ws[i] - ws[i - 1]) if ws[i] != ws[i - 1] else float(i)
    e = rb[-1][1] + lo
    bot = e + (ws[e] - thr_b) / (ws[e] - ws[e + 1]) if ws[e] != ws[e + 1] else float(e)
    top, bot = _q(top), _q(bot)
    if bot <= top + 1:
        return out
    a0, b0 = int(math.ceil(top)), int(math.floor(bot))
    seg = wz[a0:b0 + 1]
    cand = [j for j in range(1, len(seg) - 1)
            if seg[j] > seg[j - 1] and seg[j] >= seg[j + 1] and seg[j] >= thr_b]
    modes = []
    for j in cand:
        pk = seg[j]
        l = j
        while l > 0 and seg[l - 1] <= pk:
            l -= 1
        left_base = seg[l:j + 1].min()
        rr = j
        while rr < len(seg) - 1 and seg[rr + 1] <= pk:
            rr += 1
        right_base = seg[j:rr + 1].min()
        if pk - max(left_base, right_base) >= K_PROMINENCE * sdc or (l == 0 and rr == len(seg) - 1):
            den = seg[j - 1] - 2 * seg[j] + seg[j + 1]
            off = 0.5 * (seg[j - 1] - seg[j + 1]) / den if den != 0 else 0.0
            modes.append((_q(a0 + j + off), float(pk)))
    if not modes:
        return out
    modes = modes[:20]
    zc, zamp = modes[-1]
    # cumulative energy of the mode-smoothed waveform above the noise mean, from botloc upward
    grid = np.arange(top, bot + 1e-9, 0.25)
    vals = np.clip(np.interp(grid, np.arange(n), wz) - mu, 0, None)
    rv = vals[::-1]
    cum = np.cumsum(rv)
    tot = cum[-1]
    if tot <= 0:
        return out
    frac = cum / tot
    pos_rev = grid[::-1]
    kk = np.arange(101) / 100.0
    cpos = np.interp(kk, np.concatenate([[0.0], frac]), np.concatenate([[pos_rev[0]], pos_rev]))
    cpos[0], cpos[100] = bot, top
    # energy of the lowest mode: from the valley above it down to botloc
    zi = int(round(zc))
    if len(modes) > 1:
        up = int(round(modes[-2][0]))
        valley = up + int(np.argmin(wz[up:zi + 1]))
    else:
        valley = a0
    lme = float(np.clip(wz[valley:b0 + 1] - mu, 0, None).sum())
    sig_eff = math.sqrt(NOMINAL_PULSE_SIGMA ** 2 + p["sig_modes"] ** 2)
    mdt = p["k_back"] * sdc
    out.update(ok=True, top=top, bot=bot, zcross=zc, zamp=zamp, modes=modes, cum=cpos,
               lme=lme, mdt=mdt, mde=mdt * math.sqrt(2 * math.pi) * sig_eff,
               pk_sm=float(ws.max()), peak=float(w.max()), botloc_amp=float(np.interp(bot, np.arange(n), ws)))
    return out


# --------------------------------------------------------------------------------------------
# Output helpers
# --------------------------------------------------------------------------------------------
def _sattr(obj, name, value):
    import h5py
    obj.attrs.create(name, np.array([value], dtype=h5py.string_dtype()))


def _ds(g, name, data, dtype, shape=None):
    a = np.asarray(data, dtype=dtype)
    if shape is not None:
        a = a.reshape(shape)
    kw = {}
    if a.size > 32:
        kw = dict(compression="gzip", compression_opts=4, chunks=True)
    g.create_dataset(name, data=a, **kw)


def solar_position(when, lat, lon):
    doy = when.timetuple().tm_yday
    hour = when.hour + when.minute / 60 + when.second / 3600
    g = 2 * math.pi / 365 * (doy - 1 + (hour - 12) / 24)
    decl = (0.006918 - 0.399912 * math.cos(g) + 0.070257 * math.sin(g) - 0.006758 * math.cos(2 * g)
            + 0.000907 * math.sin(2 * g) - 0.002697 * math.cos(3 * g) + 0.00148 * math.sin(3 * g))
    eqt = 229.18 * (0.000075 + 0.001868 * math.cos(g) - 0.032077 * math.sin(g)
                    - 0.014615 * math.cos(2 * g) - 0.040849 * math.sin(2 * g))
    tst = hour * 60 + eqt + 4 * lon
    ha = math.radians(tst / 4 - 180)
    la = math.radians(lat)
    cz = math.sin(la) * math.sin(decl) + math.cos(la) * math.cos(decl) * math.cos(ha)
    elev = 90 - math.degrees(math.acos(max(-1, min(1, cz))))
    az = math.degrees(math.atan2(math.sin(ha), math.cos(ha) * math.sin(la) - math.tan(decl) * math.cos(la))) + 180
    return az % 360, elev


def _atomic_h5(path):
    import h5py
    tmp = path + ".tmp"
    if os.path.exists(tmp):
        os.remove(tmp)
    return h5py.File(tmp, "w", libver="earliest", track_order=False), tmp


def _beam_group(f, beam, btype, software):
    """A beam group with its description and the processing software's attributes."""
    G = f.create_group(beam)
    _sattr(G, "description", "Coverage beam" if btype == "coverage" else "Full power beam")
    _sattr(G, software + "_githash", "0" * 40)
    _sattr(G, software + "_version", "worldgen-" + VERSION)
    return G


def _metadata(f, short, fname, pge, created, uid, abstract):
    md = f.create_group("METADATA").create_group("DatasetIdentification")
    for k, v in [("PGEVersion", pge), ("VersionID", "002"), ("abstract", abstract),
                 ("characterSet", "utf8"), ("creationDate", created),
                 ("credit", "SYNTHETIC granule written by " + GENERATOR + " (not a NASA product)."),
                 ("fileName", fname), ("language", "eng"),
                 ("originatorOrganizationName", "worldgen (synthetic test data)"),
                 ("purpose", "Synthetic GEDI-like test granule simulated from airborne lidar; see truth.json."),
                 ("shortName", short), ("spatialRepresentationType", "along-track"),
                 ("status", "onGoing"), ("topicCategory", "geoscientificInformation"), ("uuid", uid)]:
        _sattr(md, k, v)


def leaf_off(doy):
    return 1 if (doy >= 305 or doy < 110) else 0


def write_granule(outdir, gran, geoid, phys, seed):
    """Write the L1B and L2A files of one pass."""
    l1name, l2name = gran["l1b"], gran["l2a"]
    grng = rng_for(seed, "granule-meta", gran["p"])
    created = (gran["date"] + _dt.timedelta(days=30)).strftime("%Y-%m-%dT%H:%M:%S.000000Z")
    uid1 = str(uuid.UUID(int=int(grng.integers(0, 2 ** 63)) << 64 | int(grng.integers(0, 2 ** 63)), version=4))
    uid2 = str(uuid.UUID(int=int(grng.integers(0, 2 ** 63)) << 64 | int(grng.integers(0, 2 ** 63)), version=4))
    tides = {"tide_earth": float(grng.normal(0, 0.12)), "tide_load": float(grng.normal(0, 0.01)),
             "dynamic_atmosphere_correction": float(grng.normal(0, 0.01)),
             "tide_pole": float(grng.normal(0, 0.0005)), "tide_ocean_pole": float(grng.normal(0, 0.00003))}
    # ---------------- L1B
    f, tmp1 = _atomic_h5(os.path.join(outdir, l1name))
    _sattr(f, "short_name", "GEDI_L1B")
    _metadata(f, "GEDI_L1B", l1name, "005", created, uid1,
              "SYNTHETIC GEDI L1B-like geolocated waveforms (worldgen).")
    for beam, shots in gran["beams"]:
        bnum, chan, btype, _, _, _ = BEAMS[beam]
        N = len(shots)
        G = _beam_group(f, beam, btype, "wp-l1a-to-l1b")
        R = [s["rec"] for s in shots]
        cnt = np.array([r["n"] for r in R])
        start = np.concatenate([[1], 1 + np.cumsum(cnt)[:-1]])
        dt = np.array([s["delta_time"] for s in shots])
        mi = np.floor(dt)
        sn = np.array([s["shot_number"] for s in shots], dtype=np.uint64)
        _ds(G, "shot_number", sn, np.uint64)
        _ds(G, "beam", np.full(N, bnum), np.uint16)
        _ds(G, "channel", np.full(N, chan), np.uint8)
        _ds(G, "delta_time", dt, np.float64)
        _ds(G, "master_int", mi, np.uint32)
        _ds(G, "master_frac", dt - mi, np.float64)
        _ds(G, "rxwaveform", np.concatenate([r["rx"] for r in R]), np.float32)
        _ds(G, "rx_sample_count", cnt, np.uint16)
        _ds(G, "rx_sample_start_index", start, np.uint64)
        _ds(G, "txwaveform", np.concatenate([r["tx"] for r in R]), np.float32)
        _ds(G, "tx_sample_count", np.full(N, TX_SAMPLES), np.uint16)
        _ds(G, "tx_sample_start_index", 1 + TX_SAMPLES * np.arange(N), np.uint64)
        _ds(G, "noise_mean_corrected", [r["noise_mean"] for r in R], np.float64)
        _ds(G, "noise_stddev_corrected", [r["noise_sd"] for r in R], np.float64)
        _ds(G, "nsemean_even", [r["nse_even"] for r in R], np.float32)
        _ds(G, "nsemean_odd", [r["nse_odd"] for r in R], np.float32)
        _ds(G, "rx_energy", [r["rx_energy"] for r in R], np.float64)
        _ds(G, "all_samples_sum", [round(r["noise_mean"] * 66713 + r["E_sig"]) for r in R], np.uint32)
        _ds(G, "rx_offset", [57700 + int(round(r["r_bin0"] / BIN_M)) % 500 for r in R], np.uint16)
        _ds(G, "rx_open", np.full(N, 2856192), np.uint32)
        _ds(G, "stale_return_flag", np.zeros(N), np.uint8)
        _ds(G, "selection_stretchers_x", np.full(N, 300), np.uint16)
        _ds(G, "selection_stretchers_y", np.full(N, 400), np.uint16)
        _ds(G, "th_left_used", np.full(N, 250), np.uint16)
        fits = np.array([r["txfit"][:4] for r in R])
        errs = np.array([r["txfit"][4] for r in R])
        _ds(G, "tx_egamplitude", fits[:, 0], np.float32)
        _ds(G, "tx_egamplitude_error", errs[:, 0], np.float32)
        _ds(G, "tx_gloc", fits[:, 1], np.float32)
        _ds(G, "tx_gloc_error", errs[:, 1], np.float32)
        _ds(G, "tx_egsigma", fits[:, 2], np.float32)
        _ds(G, "tx_egsigma_error", errs[:, 2], np.float32)
        _ds(G, "tx_egbias", fits[:, 3], np.float32)
        _ds(G, "tx_egbias_error", errs[:, 3], np.float32)
        _ds(G, "tx_eggamma", np.zeros(N), np.float32)
        _ds(G, "tx_eggamma_error", np.zeros(N), np.float32)
        _ds(G, "tx_egflag", np.ones(N), np.uint8)
        _ds(G, "tx_pulseflag", np.ones(N), np.uint8)
        A = G.create_group("ancillary")
        _ds(A, "master_time_epoch", [MASTER_TIME_EPOCH], np.float64)
        _ds(A, "mean_samples", [20000], np.int64)
        _ds(A, "smoothing_width", [2000.0], np.float64)
        L = G.create_group("geolocation")
        _sattr(L, "description", "Geolocation")
        lat0 = np.array([s["lat0"] for s in shots])
        lon0 = np.array([s["lon0"] for s in shots])
        latN = np.array([s["latN"] for s in shots])
        lonN = np.array([s["lonN"] for s in shots])
        z0 = np.array([s["z0"] for s in shots])
        zN = np.array([s["zN"] for s in shots])
        _ds(L, "elevation_bin0", z0, np.float64)
        _ds(L, "elevation_lastbin", zN, np.float64)
        _ds(L, "latitude_bin0", lat0, np.float64)
        _ds(L, "longitude_bin0", lon0, np.float64)
        _ds(L, "latitude_lastbin", latN, np.float64)
        _ds(L, "longitude_lastbin", lonN, np.float64)
        for nm, v in [("elevation_bin0_error", 0.33), ("elevation_lastbin_error", 0.33),
                      ("latitude_bin0_error", 5.3e-5), ("latitude_lastbin_error", 5.3e-5),
                      ("longitude_bin0_error", 4.1e-5), ("longitude_lastbin_error", 4.1e-5),
                      ("altitude_instrument_error", 0.2), ("latitude_instrument_error", 3.0e-6),
                      ("longitude_instrument_error", 2.8e-6), ("bounce_time_offset_bin0_error", 7.4e-10),
                      ("bounce_time_offset_lastbin_error", 7.4e-10), ("local_beam_azimuth_error", 3.2e-4),
                      ("local_beam_elevation_error", 1.8e-5)]:
            _ds(L, nm, np.full(N, v), np.float32)
        _ds(L, "degrade", np.zeros(N), np.int8)
        _ds(L, "digital_elevation_model", [s["dem"] for s in shots], np.float32)
        _ds(L, "mean_sea_surface", np.full(N, geoid + 0.3), np.float32)
        _ds(L, "shot_number", sn, np.uint64)
        _ds(L, "delta_time", dt, np.float64)
        _ds(L, "altitude_instrument", [s["inst_alt"] for s in shots], np.float64)
        _ds(L, "latitude_instrument", [s["inst_lat"] for s in shots], np.float64)
        _ds(L, "longitude_instrument", [s["inst_lon"] for s in shots], np.float64)
        _ds(L, "bounce_time_offset_bin0", [s["bt0"] for s in shots], np.float64)
        _ds(L, "bounce_time_offset_lastbin", [s["btN"] for s in shots], np.float64)
        _ds(L, "local_beam_azimuth", [s["beam_az"] for s in shots], np.float32)
        _ds(L, "local_beam_elevation", [s["beam_el"] for s in shots], np.float32)
        _ds(L, "neutat_delay_total_bin0", np.full(N, 2.30), np.float32)
        _ds(L, "neutat_delay_total_lastbin", np.full(N, 2.33), np.float32)
        _ds(L, "neutat_delay_derivative_bin0", np.full(N, -7.8e-8), np.float32)
        _ds(L, "neutat_delay_derivative_lastbin", np.full(N, -7.8e-8), np.float32)
        _ds(L, "range_bias_correction", np.zeros(N), np.float32)
        _ds(L, "solar_azimuth", [s["sun_az"] for s in shots], np.float32)
        _ds(L, "solar_elevation", [s["sun_el"] for s in shots], np.float32)
        st = np.zeros((5, N))
        st[0] = 1
        _ds(L, "surface_type", st, np.int8)
        Q = G.create_group("geophys_corr")
        _sattr(Q, "description", "Geophysical corrections")
        _ds(Q, "delta_time", dt, np.float64)
        _ds(Q, "geoid", np.full(N, geoid), np.float32)
        for k, v in tides.items():
            _ds(Q, k, np.full(N, v), np.float32)
        _ds(Q, "tide_ocean", np.zeros(N), np.float32)
    f.close()
    # ---------------- L2A
    f, tmp2 = _atomic_h5(os.path.join(outdir, l2name))
    _sattr(f, "short_name", "GEDI_L2A")
    _metadata(f, "GEDI_L2A", l2name, "003", created, uid2,
              "SYNTHETIC GEDI L2A-like elevation and height metrics (worldgen).")
    for beam, shots in gran["beams"]:
        bnum, chan, btype, _, _, _ = BEAMS[beam]
        N = len(shots)
        G = _beam_group(f, beam, btype, "wp-l2-l2a")
        dt = np.array([s["delta_time"] for s in shots])
        mi = np.floor(dt)
        sn = np.array([s["shot_number"] for s in shots], dtype=np.uint64)
        RS = [s["l2a"] for s in shots]
        sel = np.array([r["selected"] for r in RS])
        _ds(G, "shot_number", sn, np.uint64)
        _ds(G, "beam", np.full(N, bnum), np.uint16)
        _ds(G, "channel", np.full(N, chan), np.uint8)
        _ds(G, "delta_time", dt, np.float64)
        _ds(G, "master_int", mi, np.uint32)
        _ds(G, "master_frac", dt - mi, np.float64)
        A = {a: [r["alg"][a] for r in RS] for a in ALGS}

        def pick(key):
            return [RS[i]["alg"][sel[i]][key] if sel[i] else A[1][i][key] for i in range(N)]

        _ds(G, "quality_flag", [RS[i]["alg"][sel[i]]["quality"] if sel[i] else 0 for i in range(N)], np.uint8)
        _ds(G, "degrade_flag", np.zeros(N), np.uint8)
        _ds(G, "sensitivity", pick("sensitivity"), np.float32)
        _ds(G, "selected_algorithm", sel, np.uint8)
        _ds(G, "selected_mode", pick("selected_mode"), np.uint8)
        _ds(G, "selected_mode_flag", np.zeros(N), np.uint8)
        _ds(G, "elev_lowestmode", pick("elev_lowestmode"), np.float32)
        _ds(G, "elev_highestreturn", pick("elev_highestreturn"), np.float32)
        _ds(G, "lat_lowestmode", pick("lat_lowestmode"), np.float64)
        _ds(G, "lon_lowestmode", pick("lon_lowestmode"), np.float64)
        _ds(G, "lat_highestreturn", pick("lat_highestreturn"), np.float64)
        _ds(G, "lon_highestreturn", pick("lon_highestreturn"), np.float64)
        rh_sel = np.array(pick("rh_cm"), dtype=np.int16).reshape(N, 101)
        _ds(G, "rh", rh_sel.astype(np.float32) / np.float32(100.0), np.float32)
        _ds(G, "energy_total", [r["energy_total"] for r in RS], np.float32)
        _ds(G, "num_detectedmodes", pick("nmodes"), np.uint8)
        _ds(G, "digital_elevation_model", [s["dem"] for s in shots], np.float32)
        _ds(G, "digital_elevation_model_srtm", [s["dem_srtm"] for s in shots], np.float32)
        _ds(G, "elevation_bias_flag", np.zeros(N), np.uint8)
        _ds(G, "surface_flag", np.ones(N), np.uint8)
        _ds(G, "elevation_bin0_error", np.full(N, 0.33), np.float32)
        _ds(G, "latitude_bin0_error", np.full(N, 5.3e-5), np.float32)
        _ds(G, "longitude_bin0_error", np.full(N, 4.1e-5), np.float32)
        _ds(G, "mean_sea_surface", np.full(N, geoid + 0.3), np.float32)
        _ds(G, "solar_azimuth", [s["sun_az"] for s in shots], np.float32)
        _ds(G, "solar_elevation", [s["sun_el"] for s in shots], np.float32)
        _ds(G.create_group("ancillary"), "l2a_alg_count", [6], np.uint8)
        LC = G.create_group("land_cover_data")
        cov = np.array([s["rec"]["cover"] * 100 for s in shots])
        _ds(LC, "landsat_treecover", np.round(cov), np.float64)
        _ds(LC, "modis_treecover", np.round(np.clip(cov * 0.9, 0, 100)), np.float64)
        _ds(LC, "modis_treecover_sd", np.full(N, 5.0), np.float64)
        _ds(LC, "modis_nonvegetated", np.round(np.clip(100 - cov, 0, 100) * 0.2), np.float64)
        _ds(LC, "modis_nonvegetated_sd", np.full(N, 5.0), np.float64)
        doy = gran["date"].timetuple().tm_yday
        _ds(LC, "leaf_off_flag", np.full(N, leaf_off(doy)), np.uint8)
        _ds(LC, "leaf_off_doy", np.full(N, 305), np.int16)
        _ds(LC, "leaf_on_doy", np.full(N, 110), np.int16)
        _ds(LC, "leaf_on_cycle", np.ones(N), np.uint8)
        _ds(LC, "pft_class", np.full(N, 4), np.uint8)
        _ds(LC, "region_class", np.full(N, 1), np.uint8)
        _ds(LC, "urban_proportion", np.zeros(N), np.uint8)
        _ds(LC, "urban_focal_window_size", np.full(N, 3), np.uint8)
        _ds(LC, "landsat_water_persistence", np.zeros(N), np.uint8)
        L = G.create_group("geolocation")
        for a in ALGS:
            R = A[a]
            _ds(L, f"elev_lowestmode_a{a}", [r["elev_lowestmode"] for r in R], np.float32)
            _ds(L, f"elev_highestreturn_a{a}", [r["elev_highestreturn"] for r in R], np.float32)
            _ds(L, f"elev_lowestreturn_a{a}", [r["elev_lowestreturn"] for r in R], np.float32)
            for w in ("lowestmode", "highestreturn", "lowestreturn"):
                _ds(L, f"lat_{w}_a{a}", [r["lat_" + w] for r in R], np.float64)
                _ds(L, f"lon_{w}_a{a}", [r["lon_" + w] for r in R], np.float64)
            _ds(L, f"rh_a{a}", np.array([r["rh_cm"] for r in R]).reshape(N, 101), np.int16)
            _ds(L, f"sensitivity_a{a}", [r["sensitivity"] for r in R], np.float32)
            _ds(L, f"quality_flag_a{a}", [r["quality"] for r in R], np.uint8)
            _ds(L, f"num_detectedmodes_a{a}", [r["nmodes"] for r in R], np.uint8)
            _ds(L, f"elevs_allmodes_a{a}", np.array([r["elevs_modes"] for r in R]).reshape(N, 20), np.float32)
            _ds(L, f"lats_allmodes_a{a}", np.array([r["lats_modes"] for r in R]).reshape(N, 20), np.float64)
            _ds(L, f"lons_allmodes_a{a}", np.array([r["lons_modes"] for r in R]).reshape(N, 20), np.float64)
            _ds(L, f"energy_lowestmode_a{a}", [r["lme"] for r in R], np.float32)
        _ds(L, "elevation_1gfit", [r["gfit_elev"] for r in RS], np.float32)
        _ds(L, "latitude_1gfit", [r["gfit_lat"] for r in RS], np.float64)
        _ds(L, "longitude_1gfit", [r["gfit_lon"] for r in RS], np.float64)
        _ds(L, "stale_return_flag", np.zeros(N), np.uint8)
        for a in ALGS:
            R = A[a]
            P = G.create_group(f"rx_processing_a{a}")
            _sattr(P, "wp-l2-rxwave_version", "worldgen-" + VERSION)
            for key, dtp in [("mean", np.float32), ("stddev", np.float32), ("mean_sm", np.float32),
                             ("sd_sm", np.float32), ("front_threshold", np.float32),
                             ("back_threshold", np.float32), ("search_start", np.float32),
                             ("search_end", np.float32), ("toploc", np.float32), ("botloc", np.float32),
                             ("botloc_amp", np.float32), ("zcross", np.float32), ("zcross0", np.float32),
                             ("zcross_amp", np.float32), ("peak", np.float32), ("pk_sm", np.float32),
                             ("energy_sm", np.float32), ("lastmodeenergy", np.float32),
                             ("min_detection_threshold", np.float32), ("min_detection_energy", np.float32),
                             ("smoothwidth", np.float32), ("smoothwidth_zcross", np.float32)]:
                _ds(P, key, [r["rp"][key] for r in R], dtp)
            _ds(P, "toploc_miss", np.zeros(N), np.uint8)
            _ds(P, "rx_algrunflag", [r["rp"]["rx_algrunflag"] for r in R], np.uint8)
            _ds(P, "rx_nummodes", [r["nmodes"] for r in R], np.uint8)
            _ds(P, "selected_mode", [r["selected_mode"] for r in R], np.uint8)
            _ds(P, "selected_mode_flag", np.zeros(N), np.uint8)
            _ds(P, "rx_modelocs", np.array([r["rp"]["modelocs"] for r in R]).reshape(N, 20), np.float32)
            _ds(P, "rx_modeamps", np.array([r["rp"]["modeamps"] for r in R]).reshape(N, 20), np.float32)
            _ds(P, "rx_modewidths", np.zeros((N, 20)), np.float32)
            _ds(P, "rx_cumulative", np.array([r["rp"]["cumulative"] for r in R]).reshape(N, 101), np.float32)
            AN = P.create_group("ancillary")
            pa = ALGS[a]
            _ds(AN, "rx_smoothing_width_locs", [pa["sig_locs"]], np.float64)
            _ds(AN, "rx_smoothing_width_zcross", [pa["sig_modes"]], np.float64)
            _ds(AN, "rx_front_threshold", [pa["k_front"]], np.float64)
            _ds(AN, "rx_back_threshold", [pa["k_back"]], np.float64)
            _ds(AN, "rx_subbin_resolution", [4], np.int64)
            _ds(AN, "rx_max_mode_count", [20], np.int64)
            _ds(AN, "rx_use_fixed_thresholds", [0], np.int32)
            _ds(AN, "enable_select_mode", [0], np.int32)
        RA = G.create_group("rx_assess")
        _ds(RA, "mean", [s["rec"]["noise_mean"] for s in shots], np.float32)
        _ds(RA, "sd_corrected", [s["rec"]["noise_sd"] for s in shots], np.float32)
        _ds(RA, "mean_64kadjusted", [s["rec"]["noise_mean"] for s in shots], np.float32)
        _ds(RA, "rx_energy", [r["energy_total"] for r in RS], np.float32)
        _ds(RA, "rx_maxamp", [float(s["rec"]["rx"].max()) - s["rec"]["noise_mean"] for s in shots], np.float32)
        _ds(RA, "rx_maxpeakloc", [int(np.argmax(s["rec"]["rx"])) for s in shots], np.uint16)
        _ds(RA, "rx_clipbin0", np.zeros(N), np.uint16)
        _ds(RA, "rx_clipbin_count", [s["rec"]["clipped"] for s in shots], np.uint16)
        _ds(RA, "rx_assess_flag", np.zeros(N), np.uint16)
        _ds(RA, "quality_flag", np.ones(N), np.uint8)
        _ds(RA, "ocean_calibration_shot_flag", np.zeros(N), np.uint8)
        _ds(RA, "shot_number", sn, np.uint64)
    f.close()
    return tmp1, tmp2


def l2a_for_shot(shot, phys):
    """Run a1..a6 on one waveform, apply the ground_detection effect, choose an algorithm."""
    rec = shot["rec"]
    w = rec["rx"]
    n = rec["n"]
    mu = rec["noise_mean"]
    sdc = rec["noise_sd"]
    z0, zN = shot["z0"], shot["zN"]
    la0, laN, lo0, loN = shot["lat0"], shot["latN"], shot["lon0"], shot["lonN"]

    def zf(i):
        return z0 + (zN - z0) * i / (n - 1)

    def latf(i):
        return la0 + (laN - la0) * i / (n - 1)

    def lonf(i):
        return lo0 + (loN - lo0) * i / (n - 1)

    energy_total = float((w.astype(float) - mu).sum())
    algs = {}
    raw = {}
    for a in ALGS:
        r = l2a_process(w, mu, sdc, a)
        raw[a] = r
        p = ALGS[a]
        o = {"rp": {"mean": mu, "stddev": sdc, "mean_sm": mu, "sd_sm": sdc,
                    "front_threshold": r["thr_f"], "back_threshold": r["thr_b"],
                    "search_start": r["search_start"], "search_end": r["search_end"],
                    "smoothwidth": p["sig_locs"], "smoothwidth_zcross": p["sig_modes"],
                    "energy_sm": float((r["ws"] - mu).sum())}}
        if not r["ok"]:
            o.update(quality=0, sensitivity=0.0, nmodes=0, selected_mode=0,
                     elev_lowestmode=FILL, elev_highestreturn=FILL, elev_lowestreturn=FILL,
                     lat_lowestmode=FILL, lon_lowestmode=FILL, lat_highestreturn=FILL,
                     lon_highestreturn=FILL, lat_lowestreturn=FILL, lon_lowestreturn=FILL,
                     rh_cm=[0] * 101, elevs_modes=[0.0] * 20, lats_modes=[0.0] * 20,
                     lons_modes=[0.0] * 20, lme=0.0, rh_m=None)
            o["rp"].update(toploc=0, botloc=0, botloc_amp=0, zcross=0, zcross0=0, zcross_amp=0,
                           peak=float(w.max()), pk_sm=float(r["ws"].max()), lastmodeenergy=0,
                           min_detection_threshold=0, min_detection_energy=0, rx_algrunflag=0,
                           modelocs=[0.0] * 20, modeamps=[0.0] * 20, cumulative=[0.0] * 101)
            algs[a] = o
            continue
        zc = r["zcross"]
        offset = 0.0
        if phys.ground_detection is not None:
            ga, goff = phys.ground_detection
            if ga == "all" or int(ga) == a:
                offset = goff
        # the ground moves up by `offset` metres: along the record that is -offset/dz_per_sample
        dz_bin = (z0 - zN) / (n - 1)
        zc_eff = zc - offset / dz_bin
        modes = list(r["modes"])
        modes[-1] = (zc_eff, modes[-1][1])
        rh_m = np.array([zf(c) - zf(zc_eff) for c in r["cum"]])
        rh_cm = np.clip(np.trunc(rh_m * 100.0), -32768, 32767).astype(int)
        sens = 1.0 - r["mde"] / energy_total if energy_total > 0 else 0.0
        edge = r["top"] < GUARD + 2 or r["bot"] > n - GUARD - 3
        q = int(sens >= 0.9 and not edge and energy_total > 0)
        nm = len(modes)
        pad = lambda v: list(v) + [0.0] * (20 - len(v))
        o.update(quality=q, sensitivity=float(sens), nmodes=nm, selected_mode=nm - 1,
                 elev_lowestmode=zf(zc_eff), elev_highestreturn=zf(r["top"]),
                 elev_lowestreturn=zf(r["bot"]), lat_lowestmode=latf(zc_eff),
                 lon_lowestmode=lonf(zc_eff), lat_highestreturn=latf(r["top"]),
                 lon_highestreturn=lonf(r["top"]), lat_lowestreturn=latf(r["bot"]),
                 lon_lowestreturn=lonf(r["bot"]), rh_cm=rh_cm.tolist(), rh_m=rh_m,
                 elevs_modes=pad([zf(m[0]) for m in modes]), lats_modes=pad([latf(m[0]) for m in modes]),
                 lons_modes=pad([lonf(m[0]) for m in modes]), lme=r["lme"], zamp=r["zamp"],
                 ground_offset_applied=offset)
        o["rp"].update(toploc=r["top"], botloc=r["bot"], botloc_amp=r["botloc_amp"], zcross=zc_eff,
                       zcross0=zc, zcross_amp=r["zamp"], peak=r["peak"], pk_sm=r["pk_sm"],
                       lastmodeenergy=r["lme"], min_detection_threshold=r["mdt"],
                       min_detection_energy=r["mde"], rx_algrunflag=1,
                       modelocs=pad([m[0] for m in modes]), modeamps=pad([m[1] for m in modes]),
                       cumulative=list(r["cum"]))
        algs[a] = o
    # our selection rule: a1, unless a2 finds a credible ground clearly below a1's (or a1 failed)
    sel = 0
    a1, a2 = algs[1], algs[2]
    if a1["quality"] == 1:
        sel = 1
        if a2["quality"] == 1 and raw[2]["ok"] and raw[1]["ok"]:
            lower = raw[1]["zcross"] - raw[2]["zcross"]  # samples; negative => a2 lower
            if -lower * (z0 - zN) / (n - 1) > 1.5 and raw[2]["zamp"] - mu >= 3 * sdc:
                sel = 2
    elif a2["quality"] == 1:
        sel = 2
    else:
        for a in (3, 4, 5, 6):
            if algs[a]["quality"] == 1:
                sel = a
                break
    # single Gaussian fit of the whole signal
    r1 = raw[1]
    if r1["ok"]:
        lo = max(0, int(r1["top"]) - 20)
        hi = min(n, int(r1["bot"]) + 20)
        gf = gfit(w[lo:hi].astype(float))
        gi = lo + gf[1]
        gfit_res = (zf(gi), latf(gi), lonf(gi))
    else:
        gfit_res = (FILL, FILL, FILL)
    return {"alg": algs, "selected": sel, "energy_total": energy_total,
            "gfit_elev": gfit_res[0], "gfit_lat": gfit_res[1], "gfit_lon": gfit_res[2]}


# --------------------------------------------------------------------------------------------
# World
# --------------------------------------------------------------------------------------------
def generate_world(args):
    t_start = time.time()
    from pyproj import Transformer
    effects = parse_effects(args.effect, args.param, args.magnitude)
    phys = Physics(effects)
    seed = int(args.seed)
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    truth_path = os.path.join(out, "truth.json")
    if os.path.exists(truth_path):
        os.remove(truth_path)
    for sub, ext in (("als", ".laz"), ("gedi", ".h5")):
        d = os.path.join(out, sub)
        if os.path.isdir(d):
            for fn in os.listdir(d):
                if fn.endswith(ext) or fn.endswith(".tmp"):
                    os.remove(os.path.join(d, fn))
    tiles = [load_tile(p) for p in collect_tile_paths(args.tiles)]
    tx_sources = args.tx_l1b or default_tx_sources()
    if not tx_sources:
        raise SystemExit("no real L1B found for the transmit pulse library (use --tx-l1b)")
    lib = load_pulse_library(tx_sources)
    sc = build_scene(tiles, seed, args.grid, args.tile_mode, args.slope_deg)
    sc.als_date = sc.primary.date
    geoid = float(np.float32(rng_for(seed, "geoid").uniform(*GEOID_RANGE)))
    passes = plan_passes(sc, seed, args.passes, phys)
    to_ll = Transformer.from_crs("EPSG:2154", "EPSG:4326", always_xy=True)
    # ---- simulate
    granules = []
    tracks_truth, shots_truth = [], []
    for ps in passes:
        gstart = ps["gstart"]
        stamp = gstart.strftime("%Y") + f"{gstart.timetuple().tm_yday:03d}" + gstart.strftime("%H%M%S")
        stem = f"{stamp}_O{ps['orbit']:05d}_{ps['sub']:02d}_T{ps['track_no']:05d}_02"
        l1b = f"GEDI01_B_{stem}_005_02_V002.h5"
        l2a = f"GEDI02_A_{stem}_003_02_V002.h5"
        t0 = (ps["date"] - GEDI_EPOCH).total_seconds()
        gbeams = []
        for b in ps["beams"]:
            bshots = []
            for sh in b["shots"]:
                rec = simulate_shot(sc, phys, args.pulse_reference, sh, b, ps, geoid, lib, seed)
                if rec is None:
                    continue
                sh["rec"] = rec
                bnum = BEAMS[b["beam"]][0]
                idx8 = 105000 + sh["ks"]
                mid3 = (2 * idx8 + 37 * b["k"]) % 1000
                sh["shot_number"] = int(ps["orbit"]) * 10 ** 13 + bnum * 10 ** 11 + mid3 * 10 ** 8 + idx8
                sh["delta_time"] = t0 + sh["t_rel"] + b["k"] * 1e-4
                dz = phys.datum_dz
                P0, PN = rec["P0"], rec["PN"]
                sh["z0"] = P0[2] + geoid + dz
                sh["zN"] = PN[2] + geoid + dz
                lons, lats = to_ll.transform(np.array([P0[0], PN[0], rec["inst"][0], sh["xr"], sh["xt"]]) + sc.X0,
                                             np.array([P0[1], PN[1], rec["inst"][1], sh["yr"], sh["yt"]]) + sc.Y0)
                sh["lat0"], sh["lon0"], sh["latN"], sh["lonN"] = lats[0], lons[0], lats[1], lons[1]
                sh["inst_lat"], sh["inst_lon"] = lats[2], lons[2]
                sh["inst_alt"] = rec["inst"][2] + geoid
                sh["lat_r"], sh["lon_r"], sh["lat_t"], sh["lon_t"] = lats[3], lons[3], lats[4], lons[4]
                rng0 = (ISS_ALT - P0[2]) / math.cos(rec["theta"])
                sh["bt0"] = rng0 / C_LIGHT
                sh["btN"] = (rng0 + (rec["n"] - 1) * BIN_M) / C_LIGHT
                sh["beam_az"] = (rec["az"] + math.pi) % (2 * math.pi) - math.pi
                sh["beam_el"] = math.pi / 2 - rec["theta"]
                when = GEDI_EPOCH + _dt.timedelta(seconds=sh["delta_time"])
                sh["sun_az"], sh["sun_el"] = solar_position(when, lats[3], lons[3])
                sh["dem"] = rec["zg_rep"] + geoid + rec["dem_err"]
                sh["dem_srtm"] = rec["zg_rep"] + geoid + rec["dem_srtm_err"]
                sh["l2a"] = l2a_for_shot(sh, phys)
                bshots.append(sh)
            if not bshots:
                continue
            bshots.sort(key=lambda s: s["delta_time"])
            gbeams.append((b["beam"], bshots))
            tid = f"p{ps['p']:02d}_{b['beam']}"
            ex = b["extra_beam"] if phys.geo_level == "beam" else np.zeros(2)
            tracks_truth.append({
                "id": tid, "granule": l1b, "granule_l2a": l2a, "beam": b["beam"],
                "beam_type": BEAMS[b["beam"]][2],
                "dx_m": round(b["dx"] + float(ex[0]), 4), "dy_m": round(b["dy"] + float(ex[1]), 4),
                "dx_track_m": round(b["dx"], 4), "dy_track_m": round(b["dy"], 4),
                "dx_effect_m": round(float(ex[0]), 4), "dy_effect_m": round(float(ex[1]), 4),
                "dz_m": phys.datum_dz, "shots": len(bshots),
                "heading_deg": round(ps["heading"], 3), "off_nadir_deg": round(b["theta"], 4),
                "instrument_azimuth_deg": round(ps["inst_az"], 3),
                "date_utc": ps["date"].strftime("%Y-%m-%dT%H:%M:%SZ"),
                "leaf_off_flag": leaf_off(ps["date"].timetuple().tm_yday),
            })
            for sh in bshots:
                rec = sh["rec"]
                xr, yr = sh["xr"] + sc.X0, sh["yr"] + sc.Y0
                xt, yt = sh["xt"] + sc.X0, sh["yt"] + sc.Y0
                L2 = sh["l2a"]
                s_alg = L2["selected"]
                shots_truth.append({
                    "shot_number": str(sh["shot_number"]), "track": tid, "beam": b["beam"],
                    "granule": l1b,
                    "x_reported": round(xr, 3), "y_reported": round(yr, 3),
                    "x_true": round(xt, 3), "y_true": round(yt, 3),
                    "lat_reported": sh["lat_r"], "lon_reported": sh["lon_r"],
                    "lat_true": sh["lat_t"], "lon_true": sh["lon_t"],
                    "als_ground_m": round(footprint_ground(sc, xt, yt, phys.fsigma), 4),
                    "als_ground_center_m": round(float(ground_at(sc, xt, yt)[0]), 4),
                    "als_ground_reported_m": round(footprint_ground(sc, xr, yr, phys.fsigma), 4),
                    "expected_gedi_ground_m": round(footprint_ground(sc, xt, yt, phys.fsigma) + geoid + phys.datum_dz, 4),
                    "delta_time": sh["delta_time"],
                    "rx_sample_count": rec["n"],
                    "ground_energy_fraction": round(rec["ground_frac"], 4),
                    "return_centroid_elev_m": round(rec["return_centroid_elev"], 4),
                    "canopy_cover": round(rec["cover"], 4),
                    "noise_stddev_corrected": rec["noise_sd"],
                    "pulse": {k: (round(v, 5) if isinstance(v, float) else v) for k, v in rec["pulse"].items()},
                    "selected_algorithm": s_alg,
                    "elev_lowestmode_selected": (None if not s_alg else round(L2["alg"][s_alg]["elev_lowestmode"], 4)),
                })
        if gbeams:
            granules.append({"p": ps["p"], "date": ps["date"], "l1b": l1b, "l2a": l2a, "beams": gbeams})
    if not shots_truth:
        raise SystemExit("no shot fell inside the mosaic")
    t_sim = time.time() - t_start
    # ---- write ALS, then GEDI, then truth.json
    als_files = write_als(sc, os.path.join(out, "als"), sc.als_date)
    gdir = os.path.join(out, "gedi")
    os.makedirs(gdir, exist_ok=True)
    for g in granules:
        tmp1, tmp2 = write_granule(gdir, g, geoid, phys, seed)
        os.replace(tmp1, os.path.join(gdir, g["l1b"]))
        os.replace(tmp2, os.path.join(gdir, g["l2a"]))
    truth = {
        "generator": GENERATOR,
        "seed": seed,
        "effects": effects,
        "pulse_reference": args.pulse_reference,
        "geoid_m": geoid,
        "datum_dz_m": phys.datum_dz,
        "physics": {
            "footprint_sigma_m": phys.fsigma, "rho_ground": phys.rho_g, "rho_veg": phys.rho_v,
            "pulse_extra_sigma_m": phys.pulse_sigma_m, "noise_sigma_factor": phys.noise_factor,
            "canopy_change": phys.canopy_change, "occlusion": phys.occlusion,
            "ground_detection": phys.ground_detection,
            "geolocation_effect": {"level": phys.geo_level, "sigma_m": phys.geo_sigma},
            "bin_m": BIN_M, "noise_sd_ratio_corrected_over_record": NOISE_SD_RATIO,
            "noise_correlation_sigma_samples": NOISE_CORR_SIGMA, "shot_noise_kappa": SHOT_NOISE_KAPPA,
            "energy_median": E_MEDIAN, "track_offset_sigma_m": 3.0, "track_offset_clip_m": 7.5,
            "pulse_library": sorted({os.path.basename(p) for p in tx_sources}),
            "l2a_algorithms": {str(k): v for k, v in ALGS.items()},
        },
        "tracks": tracks_truth,
        "shots": shots_truth,
        "scene": {
            "crs": "EPSG:2154", "height_reference": "ALS heights as in the source tiles (orthometric, NGF-IGN69 per the tile provenance); GEDI elevation = ALS height + geoid_m + datum_dz_m",
            "origin_x": sc.X0, "origin_y": sc.Y0, "cell_m": sc.cell, "grid": sc.N,
            "size_m": sc.size, "bbox": [sc.X0, sc.Y0, sc.X0 + sc.size, sc.Y0 + sc.size],
            "z_base_m": sc.zbase, "slope_deg": sc.slope_deg, "slope_uphill_azimuth_deg": sc.slope_az,
            "slope_dz_dx": sc.sx, "slope_dz_dy": sc.sy, "slope_center": [sc.Xm, sc.Ym],
            "tile_mode": args.tile_mode,
            "sources": [{"file": t.name, "sha256": t.sha256, "bbox": [t.xmin, t.ymin, t.xmax, t.ymax],
                         "acquired_utc": t.date.strftime("%Y-%m-%dT%H:%M:%SZ"), "points": t.npoints,
                         "ground_plane_removed": [float(v) for v in t.plane]}
                        for t in sorted({c["tile"] for c in sc.copies}, key=lambda t: t.name)],
            "als_acquired_utc": sc.als_date.strftime("%Y-%m-%dT%H:%M:%SZ"),
            "copies": [{"i": c["i"], "j": c["j"], "source": c["tile"].name, "rotation_deg": 90 * c["rot"],
                        "mirror_x": c["mirror"], "center": [c["cx"], c["cy"]]} for c in sc.copies],
            "transform": "world = center + R(rotation_deg) * M(mirror_x) * (src - src_bbox_center); z = z_src - ground_plane(src) + z_base + slope plane",
            "als_files": als_files,
            "gedi_files": sorted([g["l1b"] for g in granules] + [g["l2a"] for g in granules]),
        },
    }
    tmp = truth_path + ".tmp"
    with open(tmp, "w") as fh:
        json.dump(truth, fh, indent=1, default=_json_default)
    os.replace(tmp, truth_path)
    if not args.quiet:
        print(f"{out}: {len(tracks_truth)} tracks, {len(shots_truth)} shots, {len(granules)} granules, "
              f"{len(als_files)} ALS tiles, simulate {t_sim:.1f} s, total {time.time() - t_start:.1f} s")
    return truth


def _json_default(o):
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, tuple):
        return list(o)
    raise TypeError(type(o))


def build_parser():
    ap = argparse.ArgumentParser(description="Generate an independent GEDI test world from ALS tiles.")
    ap.add_argument("--effect", default="none", help="none | <effect> | <a>+<b>")
    ap.add_argument("--param", action="append", default=[], help="key=value or effect.key=value")
    ap.add_argument("--magnitude", type=float, default=None, help="value of the effect's primary parameter")
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--tiles", nargs="+", required=True, help="LAZ files or folders")
    ap.add_argument("--out", required=True)
    ap.add_argument("--pulse-reference", choices=["centroid", "peak", "gaussian-fit"], default="gaussian-fit")
    ap.add_argument("--passes", type=int, default=6)
    ap.add_argument("--grid", type=int, default=None, help="mosaic copies per side (default: >= 450 m)")
    ap.add_argument("--tile-mode", choices=["single", "mix"], default="single")
    ap.add_argument("--slope-deg", type=float, default=None, help="terrain slope (default: 1-4 deg by seed)")
    ap.add_argument("--tx-l1b", nargs="*", default=None, help="real L1B files for the pulse library")
    ap.add_argument("--quiet", action="store_true")
    return ap


def main(argv=None):
    args = build_parser().parse_args(argv)
    generate_world(args)


if __name__ == "__main__":
    main()
