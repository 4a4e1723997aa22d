"""Quick self-check of worldgen (pytest).  Runs ~1-2 minutes on 2 cores.

    python3 -m pytest -q tools/worldgen/test_worldgen.py
"""
from __future__ import annotations

import glob
import hashlib
import json
import os
import re
import sys
import time

import numpy as np
import pytest

h5py = pytest.importorskip("h5py")
laspy = pytest.importorskip("laspy")

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import worldgen  # noqa: E402

ALS_DIR = os.path.join(HERE, "..", "..", "tests", "data", "als")
TILE = os.path.join(ALS_DIR, "lidarforfuel_2_bas_lig.laz")
REAL_L1B = sorted(glob.glob(os.path.join(HERE, "..", "..", "tests", "data", "gedi", "GEDI01_B_*.h5")))
SEED = 7

pytestmark = pytest.mark.skipif(not os.path.exists(TILE) or not REAL_L1B,
                                reason="bundled ALS/GEDI test data not found")


def make(root, name, *extra, seed=SEED, pref="gaussian-fit"):
    out = os.path.join(root, name)
    argv = ["--seed", str(seed), "--tiles", TILE, "--out", out, "--passes", "3", "--grid", "3",
            "--pulse-reference", pref, "--quiet", *extra]
    t0 = time.time()
    worldgen.main(argv)
    return out, time.time() - t0


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return str(tmp_path_factory.mktemp("worlds"))


@pytest.fixture(scope="module")
def control(root):
    out, dt = make(root, "control")
    return out, dt


# ------------------------------------------------------------------------------------------
# readers used by the checks
# ------------------------------------------------------------------------------------------
def pairs(world):
    l1 = sorted(glob.glob(os.path.join(world, "gedi", "GEDI01_B_*.h5")))
    out = []
    for f1 in l1:
        f2 = f1.replace("GEDI01_B_", "GEDI02_A_").replace("_005_02_V002", "_003_02_V002")
        assert os.path.exists(f2), f2
        out.append((f1, f2))
    return out


def shots(world):
    """Per shot: L1B waveform and geolocation, L2A main fields, keyed by shot_number."""
    res = {}
    for f1, f2 in pairs(world):
        with h5py.File(f1, "r") as a, h5py.File(f2, "r") as b:
            for beam in [k for k in a.keys() if k.startswith("BEAM")]:
                A, B = a[beam], b[beam]
                st = A["rx_sample_start_index"][:].astype(np.int64) - 1
                n = A["rx_sample_count"][:].astype(np.int64)
                rx = A["rxwaveform"][:]
                tx = A["txwaveform"][:].reshape(-1, 128)
                sn2 = {int(s): i for i, s in enumerate(B["shot_number"][:])}
                for i, sn in enumerate(A["shot_number"][:]):
                    j = sn2[int(sn)]
                    res[int(sn)] = dict(
                        beam=beam, rx=rx[st[i]:st[i] + n[i]].astype(float), tx=tx[i].astype(float),
                        mu=A["noise_mean_corrected"][i], sd=A["noise_stddev_corrected"][i],
                        z0=A["geolocation/elevation_bin0"][i], zN=A["geolocation/elevation_lastbin"][i],
                        elev=float(B["elev_lowestmode"][j]),
                        elev_a={k: float(B[f"geolocation/elev_lowestmode_a{k}"][j]) for k in range(1, 7)},
                        rh=B["rh"][j].astype(float), rh_a1=B["geolocation/rh_a1"][j].astype(int),
                        rh_a2=B["geolocation/rh_a2"][j].astype(int),
                        sel=int(B["selected_algorithm"][j]), q=int(B["quality_flag"][j]),
                        energy=float(A["rx_energy"][i]),
                        top=float(B["rx_processing_a1/toploc"][j]), bot=float(B["rx_processing_a1/botloc"][j]))
    return res


def truth(world):
    with open(os.path.join(world, "truth.json")) as fh:
        return json.load(fh)


def digest(world, pattern="**/*"):
    out = {}
    for p in sorted(glob.glob(os.path.join(world, pattern), recursive=True)):
        if os.path.isfile(p):
            with open(p, "rb") as fh:
                out[os.path.relpath(p, world)] = hashlib.sha256(fh.read()).hexdigest()
    return out


