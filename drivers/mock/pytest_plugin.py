"""pytest fixtures for testing skills against the mock backend."""
