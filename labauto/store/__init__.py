"""labauto/store."""
