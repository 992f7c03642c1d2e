"""The verdict: coverage of the confidence bounds and of a pose's U."""
