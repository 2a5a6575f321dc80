"""Kinematic errors of a three-axis turning machine (X, Z slides, C spindle) in on-machine measurement
(paper 003): HTM model, reversal separation, error map."""
