"""fdikit.isolate."""
