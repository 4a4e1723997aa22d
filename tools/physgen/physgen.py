#!/usr/bin/env python3
"""physgen -- an independent test-world generator for a GEDI waveform simulator.

One call builds ONE world: a mosaic of real LiDAR HD tiles (mirrored copies), pseudo-real GEDI V2 L1B/L2A
granules simulated over it from first principles, and truth.json.  See README.md for the physics.

    python3 tools/physgen/physgen.py --effect none --seed 1 --tiles tests/data/als --out /tmp/w

Only numpy, h5py, laspy[lazrs] and pyproj are used.  Everything random comes from numpy Generators
seeded by (seed, purpose, indices), so a control and an effect world of the same seed share the
scene, tracks, pulses and noise draws.
"""
import argparse
import datetime as _dt
import hashlib
import json
import math
import os
import sys
import zlib

import numpy as np

VERSION = "0.1.0"
C_LIGHT = 299792458.0
DBIN = C_LIGHT * 1e-9 / 2.0  # 0.149896 m of range per 1 ns sample
GEDI_EPOCH = _dt.datetime(2018, 1, 1, tzinfo=_dt.timezone.utc)
GPS_EPOCH = _dt.datetime(1980, 1, 6, tzinfo=_dt.timezone.utc)

# ----------------------------------------------------------------------------------------------
# Nominal physics constants (documented in README.md)
# ----------------------------------------------------------------------------------------------
NOMINAL = {
    "reflectance_1064nm": {"vegetation": 0.45, "ground": 0.30,
                           "rho_veg_over_ground": 1.5,
                           "source": "rho_v/rho_g = 1.5 as used for GEDI/LVIS canopy cover (Tang et al.; GEDI L2B ATBD)"},
    "return_energy": "e_j = w_p * a_j * rho_j ; a_j = (I_j/rho_j) / sum_k(I_k/rho_k) over the ALS pulse p "
                     "(intensity partition of the pulse's intercepted area), w_p = 1/(ALS pulse density in its 10 m cell) [m2]",
    "density_cell_m": 10.0,
    "footprint": {"shape": "circular Gaussian in the plane at each height", "sigma_m": 5.5,
                  "convention": "1/e^2 intensity diameter = 4 sigma = 22 m (GEDI ~25 m); weight exp(-d^2/(2 sigma^2))"},
    "off_nadir": {"range_deg": [0.5, 4.0], "per": "pass, +/-0.15 deg per beam",
                  "geometry": "beam axis is a straight 3-D line through the ground point (x0,y0,zg0); at elevation z its "
                              "horizontal centre is (x0,y0) + (z - zg0) tan(theta) u, u pointing toward the sub-satellite "
                              "track; range is measured along the axis (equal-range planes are tilted by theta)"},
    "transmit_pulse": "each shot's own recorded pulse: a real L1B txwaveform of the same beam type (tests/data/gedi), "
                      "jittered (shift +/-3 samples, stretch 0.97-1.03, amplitude 0.95-1.05); range reference = its "
                      "Gaussian-fit mean tx_gloc",
    "receiver_response": "Gaussian sigma 1.9 ns convolved with a causal exponential tau 1.0 ns (APD + TIA tail), "
                         "centroid-normalised (range bias calibrated)",
    "noise": {"photo_electron_gain_dn": 1.0, "apd_excess_noise_factor": 2.5,
              "shot_noise": "Gaussian approximation of APD-multiplied Poisson: var = g^2 F lambda per 1-ns sample, before the receiver filter",
              "background_pe_per_ns": "3.0 * max(0, sin(solar elevation))",
              "electronic": "white noise through h_rx - 0.4*G(4 ns) (band-pass, fitted to the measured noise autocorrelation "
                            "0.92/0.71/0.44/0.20/-0.07 at lags 1/2/3/4/6)",
              "electronic_sigma_dn": {"coverage": [1.2, 1.4], "power": [1.45, 1.65]},
              "digitiser": "integer DN per even/odd ADC with offsets on a 1/64 grid, stored after offset correction",
              "noise_stddev_corrected": "kappa * std of the first and last 150 samples, kappa = 1.80 (measured ratio 1.77-1.82 on the real V1 granule)"},
    "link_budget_dn_ns_per_unit_reflectance": {"coverage": 23000.0, "power": 55000.0,
                                               "two_way_atmosphere": [0.8, 1.0]},
    "geolocation": {"per_track_horizontal_sigma_m": 3.0, "per_track_vertical_sigma_m": 0.03,
                    "track": "one (granule, beam) ground track"},
    "geometry": {"along_track_m": 60.0, "across_track_beam_spacing_m": 55.0,
                 "note": "beam spacing shrunk from ~600 m to 55 m so that all 8 beams cross the 500 m mosaic"},
    "geoid": "N(x,y) = ellipsoid - IGN69, smooth model per source tile, stored float32 in geophys_corr/geoid; "
             "z_ellipsoid = z_IGN69 + N exactly with the stored value",
}
REFL_VEG = 0.45
REFL_GND = 0.30
FSIGMA = 5.5
KAPPA = 1.80
GAIN_PE = 1.0
F_EXCESS = 2.5
K_LINK = {"coverage": 23000.0, "power": 55000.0}
ALONG = 60.0
ACROSS = 55.0
V_GROUND = 6920.0  # m/s, measured: 57.2 m per 8.264 ms on the V1 granule
NT = 5  # mosaic copies per axis

BEAMS = ["BEAM0000", "BEAM0001", "BEAM0010", "BEAM0011", "BEAM0101", "BEAM0110", "BEAM1000", "BEAM1011"]
BEAM_TYPE = {b: ("coverage" if int(b[4:], 2) < 4 else "power") for b in BEAMS}
BEAM_CHANNEL = {"BEAM0000": 0, "BEAM0001": 0, "BEAM0010": 1, "BEAM0011": 1,
                "BEAM0101": 2, "BEAM0110": 3, "BEAM1000": 4, "BEAM1011": 5}
# measured noise_mean_corrected median per beam on the V1 granule (BEAM0000 absent there: mean of coverage)
BEAM_BASE = {"BEAM0000": 242.5, "BEAM0001": 245.6, "BEAM0010": 241.0, "BEAM0011": 241.0,
             "BEAM0101": 204.8, "BEAM0110": 228.0, "BEAM1000": 254.5, "BEAM1011": 222.6}
ACROSS_ORDER = ["BEAM0000", "BEAM0101", "BEAM0001", "BEAM0110", "BEAM0010", "BEAM1000", "BEAM0011", "BEAM1011"]

# L2A algorithm settings: (smooth width locs, smooth width zcross, front k, back k)  [gedi-products.md §4.2]
ALGS = {1: (6.5, 6.5, 3.0, 6.0), 2: (6.5, 3.5, 3.0, 3.0), 3: (6.5, 3.5, 3.0, 6.0),
        4: (6.5, 6.5, 6.0, 6.0), 5: (6.5, 3.5, 3.0, 2.0), 6: (6.5, 3.5, 3.0, 4.0)}
# min detection threshold / stddev (median measured ratios, gedi-products.md §4.7); our rule: ceil(m*sigma)
MDT_RATIO = {1: 8.25, 2: 3.44, 3: 6.78, 4: 8.25, 5: 2.30, 6: 4.52}
SMOOTH_EFF = 6.1 / 6.5

# ----------------------------------------------------------------------------------------------
# Effects contract
# ----------------------------------------------------------------------------------------------
EFFECTS = {
    "datum": ({"dz_m": 0.0}, "dz_m"),
    "ground_detection": ({"algorithm": "all", "offset_m": 0.0}, "offset_m"),
    "weighting": ({"rho_ground_over_veg": 1.0}, "rho_ground_over_veg"),
    "pulse": ({"pulse_sigma_m": 0.0}, "pulse_sigma_m"),
    "footprint": ({"fsigma_m": FSIGMA}, "fsigma_m"),
    "noise": ({"noise_sigma_factor": 1.0}, "noise_sigma_factor"),
    "canopy_change": ({"height_m": 10.0, "fraction": 0.0}, "fraction"),
    "occlusion": ({"height_m": 10.0, "gain": 0.0}, "gain"),
    "geolocation": ({"level": "shot", "shot_sigma_m": 0.0}, "shot_sigma_m"),
}


def parse_effects(effect, params, magnitude):
    if effect in (None, "", "none"):
        if params or magnitude is not None:
            raise SystemExit("--param/--magnitude given with --effect none")
        return []
    names = effect.split("+")
    for n in names:
        if n not in EFFECTS:
            raise SystemExit("unknown effect %r (known: %s)" % (n, ", ".join(EFFECTS)))
    if len(set(names)) != len(names):
        raise SystemExit("effect listed twice")
    out = [(n, dict(EFFECTS[n][0])) for n in names]
    if magnitude is not None:
        out[0][1][EFFECTS[names[0]][1]] = float(magnitude)
    for kv in params or []:
        if "=" not in kv:
            raise SystemExit("--param needs k=v, got %r" % kv)
        k, v = kv.split("=", 1)
        if "." in k:
            en, k = k.split(".", 1)
            targets = [p for n, p in out if n == en]
            if not targets:
                raise SystemExit("--param %s: effect %s not in this world" % (kv, en))
        else:
            targets = [p for n, p in out if k in p]
            if len(out) > 1 and len(targets) != 1:
                raise SystemExit("--param %s: use effect.key=v for pairs" % kv)
        if not targets or k not in targets[0]:
            raise SystemExit("--param %s: unknown key" % kv)
        p = targets[0]
        if isinstance(p[k], str):
            p[k] = v
        else:
            p[k] = float(v)
    for n, p in out:
        if n == "ground_detection":
            p["algorithm"] = str(p["algorithm"])
            if p["algorithm"] not in ("all", "1", "2", "3", "4", "5", "6"):
                raise SystemExit("ground_detection.algorithm must be all or 1..6")
        if n == "geolocation" and p["level"] not in ("shot", "beam"):
            raise SystemExit("geolocation.level must be shot or beam")
        if n == "footprint" and p["fsigma_m"] <= 0:
            raise SystemExit("fsigma_m must be > 0")
        if n == "occlusion" and p["gain"] <= -1:
            raise SystemExit("occlusion.gain must be > -1")
        if n == "pulse" and p["pulse_sigma_m"] < 0:
            raise SystemExit("pulse_sigma_m must be >= 0")
        if n == "noise" and p["noise_sigma_factor"] < 0:
            raise SystemExit("noise_sigma_factor must be >= 0")
    return out


