"""mmexec.config."""
