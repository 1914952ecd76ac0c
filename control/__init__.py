"""servotau.control"""