# ------------------------------------------------------------------------------------------
# V2 layout, transcribed from gedi-products.md §1-§3 (name: dtype; shape kind)
# "N" = per shot, "W" = concatenated waveform, "T" = concatenated tx, "1" = (1,), "5N" = (5, N),
# "N101"/"N20" = 2-D
# ------------------------------------------------------------------------------------------
L1B_FIELDS = {
    "shot_number": ("uint64", "N"), "beam": ("uint16", "N"), "channel": ("uint8", "N"),
    "delta_time": ("float64", "N"), "master_int": ("uint32", "N"), "master_frac": ("float64", "N"),
    "rxwaveform": ("float32", "W"), "rx_sample_count": ("uint16", "N"),
    "rx_sample_start_index": ("uint64", "N"), "txwaveform": ("float32", "T"),
    "tx_sample_count": ("uint16", "N"), "tx_sample_start_index": ("uint64", "N"),
    "noise_mean_corrected": ("float64", "N"), "noise_stddev_corrected": ("float64", "N"),
    "nsemean_even": ("float32", "N"), "nsemean_odd": ("float32", "N"), "rx_energy": ("float64", "N"),
    "all_samples_sum": ("uint32", "N"), "rx_offset": ("uint16", "N"), "rx_open": ("uint32", "N"),
    "stale_return_flag": ("uint8", "N"), "selection_stretchers_x": ("uint16", "N"),
    "selection_stretchers_y": ("uint16", "N"), "th_left_used": ("uint16", "N"),
    "tx_egamplitude": ("float32", "N"), "tx_egbias": ("float32", "N"), "tx_egsigma": ("float32", "N"),
    "tx_eggamma": ("float32", "N"), "tx_gloc": ("float32", "N"), "tx_egamplitude_error": ("float32", "N"),
    "tx_egbias_error": ("float32", "N"), "tx_egsigma_error": ("float32", "N"),
    "tx_eggamma_error": ("float32", "N"), "tx_gloc_error": ("float32", "N"),
    "tx_egflag": ("uint8", "N"), "tx_pulseflag": ("uint8", "N"),
    "ancillary/master_time_epoch": ("float64", "1"), "ancillary/mean_samples": ("int64", "1"),
    "ancillary/smoothing_width": ("float64", "1"),
    "geolocation/elevation_bin0": ("float64", "N"), "geolocation/elevation_lastbin": ("float64", "N"),
    "geolocation/latitude_bin0": ("float64", "N"), "geolocation/longitude_bin0": ("float64", "N"),
    "geolocation/latitude_lastbin": ("float64", "N"), "geolocation/longitude_lastbin": ("float64", "N"),
    "geolocation/elevation_bin0_error": ("float32", "N"), "geolocation/elevation_lastbin_error": ("float32", "N"),
    "geolocation/latitude_bin0_error": ("float32", "N"), "geolocation/longitude_bin0_error": ("float32", "N"),
    "geolocation/latitude_lastbin_error": ("float32", "N"), "geolocation/longitude_lastbin_error": ("float32", "N"),
    "geolocation/altitude_instrument_error": ("float32", "N"),
    "geolocation/latitude_instrument_error": ("float32", "N"),
    "geolocation/longitude_instrument_error": ("float32", "N"),
    "geolocation/bounce_time_offset_bin0_error": ("float32", "N"),
    "geolocation/bounce_time_offset_lastbin_error": ("float32", "N"),
    "geolocation/local_beam_azimuth_error": ("float32", "N"),
    "geolocation/local_beam_elevation_error": ("float32", "N"),
    "geolocation/degrade": ("int8", "N"), "geolocation/digital_elevation_model": ("float32", "N"),
    "geolocation/mean_sea_surface": ("float32", "N"), "geolocation/shot_number": ("uint64", "N"),
    "geolocation/delta_time": ("float64", "N"), "geolocation/altitude_instrument": ("float64", "N"),
    "geolocation/latitude_instrument": ("float64", "N"), "geolocation/longitude_instrument": ("float64", "N"),
    "geolocation/bounce_time_offset_bin0": ("float64", "N"),
    "geolocation/bounce_time_offset_lastbin": ("float64", "N"),
    "geolocation/local_beam_azimuth": ("float32", "N"), "geolocation/local_beam_elevation": ("float32", "N"),
    "geolocation/neutat_delay_total_bin0": ("float32", "N"), "geolocation/neutat_delay_total_lastbin": ("float32", "N"),
    "geolocation/neutat_delay_derivative_bin0": ("float32", "N"),
    "geolocation/neutat_delay_derivative_lastbin": ("float32", "N"),
    "geolocation/range_bias_correction": ("float32", "N"), "geolocation/solar_azimuth": ("float32", "N"),
    "geolocation/solar_elevation": ("float32", "N"), "geolocation/surface_type": ("int8", "5N"),
    "geophys_corr/delta_time": ("float64", "N"),
    **{f"geophys_corr/{k}": ("float32", "N") for k in
       ("dynamic_atmosphere_correction", "geoid", "tide_earth", "tide_load", "tide_ocean",
        "tide_ocean_pole", "tide_pole")},
}

