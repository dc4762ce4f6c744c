"""synthetic stage of calib_masonry."""
