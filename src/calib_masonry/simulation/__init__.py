"""simulate stage of calib_masonry."""
