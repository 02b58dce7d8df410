"""fdikit.monitor."""
