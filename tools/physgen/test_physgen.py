"""pytest for physgen (run: python3 -m pytest -q tools/physgen/test_physgen.py; < 60 s on 2 cores)."""
import glob
import hashlib
import json
import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import h5py
import numpy as np

sys.dont_write_bytecode = True
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
TILES = os.path.join(ROOT, "tests", "data", "als")
sys.path.insert(0, HERE)
import physgen  # noqa: E402

SEED = 5
WORLDS = {
    "control": ["--effect", "none"],
    "control_again": ["--effect", "none"],
    # datum + ground_detection(all): bin0 moves by dz only, every algorithm's ground by dz + offset
    "datum_gd": ["--effect", "datum+ground_detection", "--param", "datum.dz_m=0.6",
                 "--param", "ground_detection.algorithm=all", "--param", "ground_detection.offset_m=0.5"],
    "canopy": ["--effect", "canopy_change", "--param", "height_m=5", "--magnitude", "0.6"],
    "noise_geo": ["--effect", "noise+geolocation", "--param", "noise.noise_sigma_factor=2.0",
                  "--param", "geolocation.shot_sigma_m=3"],
}


@pytest.fixture(scope="session")
def worlds(tmp_path_factory):
    base = tmp_path_factory.mktemp("physgen")

    def run(item):
        name, args = item
        out = str(base / name)
        subprocess.run([sys.executable, os.path.join(HERE, "physgen.py"), "--seed", str(SEED), "--tiles", TILES,
                        "--out", out, "--passes", "1"] + args, check=True, capture_output=True)
        return name, out

    with ThreadPoolExecutor(2) as ex:
        return dict(ex.map(run, WORLDS.items()))


def tree_hashes(d):
    out = {}
    for p in sorted(glob.glob(os.path.join(d, "**", "*"), recursive=True)):
        if os.path.isfile(p):
            out[os.path.relpath(p, d)] = hashlib.sha256(open(p, "rb").read()).hexdigest()
    return out


def granules(d):
    l1 = sorted(glob.glob(os.path.join(d, "gedi", "GEDI01_B_*.h5")))
    l2 = sorted(glob.glob(os.path.join(d, "gedi", "GEDI02_A_*.h5")))
    return l1, l2


def per_shot(d, l1key=None, l2key=None):
    """dict shot_number -> value from all granules."""
    out = {}
    l1, l2 = granules(d)
    for fn in (l1 if l1key else l2):
        with h5py.File(fn, "r") as f:
            for b in f:
                if not b.startswith("BEAM"):
                    continue
                sn = f[b]["shot_number"][:]
                v = f[b][l1key or l2key][:]
                for i, s in enumerate(sn):
                    out[int(s)] = v[i]
    return out


def test_determinism(worlds):
    a = tree_hashes(worlds["control"])
    b = tree_hashes(worlds["control_again"])
    assert a == b
    assert any(k.endswith("truth.json") for k in a)
    assert no_tmp(worlds["control"])


def no_tmp(d):
    return not [p for p in glob.glob(os.path.join(d, "**", "*"), recursive=True) if ".tmp" in os.path.basename(p)]


def test_names_and_truth(worlds):
    d = worlds["control"]
    l1, l2 = granules(d)
    assert len(l1) == len(l2) == 1
    s1 = [os.path.basename(p) for p in l1]
    s2 = [os.path.basename(p) for p in l2]
    pat1 = re.compile(r"^GEDI01_B_(\d{13}_O\d{5}_\d{2}_T\d{5}_02)_005_02_V002\.h5$")
    pat2 = re.compile(r"^GEDI02_A_(\d{13}_O\d{5}_\d{2}_T\d{5}_02)_003_02_V002\.h5$")
    assert [pat1.match(x).group(1) for x in s1] == [pat2.match(x).group(1) for x in s2]
    t = json.load(open(os.path.join(d, "truth.json")))
    assert t["generator"].startswith("physgen ")
    assert t["seed"] == SEED and t["effects"] == [] and t["datum_dz_m"] == 0.0
    assert 40 <= len(t["shots"]) <= 120  # 1 pass here; 4 passes (default) give ~150-300
    for s in t["shots"]:
        for k in ("shot_number", "beam", "granule", "x_true", "y_true", "x_reported", "y_reported"):
            assert k in s
        assert abs(s["x_reported"] - s["x_true"] - s["track_offset_m"][0]) < 1e-9


def test_als(worlds):
    import laspy
    fs = sorted(glob.glob(os.path.join(worlds["control"], "als", "*.laz")))
    assert len(fs) == 25
    xs, ys = [], []
    for fn in fs[:3] + fs[-1:]:
        las = laspy.read(fn)
        assert las.header.point_format.id == 6 and str(las.header.version) == "1.4"
        assert las.header.global_encoding.wkt
        assert "2154" in las.header.parse_crs().to_wkt() or las.header.parse_crs().to_epsg() == 2154
        rn = np.asarray(las.return_number)
        nr = np.asarray(las.number_of_returns)
        assert np.all(rn <= nr) and np.all(rn >= 1)
        assert np.any(np.asarray(las.classification) == 2)
    for fn in fs:
        with laspy.open(fn) as r:
            xs += [r.header.mins[0], r.header.maxs[0]]
            ys += [r.header.mins[1], r.header.maxs[1]]
    assert max(xs) - min(xs) >= 450 and max(ys) - min(ys) >= 450


