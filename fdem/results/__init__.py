"""Reading a run: runout, displacement and fragment statistics, events and magnitudes, the run report.
"""
