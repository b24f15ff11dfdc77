"""Plants: right-hand sides f(t, x, u, p) with their metadata, registered by name."""