L1B_DT = {"shot_number": "uint64", "beam": "uint16", "channel": "uint8", "delta_time": "float64",
          "master_int": "uint32", "master_frac": "float64", "rxwaveform": "float32", "rx_sample_count": "uint16",
          "rx_sample_start_index": "uint64", "txwaveform": "float32", "tx_sample_count": "uint16",
          "tx_sample_start_index": "uint64", "noise_mean_corrected": "float64", "noise_stddev_corrected": "float64",
          "rx_energy": "float64", "stale_return_flag": "uint8", "tx_gloc": "float32",
          "geolocation/elevation_bin0": "float64", "geolocation/elevation_lastbin": "float64",
          "geolocation/latitude_bin0": "float64", "geolocation/longitude_bin0": "float64",
          "geolocation/latitude_lastbin": "float64", "geolocation/longitude_lastbin": "float64",
          "geolocation/degrade": "int8", "geolocation/digital_elevation_model": "float32",
          "geophys_corr/geoid": "float32", "geolocation/surface_type": "int8"}
L2A_DT = {"shot_number": "uint64", "quality_flag": "uint8", "degrade_flag": "uint8", "sensitivity": "float32",
          "selected_algorithm": "uint8", "selected_mode": "uint8", "selected_mode_flag": "uint8",
          "elev_lowestmode": "float32", "elev_highestreturn": "float32", "lat_lowestmode": "float64",
          "lon_lowestmode": "float64", "rh": "float32", "energy_total": "float32", "num_detectedmodes": "uint8",
          "land_cover_data/leaf_off_flag": "uint8", "land_cover_data/pft_class": "uint8",
          "ancillary/l2a_alg_count": "uint8"}
for _a in range(1, 7):
    L2A_DT.update({"geolocation/elev_lowestmode_a%d" % _a: "float32", "geolocation/rh_a%d" % _a: "int16",
                   "geolocation/sensitivity_a%d" % _a: "float32", "geolocation/quality_flag_a%d" % _a: "uint8",
                   "geolocation/lat_lowestmode_a%d" % _a: "float64", "rx_processing_a%d/zcross" % _a: "float32",
                   "rx_processing_a%d/rx_cumulative" % _a: "float32"})


def test_layout_and_relations(worlds):
    l1, l2 = granules(worlds["control"])
    with h5py.File(l1[0], "r") as f, h5py.File(l2[0], "r") as g:
        assert f.attrs["short_name"][0] == "GEDI_L1B" and g.attrs["short_name"][0] == "GEDI_L2A"
        beams = [b for b in f if b.startswith("BEAM")]
        assert sorted(beams) == sorted(b for b in g if b.startswith("BEAM"))
        assert len(beams) == 8
        for b in beams:
            B, L = f[b], g[b]
            desc = B.attrs["description"][0]
            assert desc == ("Coverage beam" if int(b[4:], 2) < 4 else "Full power beam")
            for k, dt in L1B_DT.items():
                assert str(B[k].dtype) == dt, (b, k, B[k].dtype)
            for k, dt in L2A_DT.items():
                assert str(L[k].dtype) == dt, (b, k, L[k].dtype)
            n = len(B["shot_number"])
            assert B["geolocation/surface_type"].shape == (5, n)
            assert L["rh"].shape == (n, 101) and L["geolocation/rh_a3"].shape == (n, 101)
            assert np.array_equal(B["shot_number"][:], L["shot_number"][:])
            st = B["rx_sample_start_index"][:].astype(np.int64)
            c = B["rx_sample_count"][:].astype(np.int64)
            assert st[0] == 1 and np.all(st[1:] == st[:-1] + c[:-1]) and st[-1] - 1 + c[-1] == len(B["rxwaveform"])
            assert np.all(B["tx_sample_count"][:] == 128)
            sel = L["selected_algorithm"][:]
            for i in range(n):
                a = int(sel[i])
                assert np.allclose(L["rh"][i], L["geolocation/rh_a%d" % a][i] / 100.0, atol=1e-6)
                assert L["elev_lowestmode"][i] == L["geolocation/elev_lowestmode_a%d" % a][i]
                # sample -> elevation mapping (gedi-products.md §1) reproduces elev_lowestmode from zcross
                z0 = B["geolocation/elevation_bin0"][i]
                zN = B["geolocation/elevation_lastbin"][i]
                zc = L["rx_processing_a%d/zcross" % a][i]
                assert abs(z0 + (zN - z0) * zc / (c[i] - 1) - L["elev_lowestmode"][i]) < 2e-3
            # slanted beam: bin0 and lastbin positions differ horizontally
            assert np.all(np.abs(B["geolocation/latitude_bin0"][:] - B["geolocation/latitude_lastbin"][:]) +
                          np.abs(B["geolocation/longitude_bin0"][:] - B["geolocation/longitude_lastbin"][:]) > 1e-6)


