-- collocation: mean Pearson r between real and simulated waveforms before (reported position) and
-- after (collocated offset) collocation, by level and beam (and all), from the offsets table, with
-- the mean offsets (m) and their uncertainty half-widths.
-- requires: offsets
SELECT
    level,
    COALESCE(beam, 'all') AS beam,
    count(*) AS n_segments,
    sum(n_shots) AS n_shots,
    avg(r_before) AS mean_r_before,
    avg(r_after) AS mean_r_after,
    avg(r_after - r_before) AS mean_gain,
    avg(dx) AS mean_dx, avg(dy) AS mean_dy, avg(dz) AS mean_dz,
    avg(dx_halfwidth) AS mean_dx_halfwidth, avg(dy_halfwidth) AS mean_dy_halfwidth
FROM offsets
GROUP BY GROUPING SETS ((level, beam), (level))
ORDER BY level, CASE WHEN beam IS NULL THEN 1 ELSE 0 END, beam
