"""Experiment machinery: simulated line runs, Monte-Carlo consistency, comparison runs."""
