"""mmexec.trees."""
