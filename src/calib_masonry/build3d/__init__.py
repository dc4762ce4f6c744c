"""build3d stage of calib_masonry."""
