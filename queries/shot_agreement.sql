-- shot_agreement: one row per shot and weighting, L2A's selected algorithm (`default`): simulated
-- and aligned GEDI RH98 and RH50 (m above the ALS ground), their differences (bias = simulated -
-- aligned GEDI, m), and the shot's footprint position (x, y: m, the dataset's projected CRS, as in
-- shots.x/y). The RH lists hold RH0..RH100 and SQL lists count from 1: RH98 is rh_sim[99].
-- requires: results, shots
SELECT
    r.shot_number, r.granule, r.weighting, s.x, s.y,
    r.rh_sim[99] AS rh98_sim, r.rh_aligned[99] AS rh98_gedi, r.rh_sim[99] - r.rh_aligned[99] AS rh98_bias,
    r.rh_sim[51] AS rh50_sim, r.rh_aligned[51] AS rh50_gedi, r.rh_sim[51] - r.rh_aligned[51] AS rh50_bias
FROM results r
JOIN shots s ON r.shot_number = s.shot_number AND r.granule = s.granule
WHERE r.algorithm = 'default'
ORDER BY r.weighting, r.shot_number
