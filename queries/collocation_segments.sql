-- collocation_segments: one line per collocated segment: Pearson r before and after, offsets (m).
-- requires: offsets
SELECT segment_id, granule, beam, level, n_shots, r_before, r_after, dx, dy, dz
FROM offsets
ORDER BY granule, beam, segment_id
