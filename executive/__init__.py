"""mmexec.executive."""
