"""The bench: sweeps of speed, bytes and error against the supersampled polygon truth."""
