"""labauto/synthetic."""
