-- phenology: leaf-on vs leaf-off (from L2A leaf_off_flag; `unknown` for V1 granules) per-percentile
-- bias = mean(rh_sim - rh_aligned), RMSE (m) and R^2 (squared Pearson correlation of simulated and
-- real RH) for the study's two settings: count weighting with the default algorithm, and int
-- weighting with a3.
-- requires: results
WITH p AS (
    SELECT
        r.phenology, r.weighting, r.algorithm, k.value AS percentile,
        CAST(r.rh_aligned[k.value + 1] AS DOUBLE) AS y,
        CAST(r.rh_sim[k.value + 1] AS DOUBLE) AS yhat
    FROM results r CROSS JOIN (SELECT unnest(range(1, 100)) AS value) AS k  -- RH1..RH99 (unnest: a plan a cluster can ship)
    WHERE (r.weighting = 'count' AND r.algorithm = 'default') OR (r.weighting = 'int' AND r.algorithm = 'a3')
)
SELECT
    phenology, weighting, algorithm, percentile,
    count(*) AS n,
    avg(yhat - y) AS bias,
    sqrt(avg((yhat - y) * (yhat - y))) AS rmse,
    corr(y, yhat) * corr(y, yhat) AS r2
FROM p
WHERE NOT isnan(y) AND NOT isnan(yhat)
GROUP BY phenology, weighting, algorithm, percentile
ORDER BY CASE phenology WHEN 'leaf_on' THEN 0 WHEN 'leaf_off' THEN 1 ELSE 2 END,
    weighting, algorithm, percentile
