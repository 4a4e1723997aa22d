-- msd: the MSD split of msd_profile averaged over RH1..RH99 (each percentile weighs the same),
-- per weighting, algorithm and sensitivity group (low, high, all). m^2. n = shots.
-- y = rh_aligned (real), yhat = rh_sim (simulated); SB = (mean_y - mean_yhat)^2,
-- SDSD = (sd_y - sd_yhat)^2, LCS = 2 (1 - r) sd_y sd_yhat (population moments); msd = SB + SDSD + LCS.
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
),
s AS (
    SELECT
        weighting, algorithm, sensitivity_group, n,
        (mean_real - mean_sim) * (mean_real - mean_sim) AS sb,
        (sd_real - sd_sim) * (sd_real - sd_sim) AS sdsd,
        2 * (sd_real * sd_sim - cov) AS lcs
    FROM m
)
SELECT
    weighting, algorithm, sensitivity_group,
    avg(sb) AS sb, avg(sdsd) AS sdsd, avg(lcs) AS lcs, avg(sb + sdsd + lcs) AS msd,
    max(n) AS n
FROM s
GROUP BY weighting, algorithm, sensitivity_group
ORDER BY weighting, CASE WHEN algorithm = 'default' THEN 0 ELSE 1 END, algorithm,
    CASE sensitivity_group WHEN 'low' THEN 0 WHEN 'high' THEN 1 ELSE 2 END