# ----------------------------------------------------------------------------------------------
# Random streams
# ----------------------------------------------------------------------------------------------
def _key(k):
    if isinstance(k, str):
        return zlib.crc32(k.encode())
    return int(k)


def rng(seed, *keys):
    return np.random.default_rng([int(seed)] + [_key(k) for k in keys])


# ----------------------------------------------------------------------------------------------
# Small numerics
# ----------------------------------------------------------------------------------------------
def gauss_kernel(sigma, half=None):
    if half is None:
        half = int(math.ceil(4 * sigma)) + 1
    t = np.arange(-half, half + 1, dtype=float)
    k = np.exp(-0.5 * (t / sigma) ** 2)
    return k / k.sum()


def smooth(w, width):
    sig = width * SMOOTH_EFF
    half = int(math.ceil(2 * width)) + 1
    k = gauss_kernel(sig, half)
    p = np.pad(w, half, mode="edge")
    return np.convolve(p, k, mode="valid")


def fftconv(a, b):
    n = len(a) + len(b) - 1
    m = 1 << (n - 1).bit_length()
    return np.fft.irfft(np.fft.rfft(a, m) * np.fft.rfft(b, m), m)[:n]


def gauss_fit(y):
    """Least-squares Gaussian + bias fit (Gauss-Newton); returns amp, mu, sigma, bias."""
    x = np.arange(len(y), dtype=float)
    b = np.median(y[:30])
    yy = y - b
    i = int(np.argmax(yy))
    a = yy[i]
    sel = yy > 0.2 * a
    mu = float(np.sum(x[sel] * yy[sel]) / np.sum(yy[sel]))
    s = max(1.0, float(np.sqrt(np.sum(yy[sel] * (x[sel] - mu) ** 2) / np.sum(yy[sel]))) * 1.2)
    p = np.array([a, mu, s, b])
    for _ in range(30):
        e = np.exp(-0.5 * ((x - p[1]) / p[2]) ** 2)
        f = p[0] * e + p[3]
        J = np.stack([e, p[0] * e * (x - p[1]) / p[2] ** 2, p[0] * e * (x - p[1]) ** 2 / p[2] ** 3,
                      np.ones_like(x)], 1)
        r = y - f
        d, *_ = np.linalg.lstsq(J, r, rcond=None)
        p = p + d
        if np.max(np.abs(d[1:3])) < 1e-6:
            break
    e = np.exp(-0.5 * ((x - p[1]) / p[2]) ** 2)
    resid = y - (p[0] * e + p[3])
    return p, resid


def solar_elevation(dt, lat, lon):
    """NOAA-style approximate solar elevation (deg) and azimuth (deg)."""
    doy = dt.timetuple().tm_yday
    hour = dt.hour + dt.minute / 60 + dt.second / 3600
    g = 2 * math.pi / 365 * (doy - 1 + (hour - 12) / 24)
    decl = (0.006918 - 0.399912 * math.cos(g) + 0.070257 * math.sin(g) - 0.006758 * math.cos(2 * g)
            + 0.000907 * math.sin(2 * g) - 0.002697 * math.cos(3 * g) + 0.00148 * math.sin(3 * g))
    eqt = 229.18 * (0.000075 + 0.001868 * math.cos(g) - 0.032077 * math.sin(g) - 0.014615 * math.cos(2 * g)
                    - 0.040849 * math.sin(2 * g))
    tst = hour * 60 + eqt + 4 * lon
    ha = math.radians(tst / 4 - 180)
    la = math.radians(lat)
    cz = math.sin(la) * math.sin(decl) + math.cos(la) * math.cos(decl) * math.cos(ha)
    cz = max(-1.0, min(1.0, cz))
    zen = math.acos(cz)
    az = math.degrees(math.atan2(math.sin(ha), math.cos(ha) * math.sin(la) - math.tan(decl) * math.cos(la))) + 180
    return 90 - math.degrees(zen), az % 360


# ----------------------------------------------------------------------------------------------
# Real transmit pulses (measured on tests/data/gedi)
# ----------------------------------------------------------------------------------------------
def load_tx_pool(gedi_dir):
    import h5py
    pool = {"coverage": [], "power": []}
    noise = {"coverage": [], "power": []}
    files = sorted(f for f in os.listdir(gedi_dir) if f.startswith("GEDI01_B") and f.endswith(".h5"))
    if not files:
        raise SystemExit("no GEDI01_B*.h5 in %s (needed for the recorded transmit pulses)" % gedi_dir)
    for fn in files:
        with h5py.File(os.path.join(gedi_dir, fn), "r") as f:
            for b in sorted(k for k in f if k.startswith("BEAM")):
                B = f[b]
                desc = B.attrs.get("description")
                desc = str(desc[0] if isinstance(desc, np.ndarray) else desc)
                typ = "coverage" if "Coverage" in desc else "power"
                tx = B["txwaveform"][:].astype(float)
                st = B["tx_sample_start_index"][:].astype(np.int64) - 1
                cn = B["tx_sample_count"][:].astype(np.int64)
                sn = B["shot_number"][:]
                for i in range(len(st)):
                    w = tx[st[i]:st[i] + cn[i]]
                    if len(w) != 128:
                        continue
                    base = np.median(w[:30])
                    pool[typ].append((int(sn[i]), w - base))
                    noise[typ].append(np.std(w[:30]))
    return pool, {k: float(np.median(v)) for k, v in noise.items()}


def jitter_pulse(p, r):
    """p: baseline-removed real tx (128). Returns jittered copy with its own noise kept."""
    shift = r.uniform(-3, 3)
    stretch = r.uniform(0.97, 1.03)
    amp = r.uniform(0.95, 1.05)
    x = np.arange(128, dtype=float)
    c = float(np.argmax(p))
    src = c + (x - c - shift) / stretch
    return amp * np.interp(src, x, p, left=p[0], right=p[-1]), dict(shift=shift, stretch=stretch, amp=amp)


def pulse_kernel_fine(pj, gloc, noise_sd, ext_sigma_samples=0.0, up=4):
    """Noise-free unit-area pulse on a 1/up-sample grid, lag 0 at gloc. Returns (kernel, index of lag 0)."""
    pk = int(np.argmax(pj))
    thr = max(3.0 * noise_sd, 0.01 * pj[pk])
    lo = pk
    while lo > 0 and pj[lo - 1] > thr:
        lo -= 1
    hi = pk
    while hi < 127 and pj[hi + 1] > thr:
        hi += 1
    lo = max(0, lo - 2)
    hi = min(127, hi + 2)
    core = np.zeros(128)
    core[lo:hi + 1] = np.clip(pj[lo:hi + 1] - 0.0, 0, None)
    xs = np.arange(lo * up - 2 * up, hi * up + 2 * up + 1) / up
    k = np.interp(xs, np.arange(128), core, left=0, right=0)
    if ext_sigma_samples > 0:
        k = np.convolve(k, gauss_kernel(ext_sigma_samples * up), mode="full")
        h = (len(gauss_kernel(ext_sigma_samples * up)) - 1) // 2
        xs = np.arange(len(k)) / up + xs[0] - h / up
    k = k / (k.sum() / up)
    # lag of each fine sample relative to gloc
    lag0 = (gloc - xs[0]) * up
    return k, lag0


def receiver_kernels():
    t = np.arange(-30, 31, dtype=float)
    g = np.exp(-0.5 * (t / 1.9) ** 2)
    e = np.where(t >= 0, np.exp(-np.clip(t, 0, None) / 1.0), 0.0)
    h = np.convolve(g / g.sum(), e / e.sum(), mode="same")
    h = h / h.sum()
    # centroid-normalise (range bias calibrated): resample so that the centroid is at lag 0
    c = float(np.sum(h * t))
    h = np.interp(t + c, t, h, left=0.0, right=0.0)
    h = h / h.sum()
    w = np.exp(-0.5 * (t / 4.0) ** 2)
    hel = h - 0.4 * w / w.sum()
    hel = hel / np.sqrt(np.sum(hel ** 2))  # unit-variance output for unit white input
    return h, hel


