"""study stage of calib_masonry."""
