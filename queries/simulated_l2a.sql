-- Simulated shots processed like GEDI L2A: each shot's simulated waveform (gedi_simulate, default
-- profile, `count` weighting) gets the noise twin of its real shot (energy_total, noise mean and σ,
-- record length; seed = shot number, so re-running gives the same rows), then L2A a1–a6 runs on
-- the twin. The twin's record covers the real record's heights: the simulation's sample 0 (height
-- z0, ALS datum) goes to the record sample at that height below elevation_bin0 − geoid_offset_used
-- (GEDI heights are ellipsoidal; a shot without a geoid offset gives a null twin). Heights stay
-- those of the ALS, so `elev_lowestmode` compares with `als_ground`.
WITH simulated AS (
    SELECT footprint_id, wave, z0, dz, als_ground
    FROM gedi_simulate('default')
    WHERE weighting = 'count' AND status = 'ok'
),
twins AS (
    SELECT
        s.shot_number,
        m.als_ground,
        gedi_noise_twin(m.wave, m.z0, m.dz, s.energy_total, s.noise_mean_corrected,
                        s.noise_stddev_corrected, s.rx_sample_count,
                        CAST(round((s.elevation_bin0 - s.geoid_offset_used - m.z0) / 0.149896229) AS BIGINT),
                        s.shot_number) AS twin
    FROM simulated m
    JOIN shots s ON m.footprint_id = CAST(s.shot_number AS VARCHAR)
),
runs AS (
    SELECT
        t.shot_number,
        t.als_ground,
        a.algorithm,
        t.twin['no_result_reason'] AS twin_reason,
        gedi_l2a(t.twin['rxwaveform'], t.twin['noise_mean'], t.twin['noise_stddev'], a.algorithm,
                 t.twin['elevation_bin0'], t.twin['elevation_lastbin']) AS l2a
    FROM twins t
    CROSS JOIN (VALUES (1), (2), (3), (4), (5), (6)) AS a(algorithm)
)
SELECT
    shot_number,
    CAST(algorithm AS TINYINT UNSIGNED) AS algorithm,
    twin_reason,
    l2a['no_result_reason'] AS no_result_reason,
    als_ground,
    l2a['elev_lowestmode'] AS elev_lowestmode,
    l2a['rh'] AS rh,
    l2a['sensitivity'] AS sensitivity,
    l2a['num_modes'] AS num_modes
FROM runs
ORDER BY shot_number, algorithm
