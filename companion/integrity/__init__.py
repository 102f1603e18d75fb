"""companion.integrity."""
