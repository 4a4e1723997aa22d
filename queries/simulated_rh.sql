-- Simulated RH of every ingested shot, per weighting: the simulator as a SQL operator.
-- gedi_simulate() streams the simulated waveforms (shots batched by spatial cell, each batch
-- reading only the ALS row groups its footprints touch); gedi_rh() recomputes RH0..RH100 from the
-- waveform and the ALS ground, so the two columns must agree.
SELECT
    footprint_id AS shot,
    weighting,
    status,
    als_ground,
    true_top,
    als_cover,
    rh,
    gedi_rh(wave, z0, dz, als_ground) AS rh_from_wave
FROM gedi_simulate('default')
ORDER BY shot, weighting
