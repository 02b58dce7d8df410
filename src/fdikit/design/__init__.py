"""fdikit.design."""
