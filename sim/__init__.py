"""mmexec.sim."""
