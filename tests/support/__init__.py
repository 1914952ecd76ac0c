"""Helpers shared by the test modules (imported as ``support.<module>``; no test module imports another)."""
