"""ALE mesh motion: surface relocation and respacing, interior smoothing, remapping, velocities."""
