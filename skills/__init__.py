"""mmexec.skills."""
