"""wall2d stage of calib_masonry."""
