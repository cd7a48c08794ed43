"""Mock backend: in-memory capabilities with scriptable outcomes (public testing module)."""
