"""Files and pictures: VTU/PVD series, the history table, state files, plain JSON, matplotlib pictures.

Imports nothing else of the package (ground floor).
"""
