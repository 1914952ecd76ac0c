"""servotau.simrobot"""
