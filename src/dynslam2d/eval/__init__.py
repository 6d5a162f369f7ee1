"""Evaluation: trajectory, relation, map and detection metrics."""