L2A_ROOT = {
    "shot_number": ("uint64", "N"), "beam": ("uint16", "N"), "channel": ("uint8", "N"),
    "delta_time": ("float64", "N"), "master_int": ("uint32", "N"), "master_frac": ("float64", "N"),
    "quality_flag": ("uint8", "N"), "degrade_flag": ("uint8", "N"), "sensitivity": ("float32", "N"),
    "selected_algorithm": ("uint8", "N"), "selected_mode": ("uint8", "N"),
    "selected_mode_flag": ("uint8", "N"), "elev_lowestmode": ("float32", "N"),
    "elev_highestreturn": ("float32", "N"), "lat_lowestmode": ("float64", "N"),
    "lon_lowestmode": ("float64", "N"), "lat_highestreturn": ("float64", "N"),
    "lon_highestreturn": ("float64", "N"), "rh": ("float32", "N101"), "energy_total": ("float32", "N"),
    "num_detectedmodes": ("uint8", "N"), "digital_elevation_model": ("float32", "N"),
    "digital_elevation_model_srtm": ("float32", "N"), "elevation_bias_flag": ("uint8", "N"),
    "surface_flag": ("uint8", "N"), "elevation_bin0_error": ("float32", "N"),
    "latitude_bin0_error": ("float32", "N"), "longitude_bin0_error": ("float32", "N"),
    "mean_sea_surface": ("float32", "N"), "solar_azimuth": ("float32", "N"),
    "solar_elevation": ("float32", "N"), "ancillary/l2a_alg_count": ("uint8", "1"),
    **{f"land_cover_data/{k}": ("float64", "N") for k in
       ("landsat_treecover", "modis_nonvegetated", "modis_nonvegetated_sd", "modis_treecover",
        "modis_treecover_sd")},
    "land_cover_data/leaf_off_flag": ("uint8", "N"), "land_cover_data/leaf_off_doy": ("int16", "N"),
    "land_cover_data/leaf_on_doy": ("int16", "N"),
    **{f"land_cover_data/{k}": ("uint8", "N") for k in
       ("leaf_on_cycle", "pft_class", "region_class", "urban_proportion", "urban_focal_window_size",
        "landsat_water_persistence")},
    "geolocation/elevation_1gfit": ("float32", "N"), "geolocation/latitude_1gfit": ("float64", "N"),
    "geolocation/longitude_1gfit": ("float64", "N"), "geolocation/stale_return_flag": ("uint8", "N"),
}
L2A_PER_ALG = {
    "elev_lowestmode_a{}": ("float32", "N"), "elev_highestreturn_a{}": ("float32", "N"),
    "elev_lowestreturn_a{}": ("float32", "N"),
    **{f"{c}_{w}_a{{}}": ("float64", "N") for c in ("lat", "lon")
       for w in ("lowestmode", "highestreturn", "lowestreturn")},
    "rh_a{}": ("int16", "N101"), "sensitivity_a{}": ("float32", "N"), "quality_flag_a{}": ("uint8", "N"),
    "num_detectedmodes_a{}": ("uint8", "N"), "energy_lowestmode_a{}": ("float32", "N"),
    "elevs_allmodes_a{}": (("float32", "float64"), "N20"), "lats_allmodes_a{}": ("float64", "N20"),
    "lons_allmodes_a{}": ("float64", "N20"),
}
BEAM_NAMES = {"BEAM0000", "BEAM0001", "BEAM0010", "BEAM0011", "BEAM0101", "BEAM0110", "BEAM1000", "BEAM1011"}
NAME_RE = re.compile(r"^GEDI0(1_B|2_A)_\d{13}_O\d{5}_\d{2}_T\d{5}_\d{2}_\d{3}_\d{2}_V002\.h5$")


