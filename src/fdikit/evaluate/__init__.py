"""fdikit.evaluate."""
