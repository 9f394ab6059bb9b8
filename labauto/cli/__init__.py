"""labauto/cli."""
