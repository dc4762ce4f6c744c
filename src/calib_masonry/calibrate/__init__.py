"""calibrate stage of calib_masonry."""
