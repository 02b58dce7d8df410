"""fdikit.estimate."""
