"""Stages with physical end rules, the factor-of-safety search, the slope workflow and ensembles.
"""
