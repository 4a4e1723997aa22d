-- tile_extents: each ingested ALS tile's extent (m, the dataset's projected CRS, the same as
-- shots.x/y) and its number of points: the background of the report's map of shots.
-- requires: tiles
SELECT tile, xmin, ymin, xmax, ymax, n_points, epsg
FROM tiles
ORDER BY tile
