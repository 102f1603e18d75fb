"""companion.sim."""
