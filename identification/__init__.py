"""servotau.identification"""
