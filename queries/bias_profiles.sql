-- bias_profiles: per-percentile bias of simulated RH, bias = mean(rh_sim - rh_aligned) (m;
-- positive = the simulation is too tall), and its RMSE, by weighting, algorithm, forest type
-- (and all) and sensitivity group (and all); mean_abs_bias = mean of |bias| over RH1..RH99 of the
-- same profile.
-- requires: results
WITH p AS (
    SELECT
        r.weighting, r.algorithm, r.forest_type, r.sensitivity_group, k.value AS percentile,
        CAST(r.rh_sim[k.value + 1] AS DOUBLE) - CAST(r.rh_aligned[k.value + 1] AS DOUBLE) AS diff
    FROM results r CROSS JOIN (SELECT unnest(range(1, 100)) AS value) AS k  -- RH1..RH99 (unnest: a plan a cluster can ship)
),
b AS (
    SELECT
        weighting, algorithm,
        COALESCE(forest_type, 'all') AS forest_type,
        COALESCE(sensitivity_group, 'all') AS sensitivity_group,
        percentile, count(*) AS n, avg(diff) AS bias, sqrt(avg(diff * diff)) AS rmse
    FROM p
    WHERE NOT isnan(diff)
    GROUP BY GROUPING SETS (
        (weighting, algorithm, forest_type, sensitivity_group, percentile),
        (weighting, algorithm, forest_type, percentile),
        (weighting, algorithm, sensitivity_group, percentile),
        (weighting, algorithm, percentile))
)
SELECT
    weighting, algorithm, forest_type, sensitivity_group, percentile, n, bias, rmse,
    avg(abs(bias)) OVER (PARTITION BY weighting, algorithm, forest_type, sensitivity_group) AS mean_abs_bias
FROM b
ORDER BY weighting, CASE WHEN algorithm = 'default' THEN 0 ELSE 1 END, algorithm, forest_type,
    CASE sensitivity_group WHEN 'low' THEN 0 WHEN 'high' THEN 1 ELSE 2 END, percentile
