"""The measurement-chain simulator: nominal surface, scan path and timing, probe, and named effects."""