def _check(group, fields, N, W=None):
    for name, (dtype, kind) in fields.items():
        assert name in group, f"{group.name}/{name} missing"
        ds = group[name]
        ok = (ds.dtype.name in dtype) if isinstance(dtype, tuple) else ds.dtype.name == dtype
        assert ok, f"{group.name}/{name}: dtype {ds.dtype} != {dtype}"
        want = {"N": (N,), "1": (1,), "5N": (5, N), "N101": (N, 101), "N20": (N, 20),
                "T": (128 * N,), "W": (W,)}[kind]
        assert ds.shape == want, f"{group.name}/{name}: shape {ds.shape} != {want}"


# ------------------------------------------------------------------------------------------
def test_small_world_generates_in_seconds(control):
    world, dt = control
    assert dt < 45, f"small world took {dt:.1f} s"
    t = truth(world)
    assert len(t["tracks"]) >= 8 and len(t["shots"]) >= 30
    assert glob.glob(os.path.join(world, "als", "*.laz"))
    assert not glob.glob(os.path.join(world, "**", "*.tmp"), recursive=True)
    for key in ("generator", "seed", "effects", "pulse_reference", "geoid_m", "datum_dz_m", "tracks", "shots", "scene"):
        assert key in t
    assert 44 <= t["geoid_m"] <= 55
    assert t["generator"].startswith("worldgen ")


def test_v2_layout(control):
    world, _ = control
    for f1, f2 in pairs(world):
        assert NAME_RE.match(os.path.basename(f1)) and NAME_RE.match(os.path.basename(f2))
        with h5py.File(f1, "r") as a:
            assert a.attrs["short_name"][0] in ("GEDI_L1B", b"GEDI_L1B")
            beams = [k for k in a.keys() if k.startswith("BEAM")]
            assert beams and set(beams) <= BEAM_NAMES
            for b in beams:
                G = a[b]
                N = G["shot_number"].shape[0]
                cnt = G["rx_sample_count"][:].astype(np.int64)
                _check(G, L1B_FIELDS, N, W=int(cnt.sum()))
                start = G["rx_sample_start_index"][:].astype(np.int64)
                assert start[0] == 1 and np.all(start[1:] == start[:-1] + cnt[:-1])
                assert np.all(G["tx_sample_count"][:] == 128)
                assert np.all(G["tx_sample_start_index"][:] == 1 + 128 * np.arange(N))
                assert np.all((cnt >= 600) & (cnt <= 2400))
                assert G.attrs["description"][0] in ("Coverage beam", "Full power beam", b"Coverage beam", b"Full power beam")
                assert np.all(G["beam"][:] == int(b[4:], 2))
                assert np.all(G["geolocation/degrade"][:] == 0) and np.all(G["stale_return_flag"][:] == 0)
        with h5py.File(f2, "r") as c:
            assert c.attrs["short_name"][0] in ("GEDI_L2A", b"GEDI_L2A")
            for b in [k for k in c.keys() if k.startswith("BEAM")]:
                G = c[b]
                N = G["shot_number"].shape[0]
                _check(G, L2A_ROOT, N)
                for k in range(1, 7):
                    _check(G["geolocation"], {n.format(k): v for n, v in L2A_PER_ALG.items()}, N)
                sel = G["selected_algorithm"][:]
                for i in range(N):
                    if sel[i]:
                        s = int(sel[i])
                        assert G["elev_lowestmode"][i] == G[f"geolocation/elev_lowestmode_a{s}"][i]
                        assert np.array_equal(G["rh"][i], G[f"geolocation/rh_a{s}"][i].astype(np.float32) / np.float32(100))
                        assert G["quality_flag"][i] == G[f"geolocation/quality_flag_a{s}"][i]
                assert np.mean(G["quality_flag"][:] == 1) > 0.5


def test_als_tiles_have_crs(control):
    world, _ = control
    for p in glob.glob(os.path.join(world, "als", "*.laz")):
        las = laspy.read(p)
        assert las.header.version.major == 1 and las.header.version.minor == 4
        assert las.header.point_format.id == 6
        assert las.header.parse_crs().to_epsg() == 2154
        assert len(las.points) > 0


def test_same_seed_same_bytes(root, control):
    world, _ = control
    again, _ = make(root, "control_again")
    assert digest(world) == digest(again)


