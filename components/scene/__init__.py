"""scene: humanpt topics -> Foxglove's own message types (transforms, path, image
annotations, camera calibration, log, 3D entities), so Foxglove and rerun's MCAP import
show the cell natively.  See README.md."""
