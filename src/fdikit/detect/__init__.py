"""fdikit.detect."""