def test_control_ground_near_als(control):
    world, _ = control
    t = truth(world)
    S = shots(world)
    exp = {int(s["shot_number"]): s["expected_gedi_ground_m"] for s in t["shots"]}
    err = np.array([S[k]["elev"] - exp[k] for k in S if S[k]["sel"]])
    assert abs(np.median(err)) < 0.3, np.median(err)
    assert np.median(np.abs(err)) < 0.5
    # the truth contract: signs of dx/dy, dz
    tracks = {tr["id"]: tr for tr in t["tracks"]}
    for s in t["shots"]:
        tr = tracks[s["track"]]
        assert abs(s["x_true"] - s["x_reported"] - tr["dx_m"]) < 2e-3
        assert abs(s["y_true"] - s["y_reported"] - tr["dy_m"]) < 2e-3
        assert tr["dz_m"] == t["datum_dz_m"] == 0.0
        assert int(s["shot_number"]) in S


def test_datum_moves_elevations(root, control):
    world, _ = control
    w2, _ = make(root, "datum", "--effect", "datum", "--param", "dz_m=0.5")
    a, b = shots(world), shots(w2)
    assert a.keys() == b.keys()
    t = truth(w2)
    assert t["datum_dz_m"] == 0.5 and all(tr["dz_m"] == 0.5 for tr in t["tracks"])
    for k in a:
        assert abs(b[k]["z0"] - a[k]["z0"] - 0.5) < 1e-6
        assert abs(b[k]["zN"] - a[k]["zN"] - 0.5) < 1e-6
        assert np.array_equal(a[k]["rx"], b[k]["rx"])
        if a[k]["sel"]:
            assert abs(b[k]["elev"] - a[k]["elev"] - 0.5) < 2e-3
            assert np.array_equal(a[k]["rh"], b[k]["rh"])


def test_ground_detection_moves_only_l2a_ground(root, control):
    world, _ = control
    w2, _ = make(root, "gd", "--effect", "ground_detection", "--param", "algorithm=1", "--param", "offset_m=0.5")
    d1 = {k: v for k, v in digest(world, "gedi/GEDI01_B_*").items()}
    d2 = {k: v for k, v in digest(w2, "gedi/GEDI01_B_*").items()}
    assert d1 == d2, "L1B must not change"
    a, b = shots(world), shots(w2)
    for k in a:
        if a[k]["elev_a"][1] == worldgen.FILL:
            continue
        assert abs(b[k]["elev_a"][1] - a[k]["elev_a"][1] - 0.5) < 2e-3
        assert b[k]["elev_a"][2] == a[k]["elev_a"][2]
        assert np.all(np.abs(b[k]["rh_a1"] - (a[k]["rh_a1"] - 50)) <= 1)
        assert np.array_equal(b[k]["rh_a2"], a[k]["rh_a2"])


def _signal_var(s):
    w = s["rx"] - s["mu"]
    lo, hi = max(0, int(s["top"]) - 40), min(len(w), int(s["bot"]) + 40)
    w = np.clip(w[lo:hi], 0, None)
    i = np.arange(len(w))
    c = (i * w).sum() / w.sum()
    return ((i - c) ** 2 * w).sum() / w.sum()


def test_pulse_broadens_received_waveform(root, control):
    world, _ = control
    w2, _ = make(root, "pulse", "--effect", "pulse", "--magnitude", "1.2")
    a, b = shots(world), shots(w2)
    for k in a:
        assert np.array_equal(a[k]["tx"], b[k]["tx"]), "txwaveform must stay the recorded pulse"
    dv = np.array([_signal_var(b[k]) - _signal_var(a[k]) for k in a])
    expect = (1.2 / worldgen.BIN_M) ** 2          # added variance, samples^2
    assert 0.5 * expect < np.median(dv) < 1.5 * expect, (np.median(dv), expect)
    pk = np.array([(b[k]["rx"] - b[k]["mu"]).max() / (a[k]["rx"] - a[k]["mu"]).max() for k in a])
    assert np.median(pk) < 0.97


def test_footprint_changes_waveform_shape(root, control):
    world, _ = control
    a = shots(world)
    for fs in ("4.0", "7.5"):
        w2, _ = make(root, "fp" + fs, "--effect", "footprint", "--magnitude", fs)
        b = shots(w2)
        common = [k for k in a if k in b]
        assert len(common) == len(a)
        diff = []
        for k in common:
            if len(a[k]["rx"]) == len(b[k]["rx"]) and a[k]["z0"] == b[k]["z0"]:
                diff.append(np.abs(a[k]["rx"] - b[k]["rx"]).max())
            else:
                diff.append(np.inf)
        assert np.median(diff) > 5 * np.median([a[k]["sd"] for k in a])
        rhd = np.array([b[k]["rh"][50] - a[k]["rh"][50] for k in common])
        assert np.mean(np.abs(rhd) > 0.05) > 0.3


