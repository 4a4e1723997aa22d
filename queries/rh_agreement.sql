-- rh_agreement: simulated vs aligned GEDI RH98 and RH50 per weighting, L2A's selected algorithm
-- (`default`), all shots: n, bias = mean(simulated - aligned GEDI) (m), RMSE (m) and R^2 (squared
-- Pearson correlation). What the report's 1:1 scatter states; `shot_agreement` has the points.
-- requires: results
WITH d AS (
    SELECT weighting, 'RH98' AS metric, rh_sim[99] AS sim, rh_aligned[99] AS gedi
    FROM results WHERE algorithm = 'default'
    UNION ALL
    SELECT weighting, 'RH50' AS metric, rh_sim[51] AS sim, rh_aligned[51] AS gedi
    FROM results WHERE algorithm = 'default'
)
SELECT
    weighting, metric, count(*) AS n,
    avg(sim - gedi) AS bias,
    sqrt(avg((sim - gedi) * (sim - gedi))) AS rmse,
    power(corr(sim, gedi), 2) AS r2
FROM d
WHERE NOT isnan(sim) AND NOT isnan(gedi)
GROUP BY weighting, metric
ORDER BY metric DESC, CASE weighting WHEN 'count' THEN 0 WHEN 'frac' THEN 1 ELSE 2 END
