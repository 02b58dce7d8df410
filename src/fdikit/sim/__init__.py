"""fdikit.sim."""