def test_noise_factor_reported(root, control):
    world, _ = control
    w2, _ = make(root, "noise", "--effect", "noise", "--magnitude", "2.0")
    a, b = shots(world), shots(w2)
    r = np.array([b[k]["sd"] / a[k]["sd"] for k in a])
    assert np.allclose(r, 2.0)
    pre = np.array([np.std(b[k]["rx"][:150]) / np.std(a[k]["rx"][:150]) for k in a])
    assert 1.8 < np.median(pre) < 2.2
    # stored-record noise is ~ noise_stddev_corrected / 1.74, as measured on the real L1B
    ratio = np.median([a[k]["sd"] / np.std(a[k]["rx"][:150]) for k in a])
    assert 1.4 < ratio < 2.1


def test_weighting_and_canopy_change(root, control):
    world, _ = control
    a = shots(world)
    w_hi, _ = make(root, "whi", "--effect", "weighting", "--magnitude", "1.6")
    b = shots(w_hi)
    assert np.median([b[k]["energy"] / a[k]["energy"] for k in a]) > 1.02
    assert np.median([b[k]["rh"][50] - a[k]["rh"][50] for k in a]) < 0
    w_cc, _ = make(root, "cc", "--effect", "canopy_change", "--param", "height_m=10", "--param", "fraction=0.3")
    c = shots(w_cc)
    assert np.median([c[k]["energy"] / a[k]["energy"] for k in a]) < 0.98
    assert np.median([c[k]["rh"][75] - a[k]["rh"][75] for k in a]) < 0


def test_tx_centroid_after_peak(control):
    world, _ = control
    S = shots(world)

    def refs(tx):
        s = tx - np.median(tx[:20])
        return worldgen.pulse_reference_points(s)

    d = np.array([refs(S[k]["tx"])[1] - refs(S[k]["tx"])[0] for k in S])
    assert np.all(d > 0.5), d.min()
    with h5py.File(REAL_L1B[0], "r") as f:
        real = np.concatenate([f[b]["txwaveform"][:].reshape(-1, 128) for b in f if b.startswith("BEAM")])
    dr = np.array([refs(t)[1] - refs(t)[0] for t in real.astype(float)])
    assert np.all(dr > 0.5)
    assert np.percentile(dr, 5) - 0.7 < np.median(d) < np.percentile(dr, 95) + 0.7


def test_waveform_centroid_matches_truth_without_noise(root):
    """With noise off and the centroid convention, the energy centroid of every received waveform
    sits at the W-weighted mean return elevation recorded in truth.json."""
    w, _ = make(root, "nonoise", "--effect", "noise", "--magnitude", "0", pref="centroid")
    t = truth(w)
    S = shots(w)
    for s in t["shots"]:
        x = S[int(s["shot_number"])]
        n = len(x["rx"])
        z = x["z0"] + (x["zN"] - x["z0"]) * np.arange(n) / (n - 1)
        wv = x["rx"] - x["mu"]
        c = (z * wv).sum() / wv.sum()
        assert abs(c - (s["return_centroid_elev_m"] + t["geoid_m"] + t["datum_dz_m"])) < 0.01


def test_effect_parsing():
    e = worldgen.parse_effects("datum+pulse", ["dz_m=-0.5", "pulse.pulse_sigma_m=0.6"], None)
    assert e == [{"name": "datum", "params": {"dz_m": -0.5}}, {"name": "pulse", "params": {"pulse_sigma_m": 0.6}}]
    assert worldgen.parse_effects("none", [], None) == [{"name": "none", "params": {}}]
    assert worldgen.parse_effects("footprint", [], 4.0)[0]["params"]["fsigma_m"] == 4.0
    assert worldgen.parse_effects("ground_detection", ["algorithm=3"], None)[0]["params"]["algorithm"] == 3
    with pytest.raises(SystemExit):
        worldgen.parse_effects("bogus", [], None)
    with pytest.raises(SystemExit):
        worldgen.parse_effects("datum", ["nope=1"], None)
