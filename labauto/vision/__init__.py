"""labauto/vision."""
