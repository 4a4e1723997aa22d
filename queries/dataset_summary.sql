-- dataset_summary: the shots of the study by forest type and beam type (and all): number of
-- shots, share of leaf-off shots among those whose phenology is known (%), share of unknown
-- phenology (%), mean ALS canopy cover and slope (mean over the weightings' truths), and the share
-- of shots whose L2A selected algorithm is a1 (%).
-- requires: results
WITH shot AS (
    SELECT
        shot_number, forest_type, beam_type, phenology,
        avg(als_cover) AS cover, avg(slope_deg) AS slope, max(selected_algorithm) AS selected
    FROM results
    GROUP BY shot_number, forest_type, beam_type, phenology
)
SELECT
    COALESCE(forest_type, 'all') AS forest_type,
    COALESCE(beam_type, 'all') AS beam_type,
    count(*) AS n_shots,
    100.0 * sum(CASE WHEN phenology = 'leaf_off' THEN 1 ELSE 0 END)
        / NULLIF(sum(CASE WHEN phenology <> 'unknown' THEN 1 ELSE 0 END), 0) AS leaf_off_pct,
    100.0 * avg(CASE WHEN phenology = 'unknown' THEN 1.0 ELSE 0.0 END) AS phenology_unknown_pct,
    avg(cover) AS mean_cover,
    avg(slope) AS mean_slope_deg,
    100.0 * avg(CASE WHEN selected = 1 THEN 1.0 ELSE 0.0 END) AS a1_selected_pct
FROM shot
GROUP BY GROUPING SETS ((forest_type, beam_type), (forest_type), ())
ORDER BY CASE WHEN forest_type IS NULL THEN 1 ELSE 0 END, forest_type,
    CASE WHEN beam_type IS NULL THEN 1 ELSE 0 END, beam_type
