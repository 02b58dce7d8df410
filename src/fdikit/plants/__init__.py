"""fdikit.plants."""