def test_datum_moves_elevations_exactly(worlds):
    c0 = per_shot(worlds["control"], l1key="geolocation/elevation_bin0")
    c1 = per_shot(worlds["datum_gd"], l1key="geolocation/elevation_bin0")
    d = np.array([c1[k] - c0[k] for k in c0])
    assert np.allclose(d, 0.6, atol=1e-9)
    w0 = per_shot(worlds["control"], l1key="noise_stddev_corrected")
    w1 = per_shot(worlds["datum_gd"], l1key="noise_stddev_corrected")
    assert all(w0[k] == w1[k] for k in w0)  # same waveforms and noise draws
    assert json.load(open(os.path.join(worlds["datum_gd"], "truth.json")))["datum_dz_m"] == 0.6


def test_control_ground_matches_als(worlds):
    import laspy
    d = worlds["control"]
    t = json.load(open(os.path.join(d, "truth.json")))
    zl = per_shot(d, l2key="elev_lowestmode")
    q = per_shot(d, l2key="quality_flag")
    pts = []
    for fn in sorted(glob.glob(os.path.join(d, "als", "*.laz"))):
        las = laspy.read(fn)
        g = np.asarray(las.classification) == 2
        pts.append(np.c_[np.asarray(las.x)[g], np.asarray(las.y)[g], np.asarray(las.z)[g]])
    pts = np.concatenate(pts)
    err = []
    for s in t["shots"]:
        if not q[s["shot_number"]]:
            continue
        m = (np.abs(pts[:, 0] - s["x_true"]) < 2.5) & (np.abs(pts[:, 1] - s["y_true"]) < 2.5)
        if m.sum() < 3:
            continue
        z_als = np.median(pts[m, 2])
        err.append(zl[s["shot_number"]] - s["geoid_m"] - s["dz_reported_m"] - z_als)
    err = np.array(err)
    assert len(err) > 30
    assert abs(np.median(err)) < 0.8
    assert np.mean(np.abs(err) < 3.0) > 0.85


def test_ground_detection_all(worlds):
    l1c, l2c = granules(worlds["control"])
    l1e, l2e = granules(worlds["datum_gd"])
    with h5py.File(l2c[0], "r") as c, h5py.File(l2e[0], "r") as e:
        for b in (k for k in c if k.startswith("BEAM")):
            for a in range(1, 7):
                dz = e[b]["geolocation/elev_lowestmode_a%d" % a][:] - c[b]["geolocation/elev_lowestmode_a%d" % a][:]
                assert np.allclose(dz, 0.6 + 0.5, atol=2e-3)
                drh = e[b]["geolocation/rh_a%d" % a][:].astype(int) - c[b]["geolocation/rh_a%d" % a][:].astype(int)
                assert np.all(np.abs(drh + 50) <= 1)


def test_canopy_change_and_noise(worlds):
    e0 = per_shot(worlds["control"], l1key="rx_energy")
    e1 = per_shot(worlds["canopy"], l1key="rx_energy")
    r = np.array([e1[k] / e0[k] for k in e0])
    assert np.median(r) < 0.8  # 60 % of the energy above 5 m removed
    g0 = per_shot(worlds["control"], l2key="elev_lowestmode")
    g1 = per_shot(worlds["canopy"], l2key="elev_lowestmode")
    assert abs(np.median([g1[k] - g0[k] for k in g0])) < 0.3  # ground stays
    n0 = per_shot(worlds["control"], l1key="noise_stddev_corrected")
    n1 = per_shot(worlds["noise_geo"], l1key="noise_stddev_corrected")
    assert 1.85 < np.median([n1[k] / n0[k] for k in n0]) < 2.15
    b0 = per_shot(worlds["control"], l1key="geolocation/latitude_bin0")
    b1 = per_shot(worlds["noise_geo"], l1key="geolocation/latitude_bin0")
    assert np.median([abs(b1[k] - b0[k]) for k in b0]) > 3e-6  # ~0.3 m+ in latitude
    t = json.load(open(os.path.join(worlds["noise_geo"], "truth.json")))
    assert [x["name"] for x in t["effects"]] == ["noise", "geolocation"]
    for s in t["shots"]:
        assert abs(s["x_reported"] - s["x_true"] - s["track_offset_m"][0] - s["geolocation_effect_m"][0]) < 1e-9


def test_parse_effects():
    assert physgen.parse_effects("none", [], None) == []
    e = physgen.parse_effects("datum+pulse", ["pulse.pulse_sigma_m=1.4"], 0.6)
    assert e == [("datum", {"dz_m": 0.6}), ("pulse", {"pulse_sigma_m": 1.4})]
    with pytest.raises(SystemExit):
        physgen.parse_effects("nosuch", [], None)
    with pytest.raises(SystemExit):
        physgen.parse_effects("ground_detection", ["algorithm=7"], None)
