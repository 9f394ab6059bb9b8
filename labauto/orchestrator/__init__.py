"""labauto/orchestrator."""
