-- msd_profile: mean squared deviation between real (aligned) and simulated RH at each percentile
-- RH1..RH99, split after Kobayashi & Salam (2000) with population moments:
--   SB = (mean_y - mean_yhat)^2, SDSD = (sd_y - sd_yhat)^2, LCS = 2 (1 - r) sd_y sd_yhat,
-- with y = rh_aligned (real, above the ALS ground) and yhat = rh_sim. LCS is computed as
-- 2 (sd_y sd_yhat - cov(y, yhat)), the same number, defined even when a deviation is 0.
-- msd = SB + SDSD + LCS = mean((y - yhat)^2). Per weighting, algorithm, sensitivity group (and all).
-- requires: results
WITH p AS (
    SELECT
        r.weighting, r.algorithm, r.sensitivity_group, k.value AS percentile,
        CAST(r.rh_aligned[k.value + 1] AS DOUBLE) AS y,
        CAST(r.rh_sim[k.value + 1] AS DOUBLE) AS yhat
    FROM results r CROSS JOIN (SELECT unnest(range(1, 100)) AS value) AS k  -- RH1..RH99 (unnest: a plan a cluster can ship)
),
m AS (
    SELECT
        weighting, algorithm, COALESCE(sensitivity_group, 'all') AS sensitivity_group, percentile,
        count(*) AS n,
        avg(y) AS mean_real, avg(yhat) AS mean_sim,
        stddev_pop(y) AS sd_real, stddev_pop(yhat) AS sd_sim,
        covar_pop(y, yhat) AS cov
    FROM p
    WHERE NOT isnan(y) AND NOT isnan(yhat)
    GROUP BY GROUPING SETS ((weighting, algorithm, sensitivity_group, percentile), (weighting, algorithm, percentile))
)
SELECT
    weighting, algorithm, sensitivity_group, percentile, n,
    (mean_real - mean_sim) * (mean_real - mean_sim) AS sb,
    (sd_real - sd_sim) * (sd_real - sd_sim) AS sdsd,
    2 * (sd_real * sd_sim - cov) AS lcs,
    (mean_real - mean_sim) * (mean_real - mean_sim) + (sd_real - sd_sim) * (sd_real - sd_sim)
        + 2 * (sd_real * sd_sim - cov) AS msd
FROM m
ORDER BY weighting, CASE WHEN algorithm = 'default' THEN 0 ELSE 1 END, algorithm,
    CASE sensitivity_group WHEN 'low' THEN 0 WHEN 'high' THEN 1 ELSE 2 END, percentile
