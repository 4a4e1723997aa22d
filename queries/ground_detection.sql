-- ground_detection: how far GEDI's ground is from the ALS ground, per L2A algorithm and
-- sensitivity group (low: 0.90 <= s <= 0.96, high: s > 0.96, all).
-- bias = mean(gedi_ground - als_ground), rmse = sqrt(mean((gedi_ground - als_ground)^2)), metres,
-- both grounds in the ALS vertical datum (see results.vertical_reference). The ALS ground is that
-- of the `count` weighting (the ALS truth differs slightly between weightings).
-- requires: results
WITH d AS (
    SELECT algorithm, sensitivity_group, gedi_ground - als_ground AS diff
    FROM results
    WHERE weighting = 'count' AND NOT isnan(gedi_ground - als_ground)
)
SELECT
    algorithm,
    COALESCE(sensitivity_group, 'all') AS sensitivity_group,
    count(*) AS n,
    avg(diff) AS bias,
    sqrt(avg(diff * diff)) AS rmse
FROM d
GROUP BY GROUPING SETS ((algorithm, sensitivity_group), (algorithm))
ORDER BY
    CASE WHEN algorithm = 'default' THEN 0 ELSE 1 END, algorithm,
    CASE COALESCE(sensitivity_group, 'all') WHEN 'low' THEN 0 WHEN 'high' THEN 1 ELSE 2 END
