"""One design's figures, the paper's analyses: ghosts, spots and PSFs, folded LSFs, RMTF
and depth of field, light efficiency, diffraction, the unstated-parameter study."""
