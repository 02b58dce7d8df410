"""fdikit.faults."""
