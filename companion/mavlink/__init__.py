"""companion.mavlink."""