# ----------------------------------------------------------------------------------------------
# ALS scene
# ----------------------------------------------------------------------------------------------
class Scene:
    def __init__(self, path, rho_ground_factor=1.0):
        import laspy
        self.path = path
        las = laspy.read(path)
        self.las = las
        h = las.header
        self.X = np.asarray(las.X, dtype=np.int64)
        self.Y = np.asarray(las.Y, dtype=np.int64)
        self.sx, self.sy, self.sz = h.scales
        self.ox_, self.oy_, self.oz_ = h.offsets
        x = self.X * self.sx + self.ox_
        y = self.Y * self.sy + self.oy_
        self.z = np.asarray(las.z, dtype=float)
        self.cls = np.asarray(las.classification, dtype=np.int64)
        self.inten = np.maximum(np.asarray(las.intensity, dtype=float), 1.0)
        self.gps = np.asarray(las.gps_time, dtype=float)
        self.psid = np.asarray(las.point_source_id, dtype=np.int64)
        self.x0 = math.floor(x.min())
        self.y0 = math.floor(y.min())
        self.W = float(round(max(x.max() - self.x0, y.max() - self.y0)))
        self.u = x - self.x0  # local coords in [0, W]
        self.v = y - self.y0
        # origin of the tile in integer LAS units
        self.X0 = int(round((self.x0 - self.ox_) / self.sx))
        self.Y0 = int(round((self.y0 - self.oy_) / self.sy))
        self.WI = int(round(self.W / self.sx))
        self._dtm()
        self._pulses()
        self._index()

    # DTM on a 1 m grid of class-2 means, holes filled by neighbour averaging
    def _dtm(self):
        n = int(self.W)
        self.dn = n
        g = self.cls == 2
        iu = np.clip(self.u[g].astype(int), 0, n - 1)
        iv = np.clip(self.v[g].astype(int), 0, n - 1)
        s = np.bincount(iv * n + iu, weights=self.z[g], minlength=n * n)
        c = np.bincount(iv * n + iu, minlength=n * n).astype(float)
        d = np.full(n * n, np.nan)
        d[c > 0] = s[c > 0] / c[c > 0]
        d = d.reshape(n, n)
        for _ in range(200):
            m = np.isnan(d)
            if not m.any():
                break
            p = np.pad(d, 1, mode="edge")
            nb = np.stack([p[:-2, 1:-1], p[2:, 1:-1], p[1:-1, :-2], p[1:-1, 2:]])
            cnt = np.sum(~np.isnan(nb), 0)
            val = np.nansum(nb, 0) / np.maximum(cnt, 1)
            fill = m & (cnt > 0)
            d[fill] = val[fill]
        self.dtm = d
        self.h = self.z - self.dtm_local(self.u, self.v)

    def dtm_local(self, u, v):
        n = self.dn
        fu = np.clip(u - 0.5, 0, n - 1 - 1e-9)
        fv = np.clip(v - 0.5, 0, n - 1 - 1e-9)
        i = np.minimum(fu.astype(int), n - 2)
        j = np.minimum(fv.astype(int), n - 2)
        a = fu - i
        b = fv - j
        d = self.dtm
        return ((1 - a) * (1 - b) * d[j, i] + a * (1 - b) * d[j, i + 1] + (1 - a) * b * d[j + 1, i]
                + a * b * d[j + 1, i + 1])

    def _pulses(self):
        key = np.round(self.gps * 1e7).astype(np.int64) * 1000 + self.psid
        _, inv = np.unique(key, return_inverse=True)
        self.pid = inv
        npul = inv.max() + 1
        self.npul = npul
        gnd = self.cls == 2
        self.is_ground = gnd
        cu = np.bincount(inv, weights=self.u, minlength=npul) / np.bincount(inv, minlength=npul)
        cv = np.bincount(inv, weights=self.v, minlength=npul) / np.bincount(inv, minlength=npul)
        cell = 10.0
        nc = int(math.ceil(self.W / cell))
        ci = np.clip((cu / cell).astype(int), 0, nc - 1) + nc * np.clip((cv / cell).astype(int), 0, nc - 1)
        dens = np.bincount(ci, minlength=nc * nc) / (cell * cell)
        self.w_pulse = 1.0 / dens[ci]  # m2 per pulse
        rho_nom = np.where(gnd, REFL_GND, REFL_VEG)
        area = self.inten / rho_nom
        tot = np.bincount(inv, weights=area, minlength=npul)
        self.a = area / tot[inv]  # intercepted-area share of the pulse
        self.pulse_hmax = np.full(npul, -1e9)
        np.maximum.at(self.pulse_hmax, inv, self.h)

    def energy(self, effects):
        """GEDI-side backscatter energy per ALS return [m2 * reflectance], with effects applied."""
        fac = 1.0
        eff = dict(effects)
        if "weighting" in eff:
            fac = eff["weighting"]["rho_ground_over_veg"]
        rho = np.where(self.is_ground, REFL_GND * fac, REFL_VEG)
        e = self.w_pulse[self.pid] * self.a * rho
        if "canopy_change" in eff:
            p = eff["canopy_change"]
            e = np.where(self.h > p["height_m"], e * (1.0 - p["fraction"]), e)
        if "occlusion" in eff:
            p = eff["occlusion"]
            crosses = self.pulse_hmax[self.pid] > p["height_m"]
            e = np.where(crosses & (self.h <= p["height_m"]), e * (1.0 + p["gain"]), e)
        return e

    def _index(self):
        self.cs = 5.0
        self.nc = int(math.ceil(self.W / self.cs)) + 1
        ci = np.clip((self.u / self.cs).astype(int), 0, self.nc - 1)
        cj = np.clip((self.v / self.cs).astype(int), 0, self.nc - 1)
        cell = cj * self.nc + ci
        order = np.argsort(cell, kind="stable")
        self.order = order
        self.starts = np.searchsorted(cell[order], np.arange(self.nc * self.nc + 1))

    def query_local(self, u0, u1, v0, v1):
        i0 = max(0, int(u0 // self.cs))
        i1 = min(self.nc - 1, int(u1 // self.cs))
        j0 = max(0, int(v0 // self.cs))
        j1 = min(self.nc - 1, int(v1 // self.cs))
        if i1 < i0 or j1 < j0:
            return np.zeros(0, dtype=np.int64)
        parts = [self.order[self.starts[j * self.nc + i0]:self.starts[j * self.nc + i1 + 1]] for j in range(j0, j1 + 1)]
        return np.concatenate(parts)


class Mosaic:
    """NT x NT mirrored copies of the source tile; copy (2,2) is the source at its own coordinates."""

    def __init__(self, scene):
        self.s = scene
        W = scene.W
        self.ox = scene.x0 - 2 * W
        self.oy = scene.y0 - 2 * W
        self.size = NT * W

    def to_local(self, x, y):
        W = self.s.W
        i = np.clip(np.floor((x - self.ox) / W).astype(int), 0, NT - 1)
        j = np.clip(np.floor((y - self.oy) / W).astype(int), 0, NT - 1)
        lu = x - self.ox - i * W
        lv = y - self.oy - j * W
        u = np.where(i % 2 == 1, W - lu, lu)
        v = np.where(j % 2 == 1, W - lv, lv)
        return u, v

    def dtm(self, x, y):
        u, v = self.to_local(np.asarray(x, float), np.asarray(y, float))
        return self.s.dtm_local(u, v)

    def points_in(self, xa, xb, ya, yb):
        """All mosaic points in [xa,xb]x[ya,yb]: returns src index, x, y."""
        s = self.s
        W = s.W
        out_i, out_x, out_y = [], [], []
        for i in range(NT):
            cx0 = self.ox + i * W
            if xb < cx0 or xa > cx0 + W:
                continue
            for j in range(NT):
                cy0 = self.oy + j * W
                if yb < cy0 or ya > cy0 + W:
                    continue
                la, lb = xa - cx0, xb - cx0
                ma, mb = ya - cy0, yb - cy0
                ua, ub = (W - lb, W - la) if i % 2 else (la, lb)
                va, vb = (W - mb, W - ma) if j % 2 else (ma, mb)
                idx = s.query_local(ua, ub, va, vb)
                if len(idx) == 0:
                    continue
                px = cx0 + (W - s.u[idx] if i % 2 else s.u[idx])
                py = cy0 + (W - s.v[idx] if j % 2 else s.v[idx])
                m = (px >= xa) & (px <= xb) & (py >= ya) & (py <= yb)
                out_i.append(idx[m])
                out_x.append(px[m])
                out_y.append(py[m])
        if not out_i:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
        return np.concatenate(out_i), np.concatenate(out_x), np.concatenate(out_y)


def write_als(scene, mosaic, outdir, tmp_suffix):
    import laspy
    s = scene
    las = s.las
    os.makedirs(outdir, exist_ok=True)
    # per flight line (point_source_id) time span: copies are shifted by whole seconds so that their pulses
    # never overlap in time within a flight line, while staying within minutes of the real acquisition
    span = max(float(s.gps[s.psid == q].max() - s.gps[s.psid == q].min()) for q in np.unique(s.psid))
    step = float(math.ceil(span + 1.0))
    names = []
    for i in range(NT):
        for j in range(NT):
            hdr = laspy.LasHeader(point_format=6, version="1.4")
            hdr.scales = np.array([s.sx, s.sy, s.sz])
            hdr.offsets = np.array([s.ox_, s.oy_, s.oz_])
            hdr.global_encoding.wkt = True
            hdr.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
            for v in las.header.vlrs:
                if v.user_id == "LASF_Projection" and v.record_id == 2112:
                    hdr.vlrs.append(v)
            hdr.system_identifier = "physgen"
            hdr.generating_software = "physgen %s" % VERSION
            hdr.creation_date = _dt.date(2026, 1, 1)
            out = laspy.LasData(hdr)
            p = laspy.ScaleAwarePointRecord.zeros(len(s.X), header=hdr)
            for dim in ["Z", "intensity", "return_number", "number_of_returns", "classification",
                        "scan_angle", "user_data", "point_source_id", "scanner_channel",
                        "scan_direction_flag", "edge_of_flight_line", "synthetic", "key_point", "withheld",
                        "overlap"]:
                try:
                    p[dim] = las[dim]
                except Exception:
                    pass
            lx = s.X - s.X0
            ly = s.Y - s.Y0
            cx0 = int(round((mosaic.ox + i * s.W - s.ox_) / s.sx))
            cy0 = int(round((mosaic.oy + j * s.W - s.oy_) / s.sy))
            p["X"] = cx0 + (s.WI - lx if i % 2 else lx)
            p["Y"] = cy0 + (s.WI - ly if j % 2 else ly)
            # each copy is a distinct (virtual) acquisition: gps_time shifted by whole hours per copy
            k = i * NT + j - (2 * NT + 2)
            p["gps_time"] = s.gps + k * step
            out.points = p
            out.update_header()
            ex = mosaic.ox + i * s.W
            ey = mosaic.oy + j * s.W
            name = "physgen_%07d_%08d.laz" % (int(round(ex)), int(round(ey)))
            fn = os.path.join(outdir, name)
            with open(fn + tmp_suffix, "wb") as fh:
                out.write(fh, do_compress=True, laz_backend=laspy.LazBackend.Lazrs)
            os.replace(fn + tmp_suffix, fn)
            names.append(name)
    return names


# ----------------------------------------------------------------------------------------------
# Geoid model (ellipsoid - IGN69)
# ----------------------------------------------------------------------------------------------
def geoid_model(lat, lon):
    # smooth approximation of the French geoid/RAF separation (about 44 m in the west, 52 m in the Alps)
    return 49.0 + 0.9 * (lon - 2.0) - 0.35 * (lat - 46.5) + 0.02 * (lon - 2.0) ** 2


# ----------------------------------------------------------------------------------------------
# L2A processing (our own, from public facts)
# ----------------------------------------------------------------------------------------------
def l2a_process(w, mu, sd, alg):
    wl, wz, kf, kb = ALGS[alg]
    n = len(w)
    out = {"run": 0}
    front = mu + kf * sd
    back = mu + kb * sd
    out["front_threshold"] = front
    out["back_threshold"] = back
    sl = smooth(w, wl)
    sz = smooth(w, wz)
    out["pk_sm"] = float(sl.max())
    out["mean_sm"] = float(np.mean(np.r_[sl[:100], sl[-100:]]))
    above = np.nonzero(sl > front)[0]
    aboveb = np.nonzero(sl > back)[0]
    if len(above) == 0 or len(aboveb) == 0:
        return out
    i = above[0]
    top = i - 1 + (front - sl[i - 1]) / (sl[i] - sl[i - 1]) if i > 0 else 0.0
    j = aboveb[-1]
    bot = j + (sl[j] - back) / (sl[j] - sl[j + 1]) if j < n - 1 else float(n - 1)
    top = round(top * 4) / 4
    bot = round(bot * 4) / 4
    if bot <= top:
        return out
    d = np.diff(sz)
    cand = np.nonzero((d[:-1] > 0) & (d[1:] <= 0))[0] + 1
    cand = cand[(cand >= top - 1) & (cand <= bot + 1) & (sz[cand] > back)]
    locs = []
    for c in cand:
        den = sz[c - 1] - 2 * sz[c] + sz[c + 1]
        off = 0.5 * (sz[c - 1] - sz[c + 1]) / den if den != 0 else 0.0
        locs.append(round((c + off) * 4) / 4)
    if not locs:
        seg = np.arange(int(math.ceil(top)), int(math.floor(bot)) + 1)
        locs = [float(seg[np.argmax(sz[seg])])]
    locs = np.array(locs[-20:], dtype=float)
    amps = np.interp(locs, np.arange(n), sz)
    # energy (above mean) of the zcross-smoothed wave on a 1/4 grid between botloc and toploc
    fine = np.arange(top, bot + 1e-9, 0.25)
    fv = np.clip(np.interp(fine, np.arange(n), sz) - mu, 0, None)
    csum_up = np.cumsum(fv[::-1])  # from botloc upward
    tot = csum_up[-1] if len(csum_up) else 0.0
    sel = len(locs) - 1
    flag = 0
    if alg == 2 and tot > 0:
        # our a2 rule: skip a weak lowest mode (< 6 sd above mean, < 0.5 x the next mode) if the energy
        # below the midpoint to the next mode is < 2.5 % of the total (cumulative_energy_thresh)
        for _ in range(2):
            if sel == 0:
                break
            a_lo = amps[sel] - mu
            a_hi = amps[sel - 1] - mu
            mid = 0.5 * (locs[sel] + locs[sel - 1])
            e_below = fv[fine >= mid].sum() / tot * 100
            if a_lo < 6 * sd and a_lo < 0.5 * a_hi and e_below < 2.5:
                sel -= 1
                flag += 1
            else:
                break
        flag = {0: 0, 1: 3, 2: 4}[flag]
    zc = locs[sel]
    cum = np.zeros(101)
    if tot > 0:
        frac = csum_up / tot
        pos_up = fine[::-1]
        for k in range(101):
            ii = int(np.searchsorted(frac, k / 100.0 - 1e-12))
            ii = min(ii, len(pos_up) - 1)
            cum[k] = pos_up[ii]
        cum[0] = bot
        cum[100] = top
    out.update(run=1, toploc=top, botloc=bot, locs=locs, amps=amps, sel=sel, zcross=zc, flag=flag,
               cum=cum, zcross_amp=float(amps[sel]),
               botloc_amp=float(np.interp(bot, np.arange(n), sl)), energy_sm=float(np.sum(sl - mu)))
    # per-mode local energy: between midpoints to neighbouring modes
    edges = np.r_[top, 0.5 * (locs[1:] + locs[:-1]), bot]
    le = np.array([fv[(fine >= edges[m]) & (fine < edges[m + 1] + 1e-9)].sum() * 0.25 for m in range(len(locs))])
    out["localenergy"] = le
    out["lastmodeenergy"] = float(le[sel])
    return out


# ----------------------------------------------------------------------------------------------
# World builder
# ----------------------------------------------------------------------------------------------
def list_tiles(tdir):
    import laspy
    out = []
    for fn in sorted(os.listdir(tdir)):
        if not fn.lower().endswith((".laz", ".las")):
            continue
        with laspy.open(os.path.join(tdir, fn)) as r:
            h = r.header
            ext = min(h.maxs[0] - h.mins[0], h.maxs[1] - h.mins[1])
            if ext >= 90.0 and h.point_format.id == 6 and h.point_count < 600000:
                out.append(fn)
    return out


def date_in_season(r, leaf_on):
    start = _dt.datetime(2019, 4, 18, tzinfo=_dt.timezone.utc)
    end = _dt.datetime(2023, 3, 16, tzinfo=_dt.timezone.utc)
    while True:
        d = start + _dt.timedelta(seconds=float(r.uniform(0, (end - start).total_seconds())))
        if leaf_on and d.month in (5, 6, 7, 8, 9):
            return d
        if not leaf_on and d.month in (12, 1, 2, 3):
            return d


def build(args):
    import h5py
    from pyproj import Transformer
    effects = parse_effects(args.effect, args.param, args.magnitude)
    eff = dict(effects)
    seed = int(args.seed)
    out = args.out
    tmp = ".tmp-physgen-%d" % os.getpid()
    os.makedirs(os.path.join(out, "gedi"), exist_ok=True)
    if os.path.exists(os.path.join(out, "truth.json")):
        os.remove(os.path.join(out, "truth.json"))  # a world without truth.json is incomplete
    gedi_src = args.gedi or os.path.join(os.path.dirname(os.path.abspath(args.tiles.rstrip("/"))), "gedi")

    tiles = list_tiles(args.tiles)
    if not tiles:
        raise SystemExit("no usable ALS tile (PF6, >= 90 m) in %s" % args.tiles)
    r_scene = rng(seed, "scene")
    tile = args.tile or tiles[int(r_scene.integers(len(tiles)))]
    scene = Scene(os.path.join(args.tiles, tile))
    mosaic = Mosaic(scene)
    als_names = write_als(scene, mosaic, os.path.join(out, "als"), tmp)
    energy = scene.energy(effects)

    to_geo = Transformer.from_crs(2154, 4326, always_xy=True)
    lon_c, lat_c = to_geo.transform(mosaic.ox + mosaic.size / 2, mosaic.oy + mosaic.size / 2)
    gps_mid = float(np.median(scene.gps))
    als_date = GPS_EPOCH + _dt.timedelta(seconds=gps_mid + 1e9 - 18)
    leaf_on = als_date.month in (5, 6, 7, 8, 9, 10)

    pool, tx_noise = load_tx_pool(gedi_src)
    h_rx, h_el = receiver_kernels()

    fsig = eff["footprint"]["fsigma_m"] if "footprint" in eff else FSIGMA
    pulse_sig_samples = (eff["pulse"]["pulse_sigma_m"] / DBIN) if "pulse" in eff else 0.0
    nfac = eff["noise"]["noise_sigma_factor"] if "noise" in eff else 1.0
    datum_dz = eff["datum"]["dz_m"] if "datum" in eff else 0.0

    cx = mosaic.ox + mosaic.size / 2
    cy = mosaic.oy + mosaic.size / 2
    margin = 30.0
    truth_shots = []
    granules = []
    n_pass = int(args.passes)
    for ip in range(n_pass):
        rp = rng(seed, "pass", ip)
        asc = bool(rp.integers(2))
        az = math.radians((62.0 if asc else 118.0) + rp.uniform(-3, 3))
        if rp.integers(2):
            az += math.pi  # flown the other way across the scene
        tdir = np.array([math.sin(az), math.cos(az)])  # along-track unit (east, north)
        cdir = np.array([tdir[1], -tdir[0]])  # across-track unit (to the right)
        theta_pass = rp.uniform(0.5, 4.0)
        side = 1.0 if rp.integers(2) else -1.0
        off_across = rp.uniform(-25, 25)
        phase = rp.uniform(0, ALONG)
        when = date_in_season(rp, leaf_on)
        orbit = 1964 + int((when - _dt.datetime(2019, 4, 18, 8, 3, 38, tzinfo=_dt.timezone.utc)).total_seconds() // 5562)
        sub = int(rp.integers(1, 5))
        track = int(rp.integers(1, 5600))
        atm = rp.uniform(0.8, 1.0)
        stem = "%s_O%05d_%02d_T%05d_02" % (when.strftime("%Y%j%H%M%S"), orbit, sub, track)
        sol_el, sol_az = solar_elevation(when, lat_c, lon_c)
        bg_rate = 3.0 * max(0.0, math.sin(math.radians(sol_el)))
        g_rec = {"stem": stem, "orbit": orbit, "when": when, "beams": {}, "sol": (sol_el, sol_az)}
        for ib, beam in enumerate(ACROSS_ORDER):
            rb = rng(seed, "beam", ip, beam)
            typ = BEAM_TYPE[beam]
            theta = math.radians(theta_pass + rb.uniform(-0.15, 0.15))
            u = side * cdir  # horizontal direction from the ground point toward the sub-satellite track
            off_c = off_across + (ib - 3.5) * ACROSS
            # per-track geolocation error (nominal)
            tdx, tdy = rb.normal(0, 3.0, 2)
            tdz = rb.normal(0, 0.03)
            gdx = gdy = 0.0
            if "geolocation" in eff and eff["geolocation"]["level"] == "beam":
                rg = rng(seed, "geoloc_effect", ip, beam)
                gdx, gdy = rg.normal(0, eff["geolocation"]["shot_sigma_m"], 2)
            sel_e = rb.uniform(1.2, 1.4) if typ == "coverage" else rb.uniform(1.45, 1.65)
            shots = []
            for k in range(-12, 13):
                a_t = phase + k * ALONG
                xy = np.array([cx, cy]) + a_t * tdir + off_c * cdir
                if not (mosaic.ox + margin <= xy[0] <= mosaic.ox + mosaic.size - margin and
                        mosaic.oy + margin <= xy[1] <= mosaic.oy + mosaic.size - margin):
                    continue
                shots.append((k, xy))
            if not shots:
                continue
            recs = []
            for k, xy in shots:
                rs = rng(seed, "shot", ip, beam, k + 100)
                rn = rng(seed, "noise", ip, beam, k + 100)
                rec = simulate_shot(scene, mosaic, energy, xy, theta, u, fsig, pulse_sig_samples, nfac, typ,
                                    beam, pool, tx_noise, h_rx, h_el, rs, rn, atm, bg_rate, sel_e)
                rec["k"] = k
                rec["track_offset"] = (tdx, tdy, tdz)
                ex = ey = 0.0
                if "geolocation" in eff:
                    if eff["geolocation"]["level"] == "shot":
                        rg = rng(seed, "geoloc_effect", ip, beam, k + 100)
                        ex, ey = rg.normal(0, eff["geolocation"]["shot_sigma_m"], 2)
                    else:
                        ex, ey = gdx, gdy
                rec["geo_effect"] = (ex, ey)
                recs.append(rec)
            g_rec["beams"][beam] = {"theta": theta, "u": u, "recs": recs, "tdir": tdir}
        granules.append(g_rec)

    # -------- geolocate, write granules
    truth_gran = []
    for ip, g in enumerate(granules):
        l1b_name = "GEDI01_B_%s_005_02_V002.h5" % g["stem"]
        l2a_name = "GEDI02_A_%s_003_02_V002.h5" % g["stem"]
        beams_out = {}
        for beam in BEAMS:
            if beam not in g["beams"]:
                continue
            B = g["beams"][beam]
            recs = B["recs"]
            n = len(recs)
            t0 = (g["when"] - GEDI_EPOCH).total_seconds()
            geo = {}
            for nm in ("x_true", "y_true", "x_rep", "y_rep"):
                geo[nm] = np.zeros(n)
            cols = {k: [] for k in ("bin0", "last", "xb0", "yb0", "xl", "yl", "N", "zg_true")}
            for i, r in enumerate(recs):
                tdx, tdy, tdz = r["track_offset"]
                ex, ey = r["geo_effect"]
                dxr, dyr = tdx + ex, tdy + ey
                lon0, lat0 = to_geo.transform(r["x0"], r["y0"])
                N = float(np.float32(geoid_model(lat0, lon0)))
                r["N"] = N
                r["dxr"], r["dyr"], r["dzr"] = dxr, dyr, tdz
                zshift = N + tdz + datum_dz
                cols["bin0"].append(r["z_bin0"] + zshift)
                cols["last"].append(r["z_last"] + zshift)
                cols["xb0"].append(r["xy_bin0"][0] + dxr)
                cols["yb0"].append(r["xy_bin0"][1] + dyr)
                cols["xl"].append(r["xy_last"][0] + dxr)
                cols["yl"].append(r["xy_last"][1] + dyr)
                cols["N"].append(N)
            lonb0, latb0 = to_geo.transform(np.array(cols["xb0"]), np.array(cols["yb0"]))
            lonl, latl = to_geo.transform(np.array(cols["xl"]), np.array(cols["yl"]))
            dt_ = np.array([t0 + (r["k"] + 12) * ALONG / V_GROUND for r in recs])
            beams_out[beam] = dict(recs=recs, bin0=np.array(cols["bin0"]), last=np.array(cols["last"]),
                                   latb0=np.asarray(latb0), lonb0=np.asarray(lonb0), latl=np.asarray(latl),
                                   lonl=np.asarray(lonl), N=np.array(cols["N"], dtype=np.float32), dt=dt_,
                                   theta=B["theta"], u=B["u"], tdir=B["tdir"])
        l2a_results = write_l1b(os.path.join(out, "gedi", l1b_name), tmp, g, beams_out, seed, ip)
        write_l2a(os.path.join(out, "gedi", l2a_name), tmp, g, beams_out, seed, ip, eff, leaf_on)
        for beam, bo in beams_out.items():
            for i, r in enumerate(bo["recs"]):
                truth_shots.append(shot_truth(r, bo, i, beam, l1b_name, l2a_name, g))
        truth_gran.append({"l1b": l1b_name, "l2a": l2a_name, "orbit": g["orbit"],
                           "utc": g["when"].strftime("%Y-%m-%dT%H:%M:%SZ"),
                           "solar_elevation_deg": round(g["sol"][0], 3)})

    # remove stale outputs of an earlier build into the same folder
    keep = set(als_names) | {t["l1b"] for t in truth_gran} | {t["l2a"] for t in truth_gran}
    for sub, pre in (("als", "physgen_"), ("gedi", "GEDI0")):
        for fn in os.listdir(os.path.join(out, sub)):
            if fn.startswith(pre) and fn not in keep:
                os.remove(os.path.join(out, sub, fn))
    truth = {
        "generator": "physgen %s" % VERSION,
        "seed": seed,
        "effects": [{"name": n, "params": p} for n, p in effects],
        "datum_dz_m": float(datum_dz),
        "nominal": NOMINAL,
        "scene": {"source_tile": tile, "mosaic_origin": [mosaic.ox, mosaic.oy], "mosaic_size_m": mosaic.size,
                  "copies": NT * NT, "mirrored": True, "als_files": als_names, "crs": "EPSG:2154",
                  "als_heights": "IGN69 orthometric as in the source", "als_season": "leaf-on" if leaf_on else "leaf-off",
                  "footprint_sigma_m": fsig},
        "granules": truth_gran,
        "shots": truth_shots,
    }
    fn = os.path.join(out, "truth.json")
    with open(fn + tmp, "w") as f:
        json.dump(truth, f, indent=1, sort_keys=True, default=_jsonable)
    os.replace(fn + tmp, fn)
    return truth


def _jsonable(o):
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def simulate_shot(scene, mosaic, energy, xy, theta, u, fsig, pulse_sig_samples, nfac, typ, beam, pool, tx_noise,
                  h_rx, h_el, rs, rn, atm, bg_rate, sig_e):
    x0, y0 = float(xy[0]), float(xy[1])
    zg0 = float(mosaic.dtm(np.array([x0]), np.array([y0]))[0])
    tt = math.tan(theta)
    st, ct = math.sin(theta), math.cos(theta)
    R = max(4.0 * fsig, 2.0 * FSIGMA) + 1.0
    hmax_guess = 45.0
    xa = min(x0, x0 + hmax_guess * tt * u[0]) - R
    xb = max(x0, x0 + hmax_guess * tt * u[0]) + R
    ya = min(y0, y0 + hmax_guess * tt * u[1]) - R
    yb = max(y0, y0 + hmax_guess * tt * u[1]) + R
    idx, px, py = mosaic.points_in(xa, xb, ya, yb)
    pz = scene.z[idx]
    dzp = pz - zg0
    axx = x0 + dzp * tt * u[0]
    axy = y0 + dzp * tt * u[1]
    d2 = (px - axx) ** 2 + (py - axy) ** 2
    G = np.exp(-0.5 * d2 / fsig ** 2) / (2 * math.pi * fsig ** 2)
    m = d2 < max(4.0 * fsig, 2.0 * FSIGMA) ** 2
    idx, px, py, pz, G = idx[m], px[m], py[m], pz[m], G[m]
    e = energy[idx] * G  # reflectance-weighted footprint fraction per return
    rng_ = (px - x0) * st * u[0] + (py - y0) * st * u[1] + (pz - zg0) * ct  # range above the ground point
    # tx pulse: a real one of this beam type, jittered
    src_sn, praw = pool[typ][int(rs.integers(len(pool[typ])))]
    pj, jit = jitter_pulse(praw, rs)
    txbase = BEAM_BASE[beam] + rs.uniform(-1, 1)
    tx_store = np.round(pj + txbase).astype(np.float32)
    fit, _ = gauss_fit(tx_store.astype(float))
    gloc = float(fit[1])
    # geometry of the record
    # record window from geometry only (nominal footprint), so that effects never move the window
    near = d2[m] < (2.0 * FSIGMA) ** 2
    r_top = float(rng_[near].max()) if near.any() else 0.0
    r0 = r_top + rs.uniform(40.0, 48.0)
    r_end = -rs.uniform(63.0, 67.0)
    n = int(round((r0 - r_end) / DBIN)) + 1
    # link budget
    txe = float(np.clip(pj, 0, None).sum())
    ref_e = float(np.mean([np.clip(p, 0, None).sum() for _, p in pool[typ]]))
    K = K_LINK[typ] * atm * txe / ref_e
    E = K * e  # DN*ns per return
    up = 4
    kern, lag0 = pulse_kernel_fine(pj, gloc, tx_noise[typ], pulse_sig_samples, up)
    # deposit on a fine grid with padding
    pad = 64
    nf = (n + 2 * pad) * up
    tpos = ((r0 - rng_) / DBIN + pad) * up
    i0 = np.floor(tpos).astype(np.int64)
    fr = tpos - i0
    ok = (i0 >= 0) & (i0 < nf - 1)
    dep = np.bincount(i0[ok], weights=E[ok] * (1 - fr[ok]), minlength=nf) + \
        np.bincount(i0[ok] + 1, weights=E[ok] * fr[ok], minlength=nf)
    dep = dep[:nf]
    conv = fftconv(dep, kern)
    # fine index f corresponds to deposit position f - lag0
    L = int(math.floor(lag0))
    fl = lag0 - L
    samp_fine = (np.arange(n) + pad) * up + L
    s_det = (1 - fl) * conv[samp_fine] + fl * conv[samp_fine + 1]
    # shot noise, background, receiver, electronics (paired draws: same z for any effect)
    z1 = rn.standard_normal(n + 120)
    z2 = rn.standard_normal(n + 120)
    z3 = rn.standard_normal(n + 120)
    adc = np.round(rn.uniform(-1, 1, 2) * 64) / 64
    s_pad = np.r_[np.zeros(60), np.clip(s_det, 0, None), np.zeros(60)]
    lam = s_pad / GAIN_PE
    shot = GAIN_PE * np.sqrt(F_EXCESS * lam) * z1
    bgn = GAIN_PE * np.sqrt(F_EXCESS * bg_rate) * z2
    hr = len(h_rx) // 2
    sig_rx = np.convolve(s_pad, h_rx, mode="same")[60:60 + n]
    noi_rx = np.convolve(shot + bgn, h_rx, mode="same")[60:60 + n]
    el = sig_e * np.convolve(z3, h_el, mode="same")[60:60 + n]
    base = BEAM_BASE[beam] + GAIN_PE * bg_rate
    par = np.arange(n) % 2
    raw = np.round(base + sig_rx + nfac * (noi_rx + el) + adc[par])
    raw = np.clip(raw, 0, 4095)
    wf = (raw - adc[par] + adc.mean()).astype(np.float32)
    del hr
    noise_part = np.r_[wf[:150], wf[-150:]].astype(float)
    nmean = float(noise_part.mean())
    nsd = KAPPA * float(noise_part.std())
    # truth quantities
    gsel = scene.is_ground[idx]
    e_g = float(e[gsel].sum())
    e_t = float(e.sum())
    hh = scene.h[idx]
    rec = dict(x0=x0, y0=y0, zg0=zg0, theta=theta, u=u, wf=wf, tx=tx_store, tx_fit=fit, gloc=gloc,
               tx_src=src_sn, tx_jitter=jit, n=n, r0=r0,
               z_bin0=zg0 + r0 * ct, z_last=zg0 + (r0 - (n - 1) * DBIN) * ct,
               xy_bin0=(x0 + r0 * st * u[0], y0 + r0 * st * u[1]),
               xy_last=(x0 + (r0 - (n - 1) * DBIN) * st * u[0], y0 + (r0 - (n - 1) * DBIN) * st * u[1]),
               nmean=nmean, nsd=nsd, nsemean=(base + adc[0], base + adc[1]), n_pts=int(len(idx)),
               ground_energy_fraction=(e_g / e_t if e_t > 0 else 0.0),
               z_top=float(zg0 + r_top * ct), canopy_h95=float(np.percentile(hh[hh > 2], 95)) if np.any(hh > 2) else 0.0,
               zg_weighted=float(np.sum(G[gsel] * pz[gsel]) / np.sum(G[gsel])) if gsel.any() else zg0,
               bg_rate=bg_rate, sigma_e=sig_e, K=K)
    return rec


def _z_at(p, z0, zN, n):
    return z0 + (zN - z0) * p / (n - 1)


def write_ds(g, name, data, dtype=None):
    a = np.asarray(data, dtype=dtype) if dtype is not None else np.asarray(data)
    return g.create_dataset(name, data=a, track_times=False)


def write_meta(f, short, fname, pge, seed, ip):
    f.attrs["short_name"] = np.array([short], dtype=object)
    md = f.create_group("METADATA")
    di = md.create_group("DatasetIdentification")
    uu = hashlib.sha256(("%s-%d-%d" % (short, seed, ip)).encode()).hexdigest()
    attrs = {"PGEVersion": pge, "VersionID": "02", "fileName": fname, "shortName": short,
             "creationDate": "2026-01-01T00:00:00.000000Z", "characterSet": "utf8", "language": "eng",
             "spatialRepresentationType": "along-track", "status": "onGoing",
             "topicCategory": "geoscientificInformation",
             "originatorOrganizationName": "physgen (synthetic; not a NASA product)",
             "abstract": "Synthetic pseudo-real GEDI granule written by physgen %s for simulator testing." % VERSION,
             "uuid": "%s-%s-%s-%s-%s" % (uu[:8], uu[8:12], uu[12:16], uu[16:20], uu[20:32])}
    for k, v in attrs.items():
        di.attrs[k] = np.array([v], dtype=object)


def shot_numbers(orbit, beam, recs):
    b = int(beam[4:], 2)
    return np.array([orbit * 10 ** 13 + b * 10 ** 11 + (2 * (r["k"] + 12) + 1) * 10 ** 8 + 1000000 + r["k"] + 12
                     for r in recs], dtype=np.uint64)


def write_l1b(path, tmp, g, beams_out, seed, ip):
    import h5py
    fname = os.path.basename(path)
    with h5py.File(path + tmp, "w", libver="earliest") as f:
        write_meta(f, "GEDI_L1B", fname, "005", seed, ip)
        for beam, bo in beams_out.items():
            recs = bo["recs"]
            n = len(recs)
            G = f.create_group(beam)
            G.attrs["description"] = np.array(["Coverage beam" if BEAM_TYPE[beam] == "coverage" else "Full power beam"], dtype=object)
            G.attrs["wp-l1a-to-l1b_version"] = np.array(["physgen-%s" % VERSION], dtype=object)
            sn = shot_numbers(g["orbit"], beam, recs)
            bo["shot_number"] = sn
            dt = bo["dt"]
            write_ds(G, "shot_number", sn, np.uint64)
            write_ds(G, "beam", np.full(n, int(beam[4:], 2)), np.uint16)
            write_ds(G, "channel", np.full(n, BEAM_CHANNEL[beam]), np.uint8)
            write_ds(G, "delta_time", dt, np.float64)
            write_ds(G, "master_int", np.floor(dt), np.uint32)
            write_ds(G, "master_frac", dt - np.floor(dt), np.float64)
            counts = np.array([r["n"] for r in recs])
            starts = np.r_[0, np.cumsum(counts)[:-1]] + 1
            write_ds(G, "rxwaveform", np.concatenate([r["wf"] for r in recs]), np.float32)
            write_ds(G, "rx_sample_count", counts, np.uint16)
            write_ds(G, "rx_sample_start_index", starts, np.uint64)
            write_ds(G, "txwaveform", np.concatenate([r["tx"] for r in recs]), np.float32)
            write_ds(G, "tx_sample_count", np.full(n, 128), np.uint16)
            write_ds(G, "tx_sample_start_index", np.arange(n) * 128 + 1, np.uint64)
            write_ds(G, "noise_mean_corrected", [r["nmean"] for r in recs], np.float64)
            write_ds(G, "noise_stddev_corrected", [r["nsd"] for r in recs], np.float64)
            write_ds(G, "nsemean_even", [r["nsemean"][0] for r in recs], np.float32)
            write_ds(G, "nsemean_odd", [r["nsemean"][1] for r in recs], np.float32)
            write_ds(G, "rx_energy", [float(np.sum(r["wf"].astype(float) - r["nmean"])) for r in recs], np.float64)
            write_ds(G, "all_samples_sum", [int(np.sum(r["wf"])) + 60000 * 2 for r in recs], np.uint32)
            write_ds(G, "rx_offset", np.full(n, 57800), np.uint16)
            write_ds(G, "rx_open", np.full(n, 2856192), np.uint32)
            write_ds(G, "stale_return_flag", np.zeros(n), np.uint8)
            write_ds(G, "selection_stretchers_x", np.full(n, 300), np.uint16)
            write_ds(G, "selection_stretchers_y", np.full(n, 400), np.uint16)
            write_ds(G, "th_left_used", np.full(n, 217), np.uint16)
            fits = np.array([r["tx_fit"] for r in recs])
            write_ds(G, "tx_egamplitude", fits[:, 0] * fits[:, 2] * math.sqrt(2 * math.pi), np.float32)
            write_ds(G, "tx_egbias", fits[:, 3], np.float32)
            write_ds(G, "tx_egsigma", fits[:, 2], np.float32)
            write_ds(G, "tx_eggamma", np.zeros(n), np.float32)
            write_ds(G, "tx_gloc", fits[:, 1], np.float32)
            for k in ("tx_egamplitude_error", "tx_egbias_error", "tx_egsigma_error", "tx_eggamma_error", "tx_gloc_error"):
                write_ds(G, k, np.zeros(n), np.float32)
            write_ds(G, "tx_egflag", np.ones(n), np.uint8)
            write_ds(G, "tx_pulseflag", np.ones(n), np.uint8)
            A = G.create_group("ancillary")
            write_ds(A, "master_time_epoch", [1198800018.0], np.float64)
            write_ds(A, "mean_samples", [20000], np.int64)
            write_ds(A, "smoothing_width", [2000.0], np.float64)
            L = G.create_group("geolocation")
            write_ds(L, "shot_number", sn, np.uint64)
            write_ds(L, "delta_time", dt, np.float64)
            write_ds(L, "elevation_bin0", bo["bin0"], np.float64)
            write_ds(L, "elevation_lastbin", bo["last"], np.float64)
            write_ds(L, "latitude_bin0", bo["latb0"], np.float64)
            write_ds(L, "longitude_bin0", bo["lonb0"], np.float64)
            write_ds(L, "latitude_lastbin", bo["latl"], np.float64)
            write_ds(L, "longitude_lastbin", bo["lonl"], np.float64)
            for k in ("elevation_bin0_error", "elevation_lastbin_error", "latitude_bin0_error", "longitude_bin0_error",
                      "latitude_lastbin_error", "longitude_lastbin_error", "altitude_instrument_error",
                      "latitude_instrument_error", "longitude_instrument_error", "local_beam_azimuth_error",
                      "local_beam_elevation_error", "bounce_time_offset_bin0_error",
                      "bounce_time_offset_lastbin_error"):
                write_ds(L, k, np.full(n, 3.0 if "elev" in k or "altitude" in k else 1e-5), np.float32)
            write_ds(L, "degrade", np.zeros(n), np.int8)
            dem = []
            for r in recs:
                rr = rng(seed, "dem", ip, beam, r["k"] + 100)
                dem.append(r["zg0"] + r["N"] + 0.4 * r["canopy_h95"] + rr.normal(0, 1.5))
            bo["dem"] = np.array(dem)
            write_ds(L, "digital_elevation_model", dem, np.float32)
            write_ds(L, "mean_sea_surface", bo["N"] - 0.3, np.float32)
            alt = 415000.0
            th = bo["theta"]
            u = bo["u"]
            write_ds(L, "altitude_instrument", np.full(n, alt) + bo["bin0"] * 0, np.float64)
            xi = np.array([r["x0"] + alt * math.tan(th) * u[0] for r in recs])
            yi = np.array([r["y0"] + alt * math.tan(th) * u[1] for r in recs])
            from pyproj import Transformer
            lo_i, la_i = Transformer.from_crs(2154, 4326, always_xy=True).transform(xi, yi)
            write_ds(L, "latitude_instrument", la_i, np.float64)
            write_ds(L, "longitude_instrument", lo_i, np.float64)
            rng0 = (alt - bo["bin0"]) / math.cos(th)
            write_ds(L, "bounce_time_offset_bin0", 2 * rng0 / C_LIGHT, np.float64)
            write_ds(L, "bounce_time_offset_lastbin", 2 * (rng0 + (bo["bin0"] - bo["last"]) / math.cos(th)) / C_LIGHT, np.float64)
            beam_az = math.atan2(-u[0], -u[1])  # azimuth of the downward beam's horizontal direction (rad, from north)
            write_ds(L, "local_beam_azimuth", np.full(n, beam_az), np.float32)
            write_ds(L, "local_beam_elevation", np.full(n, math.pi / 2 - th), np.float32)
            for k in ("neutat_delay_total_bin0", "neutat_delay_total_lastbin"):
                write_ds(L, k, np.full(n, 2.3), np.float32)
            for k in ("neutat_delay_derivative_bin0", "neutat_delay_derivative_lastbin"):
                write_ds(L, k, np.zeros(n), np.float32)
            write_ds(L, "range_bias_correction", np.zeros(n), np.float32)
            write_ds(L, "solar_elevation", np.full(n, g["sol"][0]), np.float32)
            write_ds(L, "solar_azimuth", np.full(n, g["sol"][1]), np.float32)
            st = np.zeros((5, n))
            st[0] = 1
            write_ds(L, "surface_type", st, np.int8)
            P = G.create_group("geophys_corr")
            write_ds(P, "delta_time", dt, np.float64)
            write_ds(P, "geoid", bo["N"], np.float32)
            for k in ("dynamic_atmosphere_correction", "tide_earth", "tide_load", "tide_ocean", "tide_ocean_pole",
                      "tide_pole"):
                write_ds(P, k, np.zeros(n), np.float32)
    os.replace(path + tmp, path)


def write_l2a(path, tmp, g, beams_out, seed, ip, eff, leaf_on):
    import h5py
    fname = os.path.basename(path)
    gd = eff.get("ground_detection")
    gd_algs = ()
    if gd:
        gd_algs = tuple(range(1, 7)) if gd["algorithm"] == "all" else (int(gd["algorithm"]),)
    with h5py.File(path + tmp, "w", libver="earliest") as f:
        write_meta(f, "GEDI_L2A", fname, "003", seed, ip)
        for beam, bo in beams_out.items():
            recs = bo["recs"]
            n = len(recs)
            G = f.create_group(beam)
            G.attrs["description"] = np.array(["Coverage beam" if BEAM_TYPE[beam] == "coverage" else "Full power beam"], dtype=object)
            sn = bo["shot_number"]
            res = {a: [] for a in range(1, 7)}
            for i, r in enumerate(recs):
                w = r["wf"].astype(float)
                for a in range(1, 7):
                    o = l2a_process(w, r["nmean"], r["nsd"], a)
                    if o["run"] and a in gd_algs:
                        # mis-detected ground: moved up by offset_m (in elevation) along the beam axis
                        dzs = (bo["bin0"][i] - bo["last"][i]) / (r["n"] - 1)
                        zc = o["zcross"] - gd["offset_m"] / dzs
                        o["zcross"] = zc
                        o["locs"] = o["locs"].copy()
                        o["locs"][o["sel"]] = zc
                    res[a].append(o)
            # per algorithm arrays
            per = {}
            for a in range(1, 7):
                P = {}
                z0 = bo["bin0"]
                zN = bo["last"]
                ns = np.array([r["n"] for r in recs], dtype=float)
                run = np.array([o["run"] for o in res[a]], dtype=np.uint8)
                P["run"] = run

                def pos(key, default=np.nan):
                    return np.array([o[key] if o["run"] else default for o in res[a]], dtype=float)

                zc = pos("zcross")
                tl = pos("toploc")
                bl = pos("botloc")
                P["zcross"], P["toploc"], P["botloc"] = zc, tl, bl

                def geo(p):
                    z = _z_at(p, z0, zN, ns)
                    la = _z_at(p, bo["latb0"], bo["latl"], ns)
                    lo = _z_at(p, bo["lonb0"], bo["lonl"], ns)
                    return z, la, lo
                P["low"] = geo(zc)
                P["high"] = geo(tl)
                P["lowret"] = geo(bl)
                modes = np.zeros((n, 20))
                amps = np.zeros((n, 20))
                lenerg = np.zeros((n, 20))
                nm = np.zeros(n, dtype=np.uint8)
                cum = np.zeros((n, 101))
                rh = np.zeros((n, 101), dtype=np.int16)
                sel = np.zeros(n, dtype=np.uint8)
                flag = np.zeros(n, dtype=np.uint8)
                for i, o in enumerate(res[a]):
                    if not o["run"]:
                        continue
                    m = len(o["locs"])
                    modes[i, :m] = o["locs"]
                    amps[i, :m] = o["amps"]
                    lenerg[i, :m] = o["localenergy"]
                    nm[i] = m
                    cum[i] = o["cum"]
                    sel[i] = o["sel"]
                    flag[i] = o["flag"]
                    zcum = _z_at(o["cum"], z0[i], zN[i], ns[i])
                    rh[i] = np.clip(np.trunc(100 * (zcum - _z_at(o["zcross"], z0[i], zN[i], ns[i]))), -32768, 32767)
                P.update(modes=modes, amps=amps, lenerg=lenerg, nm=nm, cum=cum, rh=rh, sel=sel, flag=flag)
                sd = np.array([r["nsd"] for r in recs])
                mu = np.array([r["nmean"] for r in recs])
                etot = np.array([float(np.sum(r["wf"].astype(float) - r["nmean"])) for r in recs])
                mdt = np.ceil(MDT_RATIO[a] * sd)
                mde = mdt * 6.5 * math.sqrt(2 * math.pi)
                sens = np.where(etot > 0, 1 - mde / np.maximum(etot, 1e-9), 0.0)
                P.update(sd=sd, mu=mu, etot=etot, mdt=mdt, mde=mde, sens=sens)
                zl = P["low"][0]
                dem = bo["dem"]
                zamp = pos("zcross_amp", 0.0)
                q = (run == 1) & (sens >= 0.9) & (np.abs(zl - dem) < 100) & (zamp - mu >= 3.0 * sd)
                P["quality"] = np.where(np.isnan(zl), 0, q).astype(np.uint8)
                P["zamp"] = zamp
                per[a] = P
            # selected algorithm (our rule, see README)
            dzs = (bo["bin0"] - bo["last"]) / (np.array([r["n"] for r in recs]) - 1)
            selalg = np.ones(n, dtype=np.uint8)
            for i in range(n):
                if per[1]["quality"][i] == 0:
                    for a in (2, 5, 3, 6, 4):
                        if per[a]["quality"][i]:
                            selalg[i] = a
                            break
                    else:
                        selalg[i] = 1
                    continue
                z1 = per[1]["low"][0][i]
                z5 = per[5]["low"][0][i]
                if (per[5]["quality"][i] and not np.isnan(z5) and z1 - z5 > 1.5
                        and per[5]["zamp"][i] - per[5]["mu"][i] >= 4 * per[5]["sd"][i]):
                    selalg[i] = 5
            del dzs

            def pick(key_fn, dtype):
                return np.array([key_fn(per[selalg[i]], i) for i in range(n)], dtype=dtype)

            dt = bo["dt"]
            write_ds(G, "shot_number", sn, np.uint64)
            write_ds(G, "beam", np.full(n, int(beam[4:], 2)), np.uint16)
            write_ds(G, "channel", np.full(n, BEAM_CHANNEL[beam]), np.uint8)
            write_ds(G, "delta_time", dt, np.float64)
            write_ds(G, "master_int", np.floor(dt), np.uint32)
            write_ds(G, "master_frac", dt - np.floor(dt), np.float64)
            write_ds(G, "selected_algorithm", selalg, np.uint8)
            write_ds(G, "quality_flag", pick(lambda P, i: P["quality"][i], np.uint8), np.uint8)
            write_ds(G, "degrade_flag", np.zeros(n), np.uint8)
            write_ds(G, "sensitivity", pick(lambda P, i: P["sens"][i], np.float32), np.float32)
            write_ds(G, "selected_mode", pick(lambda P, i: P["sel"][i], np.uint8), np.uint8)
            write_ds(G, "selected_mode_flag", pick(lambda P, i: P["flag"][i], np.uint8), np.uint8)
            write_ds(G, "elev_lowestmode", pick(lambda P, i: P["low"][0][i], np.float32), np.float32)
            write_ds(G, "lat_lowestmode", pick(lambda P, i: P["low"][1][i], np.float64), np.float64)
            write_ds(G, "lon_lowestmode", pick(lambda P, i: P["low"][2][i], np.float64), np.float64)
            write_ds(G, "elev_highestreturn", pick(lambda P, i: P["high"][0][i], np.float32), np.float32)
            write_ds(G, "lat_highestreturn", pick(lambda P, i: P["high"][1][i], np.float64), np.float64)
            write_ds(G, "lon_highestreturn", pick(lambda P, i: P["high"][2][i], np.float64), np.float64)
            rhsel = np.stack([per[selalg[i]]["rh"][i] for i in range(n)]).astype(np.float32) / np.float32(100)
            write_ds(G, "rh", rhsel, np.float32)
            write_ds(G, "energy_total", per[1]["etot"], np.float32)
            write_ds(G, "num_detectedmodes", pick(lambda P, i: P["nm"][i], np.uint8), np.uint8)
            write_ds(G, "digital_elevation_model", bo["dem"], np.float32)
            write_ds(G, "digital_elevation_model_srtm", bo["dem"] + 1.0, np.float32)
            write_ds(G, "elevation_bias_flag", np.zeros(n), np.uint8)
            write_ds(G, "surface_flag", np.ones(n), np.uint8)
            write_ds(G, "elevation_bin0_error", np.full(n, 3.0), np.float32)
            write_ds(G, "latitude_bin0_error", np.full(n, 1e-5), np.float32)
            write_ds(G, "longitude_bin0_error", np.full(n, 1e-5), np.float32)
            write_ds(G, "mean_sea_surface", bo["N"] - 0.3, np.float32)
            write_ds(G, "solar_elevation", np.full(n, g["sol"][0]), np.float32)
            write_ds(G, "solar_azimuth", np.full(n, g["sol"][1]), np.float32)
            A = G.create_group("ancillary")
            write_ds(A, "l2a_alg_count", [6], np.uint8)
            LC = G.create_group("land_cover_data")
            cover = np.array([1 - r["ground_energy_fraction"] for r in recs])
            write_ds(LC, "landsat_treecover", np.round(100 * cover), np.float64)
            write_ds(LC, "modis_treecover", np.round(90 * cover), np.float64)
            write_ds(LC, "modis_treecover_sd", np.full(n, 5.0), np.float64)
            write_ds(LC, "modis_nonvegetated", np.round(100 * (1 - cover) * 0.2), np.float64)
            write_ds(LC, "modis_nonvegetated_sd", np.full(n, 2.0), np.float64)
            write_ds(LC, "leaf_off_flag", np.full(n, 0 if leaf_on else 1), np.uint8)
            write_ds(LC, "leaf_off_doy", np.full(n, 305), np.int16)
            write_ds(LC, "leaf_on_doy", np.full(n, 110), np.int16)
            write_ds(LC, "leaf_on_cycle", np.ones(n), np.uint8)
            write_ds(LC, "pft_class", np.full(n, 4), np.uint8)
            write_ds(LC, "region_class", np.full(n, 1), np.uint8)
            write_ds(LC, "urban_proportion", np.zeros(n), np.uint8)
            write_ds(LC, "urban_focal_window_size", np.full(n, 3), np.uint8)
            write_ds(LC, "landsat_water_persistence", np.zeros(n), np.uint8)
            L = G.create_group("geolocation")
            write_ds(L, "shot_number", sn, np.uint64)
            write_ds(L, "stale_return_flag", np.zeros(n), np.uint8)
            lon1g = _z_at(np.array([float(np.argmax(r["wf"])) for r in recs]), bo["lonb0"], bo["lonl"], np.array([r["n"] for r in recs], float))
            lat1g = _z_at(np.array([float(np.argmax(r["wf"])) for r in recs]), bo["latb0"], bo["latl"], np.array([r["n"] for r in recs], float))
            z1g = _z_at(np.array([float(np.argmax(r["wf"])) for r in recs]), bo["bin0"], bo["last"], np.array([r["n"] for r in recs], float))
            write_ds(L, "elevation_1gfit", z1g, np.float32)
            write_ds(L, "latitude_1gfit", lat1g, np.float64)
            write_ds(L, "longitude_1gfit", lon1g, np.float64)
            for a in range(1, 7):
                P = per[a]
                s = "_a%d" % a
                write_ds(L, "elev_lowestmode" + s, P["low"][0], np.float32)
                write_ds(L, "lat_lowestmode" + s, P["low"][1], np.float64)
                write_ds(L, "lon_lowestmode" + s, P["low"][2], np.float64)
                write_ds(L, "elev_highestreturn" + s, P["high"][0], np.float32)
                write_ds(L, "lat_highestreturn" + s, P["high"][1], np.float64)
                write_ds(L, "lon_highestreturn" + s, P["high"][2], np.float64)
                write_ds(L, "elev_lowestreturn" + s, P["lowret"][0], np.float32)
                write_ds(L, "lat_lowestreturn" + s, P["lowret"][1], np.float64)
                write_ds(L, "lon_lowestreturn" + s, P["lowret"][2], np.float64)
                write_ds(L, "rh" + s, P["rh"], np.int16)
                write_ds(L, "sensitivity" + s, P["sens"], np.float32)
                write_ds(L, "quality_flag" + s, P["quality"], np.uint8)
                write_ds(L, "num_detectedmodes" + s, P["nm"], np.uint8)
                ns = np.array([r["n"] for r in recs], float)[:, None]
                em = np.where(P["modes"] > 0, _z_at(P["modes"], bo["bin0"][:, None], bo["last"][:, None], ns), 0)
                write_ds(L, "elevs_allmodes" + s, em, np.float32)
                write_ds(L, "lats_allmodes" + s, np.where(P["modes"] > 0, _z_at(P["modes"], bo["latb0"][:, None], bo["latl"][:, None], ns), 0), np.float64)
                write_ds(L, "lons_allmodes" + s, np.where(P["modes"] > 0, _z_at(P["modes"], bo["lonb0"][:, None], bo["lonl"][:, None], ns), 0), np.float64)
                write_ds(L, "energy_lowestmode" + s, [P["lenerg"][i, P["sel"][i]] for i in range(n)], np.float32)
                R = G.create_group("rx_processing" + s)
                wl, wz, kf, kb = ALGS[a]
                write_ds(R, "mean", P["mu"], np.float32)
                write_ds(R, "stddev", P["sd"], np.float32)
                write_ds(R, "sd_sm", P["sd"], np.float32)
                write_ds(R, "mean_sm", [o.get("mean_sm", np.nan) for o in res[a]], np.float32)
                write_ds(R, "front_threshold", P["mu"] + kf * P["sd"], np.float32)
                write_ds(R, "back_threshold", P["mu"] + kb * P["sd"], np.float32)
                write_ds(R, "search_start", np.zeros(n), np.float32)
                write_ds(R, "search_end", np.array([r["n"] - 1 for r in recs]), np.float32)
                write_ds(R, "toploc", P["toploc"], np.float32)
                write_ds(R, "toploc_miss", np.zeros(n), np.uint8)
                write_ds(R, "botloc", P["botloc"], np.float32)
                write_ds(R, "botloc_amp", [o.get("botloc_amp", np.nan) for o in res[a]], np.float32)
                write_ds(R, "zcross", P["zcross"], np.float32)
                write_ds(R, "zcross0", P["zcross"], np.float32)
                write_ds(R, "zcross_amp", P["zamp"], np.float32)
                write_ds(R, "zcross_localenergy", [P["lenerg"][i, P["sel"][i]] for i in range(n)], np.float32)
                write_ds(R, "lastmodeenergy", [P["lenerg"][i, P["sel"][i]] for i in range(n)], np.float32)
                write_ds(R, "peak", [float(r["wf"].max()) for r in recs], np.float32)
                write_ds(R, "pk_sm", [o.get("pk_sm", np.nan) for o in res[a]], np.float32)
                write_ds(R, "energy_sm", [o.get("energy_sm", np.nan) for o in res[a]], np.float32)
                write_ds(R, "min_detection_threshold", P["mdt"], np.float32)
                write_ds(R, "min_detection_energy", P["mde"], np.float32)
                write_ds(R, "rx_algrunflag", P["run"], np.uint8)
                write_ds(R, "rx_nummodes", P["nm"], np.uint8)
                write_ds(R, "rx_modelocs", P["modes"], np.float32)
                write_ds(R, "rx_modeamps", P["amps"], np.float32)
                write_ds(R, "rx_modewidths", np.zeros((n, 20)), np.float32)
                write_ds(R, "rx_modelocalenergy", P["lenerg"], np.float32)
                write_ds(R, "rx_cumulative", P["cum"], np.float32)
                write_ds(R, "selected_mode", P["sel"], np.uint8)
                write_ds(R, "selected_mode_flag", P["flag"], np.uint8)
                write_ds(R, "smoothwidth", np.full(n, wl), np.float32)
                write_ds(R, "smoothwidth_zcross", np.full(n, wz), np.float32)
                RA = R.create_group("ancillary")
                anc = {"rx_smoothing_width_locs": wl, "rx_smoothing_width_zcross": wz, "rx_front_threshold": kf,
                       "rx_back_threshold": kb, "rx_searchsize": 100.0, "rx_sentinel_location": 100.0,
                       "preprocessor_threshold": 4.0, "pulse_sep_thresh": 8.0, "energy_thresh": 50.0,
                       "amp_thresh": 50.0, "ampval_limit2": 250.0, "ampval_limit3": 500.0,
                       "botlocdist_limit1": 60.0, "botlocdist_limit2": 120.0, "botlocdist_limit3": 240.0,
                       "cumulative_energy_thresh": 2.5 if a == 2 else 0.0,
                       "cumulative_energy_minimum": 1.5 if a == 2 else 0.0}
                for k, v in anc.items():
                    write_ds(RA, k, [v], np.float64)
                write_ds(RA, "rx_subbin_resolution", [4], np.int64)
                write_ds(RA, "rx_max_mode_count", [20], np.int64)
                write_ds(RA, "rx_use_fixed_thresholds", [0], np.int32)
                write_ds(RA, "enable_select_mode", [1 if a == 2 else 0], np.int32)
            bo["l2a"] = per
            bo["selalg"] = selalg
    os.replace(path + tmp, path)


def shot_truth(r, bo, i, beam, l1b, l2a, g):
    sa = int(bo["selalg"][i])
    P = bo["l2a"][sa]
    N = r["N"]
    zl = float(P["low"][0][i])
    return {
        "shot_number": int(bo["shot_number"][i]),
        "beam": beam, "beam_type": BEAM_TYPE[beam], "granule": l1b, "granule_l2a": l2a,
        "x_true": r["x0"], "y_true": r["y0"],
        "x_reported": r["x0"] + r["dxr"], "y_reported": r["y0"] + r["dyr"],
        "track_offset_m": list(r["track_offset"]), "geolocation_effect_m": list(r["geo_effect"]),
        "dz_reported_m": r["dzr"],
        "off_nadir_deg": math.degrees(r["theta"]), "u_toward_satellite": [float(r["u"][0]), float(r["u"][1])],
        "geoid_m": N,
        "ground_true_ortho_m": r["zg0"], "ground_true_ellipsoid_m": r["zg0"] + N,
        "ground_footprint_weighted_ortho_m": r["zg_weighted"],
        "top_true_ortho_m": r["z_top"], "canopy_h95_m": r["canopy_h95"],
        "ground_energy_fraction": r["ground_energy_fraction"],
        "n_als_points": r["n_pts"],
        "tx_source_shot": r["tx_src"], "tx_jitter": r["tx_jitter"], "tx_gloc": r["gloc"],
        "rx_sample_count": r["n"],
        "noise_mean": r["nmean"], "noise_stddev_corrected": r["nsd"],
        "background_pe_per_ns": r["bg_rate"], "electronic_sigma_dn": r["sigma_e"],
        "selected_algorithm": sa,
        "l2a_elev_lowestmode": zl,
        "l2a_ground_minus_true_ellipsoid_m": (zl - (r["zg0"] + N)) if not math.isnan(zl) else None,
        "l2a_quality_flag": int(P["quality"][i]),
        "l2a_sensitivity": float(P["sens"][i]),
        "l2a_rh98_m": float(P["rh"][i][98]) / 100.0,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--effect", default="none")
    ap.add_argument("--param", action="append", default=[])
    ap.add_argument("--magnitude", type=float)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--tiles", required=True)
    ap.add_argument("--gedi", help="folder with real GEDI01_B*.h5 for the transmit pulses (default: <tiles>/../gedi)")
    ap.add_argument("--tile", help="force the source tile (file name in --tiles)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--passes", type=int, default=4)
    a = ap.parse_args(argv)
    build(a)


if __name__ == "__main__":
    main()
