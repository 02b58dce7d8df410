"""fdikit.io."""
