"""fdikit.residuals."""
