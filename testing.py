"""fbia.testing: conformance checks for plugins (a pytest plugin; see fbia.core.conformance)."""
