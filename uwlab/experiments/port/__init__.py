"""Port workflow: exact-refraction figures of a design's port, ChArUco image sets rendered through the port by the
simulated camera, corner detection, and the port's calibration from images in air and in water."""
