"""servotau.estimation"""
