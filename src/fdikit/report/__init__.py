"""fdikit.report."""
