-- waveform_examples: the real waveform and the three simulated ones of up to three typical shots
-- (real RH98 above the ALS ground closest to the median), on one vertical axis: the ALS datum.
-- The real waveform's elevations (WGS84 ellipsoid) are moved by the shift the results table
-- applied to GEDI's ground (elev_lowestmode - gedi_ground of the default algorithm).
-- Sample k of `wave` is at z0 - k * dz. source: gedi | count | frac | int.
-- requires: results, shots, sim
WITH d AS (
    SELECT shot_number, gedi_ground, CAST(rh_aligned[99] AS DOUBLE) AS rh98
    FROM results
    WHERE algorithm = 'default' AND weighting = 'count'
),
m AS (SELECT median(rh98) AS med FROM d),
pick AS (
    SELECT d.shot_number, d.gedi_ground
    FROM d CROSS JOIN m
    WHERE CAST(d.shot_number AS VARCHAR) IN (SELECT footprint_id FROM sim WHERE status = 'ok')
    ORDER BY abs(d.rh98 - m.med), d.shot_number
    LIMIT 3
)
SELECT
    p.shot_number, 'gedi' AS source,
    s.elevation_bin0 - (s.elev_lowestmode - p.gedi_ground) AS z0,
    (s.elevation_bin0 - s.elevation_lastbin) / CAST(s.rx_sample_count - 1 AS DOUBLE) AS dz,
    s.rx_waveform AS wave,
    s.noise_mean_corrected AS noise_mean
FROM pick p JOIN shots s ON s.shot_number = p.shot_number
UNION ALL
SELECT p.shot_number, w.weighting AS source, w.z0, w.dz, w.wave, 0.0 AS noise_mean
FROM pick p JOIN sim w ON w.footprint_id = CAST(p.shot_number AS VARCHAR)
WHERE w.status = 'ok'
ORDER BY shot_number, source
