-- GEDI L2A a1–a6 re-run on every ingested real waveform (`shots` table), beside NASA's stored values.
-- gedi_l2a() is the same kernel as `gedisim l2a`: the rows equal that command's output.
-- One row per shot with a waveform × algorithm; `no_result_reason` is null when the waveform was
-- processed. RH are metres above the ground mode (cm-truncated, as NASA stores rh_aN).
WITH runs AS (
    SELECT
        s.shot_number,
        s.beam,
        a.algorithm,
        gedi_l2a(s.rx_waveform, s.noise_mean_corrected, s.noise_stddev_corrected, a.algorithm,
                 s.elevation_bin0, s.elevation_lastbin) AS l2a,
        CASE a.algorithm
            WHEN 1 THEN s.elev_lowestmode_a1 WHEN 2 THEN s.elev_lowestmode_a2
            WHEN 3 THEN s.elev_lowestmode_a3 WHEN 4 THEN s.elev_lowestmode_a4
            WHEN 5 THEN s.elev_lowestmode_a5 WHEN 6 THEN s.elev_lowestmode_a6
        END AS nasa_elev_lowestmode,
        CASE a.algorithm
            WHEN 1 THEN s.rh_a1 WHEN 2 THEN s.rh_a2 WHEN 3 THEN s.rh_a3
            WHEN 4 THEN s.rh_a4 WHEN 5 THEN s.rh_a5 WHEN 6 THEN s.rh_a6
        END AS nasa_rh,
        CASE a.algorithm
            WHEN 1 THEN s.sensitivity_a1 WHEN 2 THEN s.sensitivity_a2 WHEN 3 THEN s.sensitivity_a3
            WHEN 4 THEN s.sensitivity_a4 WHEN 5 THEN s.sensitivity_a5 WHEN 6 THEN s.sensitivity_a6
        END AS nasa_sensitivity
    FROM shots s
    CROSS JOIN (VALUES (1), (2), (3), (4), (5), (6)) AS a(algorithm)
    WHERE s.rx_waveform IS NOT NULL
)
SELECT
    shot_number,
    beam,
    CAST(algorithm AS TINYINT UNSIGNED) AS algorithm,
    l2a['no_result_reason'] AS no_result_reason,
    l2a['toploc'] AS toploc,
    l2a['botloc'] AS botloc,
    l2a['zcross'] AS zcross,
    l2a['elev_lowestmode'] AS elev_lowestmode,
    l2a['rh'] AS rh,
    l2a['sensitivity'] AS sensitivity,
    l2a['energy_total'] AS energy_total,
    l2a['num_modes'] AS num_modes,
    nasa_elev_lowestmode,
    nasa_rh,
    nasa_sensitivity
FROM runs
ORDER BY shot_number, algorithm
