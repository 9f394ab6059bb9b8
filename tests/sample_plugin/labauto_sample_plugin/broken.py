"""A plugin that fails on import, to prove labauto reports and skips it."""

raise RuntimeError("this sample plugin is broken on purpose")
