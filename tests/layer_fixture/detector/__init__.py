"""Layer fixture (never imported)."""
